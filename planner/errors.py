"""Error classes of the planner. Each names what is wrong in one line."""

from __future__ import annotations

from typing import Any


class PlannerError(Exception):
    """Base class of every error the planner raises on purpose."""


class ScenarioError(PlannerError, ValueError):
    """A scenario file or value is invalid; the message names the field."""


class TerrainError(PlannerError, ValueError):
    """Terrain data is missing or unreadable; the message names the tile or file."""


class InfeasibleError(PlannerError, ValueError):
    """No path or schedule satisfies the constraints; the message names the vehicle.

    ``vehicle`` is the vehicle that makes it infeasible and ``earliest_s`` the earliest team
    arrival that would be feasible, when they are known (None otherwise).
    """

    def __init__(
        self, message: str, *, vehicle: str | None = None, earliest_s: float | None = None
    ) -> None:
        super().__init__(message)
        self.vehicle = vehicle
        self.earliest_s = earliest_s

    def __reduce__(self) -> tuple[Any, ...]:
        # The attributes are keyword arguments: rebuild from the message and the attributes
        # (the default reduction would call the class with the message alone).
        return _rebuild, (type(self), str(self), dict(self.__dict__))


def _rebuild(cls: type[InfeasibleError], message: str, attrs: dict[str, Any]) -> InfeasibleError:
    err = cls.__new__(cls)
    Exception.__init__(err, message)
    err.__dict__.update(attrs)
    return err


class ArrivalTimeError(InfeasibleError):
    """The requested team arrival time cannot be met by every vehicle.

    ``requested_s`` is the requested reference time (``required_s``, or ``first_s`` of spaced
    arrivals), ``earliest_s`` and ``latest_s`` bound the feasible ones (``latest_s`` is inf
    when every vehicle can loiter) and ``vehicle`` is the one that forces the bound missed.
    """

    def __init__(
        self,
        message: str,
        *,
        vehicle: str | None,
        requested_s: float,
        earliest_s: float,
        latest_s: float,
    ) -> None:
        super().__init__(message, vehicle=vehicle, earliest_s=earliest_s)
        self.requested_s = requested_s
        self.latest_s = latest_s


class SeparationError(InfeasibleError):
    """Two scheduled vehicles come closer than the separation minimum ``d_s``.

    ``pair`` names the two vehicles of the closest conflict, ``time_s`` (mission s) and
    ``distance_m`` its closest approach, ``required_m`` is ``d_s`` and ``conflicts`` the number
    of pairs below it.
    """

    def __init__(
        self,
        message: str,
        *,
        pair: tuple[str, str],
        time_s: float,
        distance_m: float,
        required_m: float,
        conflicts: int = 1,
    ) -> None:
        super().__init__(message)
        self.pair = pair
        self.time_s = time_s
        self.distance_m = distance_m
        self.required_m = required_m
        self.conflicts = conflicts
