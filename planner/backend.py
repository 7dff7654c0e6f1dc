"""Where the planner's per-vehicle work runs: in this process, in forked processes, or on Ray.

The ACO search is one coupled computation (every candidate is scored against the team's
tracks) and runs where :func:`planner.plan.plan` is called. What follows it is one job per
vehicle and pure: the route is shortened, smoothed into a flyable path, given its altitude
profile and checked against the zones and the terrain (:func:`planner.plan.finish_route`).
A backend runs those jobs and returns the routes in job order; the routes do not depend on
where they were finished, so every backend gives the same plan for the same seed. Before the
search a backend also computes each vehicle's cost-to-go field (one Dijkstra search from its
goal, the search's heuristic), the other per-vehicle part of a plan.

- :class:`LocalBackend`: here, or in ``workers`` forked processes sharing the world's memory
  (:func:`planner.plan.finish_routes`). The default.
- :class:`RayBackend`: each vehicle a Ray task. The world, the problem and the zones are put
  into Ray's object store once and shared by the tasks (on a cluster, shipped once to each
  node). ``address=None`` starts a Ray on this machine, listening on the loopback address
  only; ``address="auto"``, ``"head:6379"`` or ``"ray://head:10001"`` joins a running cluster
  (``ray.init(address=...)``). Ray is imported only when this backend is made.

Joining a cluster: one named by a loopback address is this machine's alone, and is joined on
the loopback address (Ray would otherwise put the machine's network address in its place).
Ray's ``ray start`` turns token authentication on whenever a token is at hand
(``RAY_AUTH_TOKEN``, the file ``RAY_AUTH_TOKEN_PATH`` names or ``~/.ray/auth_token``, which a
Ray started here writes), but a driver joining it sends its token only in ``RAY_AUTH_MODE=token``;
with ``RAY_AUTH_MODE`` unset and a token at hand, the backend joins in that mode (a cluster
without authentication takes it as well).
"""

from __future__ import annotations

import ipaddress
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from planner.plan import FinishJob, PlannedRoute, World
    from planner.problem import Problem
    from planner.threats import ThreatZone

__all__ = ["Backend", "LocalBackend", "RayBackend"]

AUTH_MODE_ENV = "RAY_AUTH_MODE"
"""Ray's switch for token authentication: "token" sends the token at hand."""
AUTH_TOKEN_ENV = "RAY_AUTH_TOKEN"
AUTH_TOKEN_PATH_ENV = "RAY_AUTH_TOKEN_PATH"
LOOPBACK_ONLY_ENV = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"
"""Ray's switch between a cluster (its services on the node's network address) and one
machine (on the loopback address, as on Windows and macOS): "0" is one machine."""

RAY_START_TRIES = 3
"""How many times a Ray started here is started before the backend gives up. Ray waits a fixed
30 s of wall time for its new node to register (``ray._private.node``), which a busy machine
can overrun; each start that timed out is shut down before the next."""
RAY_START_TIMED_OUT = "timed out during startup"
"""What Ray's error says when its node did not register in time."""


class Backend(Protocol):
    """Runs a plan's per-vehicle work: the cost-to-go fields before the search, and the
    route-finishing jobs after it (the routes come back in job order)."""

    def fill_fields(self, problem: Problem) -> None:
        """Compute the problem's missing cost-to-go fields and keep them in it (or leave
        them to be computed as the search asks for them)."""

    def finish_routes(
        self,
        world: World,
        problem: Problem,
        jobs: Sequence[FinishJob],
        *,
        threats: Sequence[ThreatZone],
    ) -> list[PlannedRoute]: ...


@dataclass(frozen=True)
class LocalBackend:
    """This process (``workers`` 1) or that many forked processes."""

    workers: int = 1

    def fill_fields(self, problem: Problem) -> None:
        from planner.plan import fill_fields

        fill_fields(problem, self.workers)

    def finish_routes(
        self,
        world: World,
        problem: Problem,
        jobs: Sequence[FinishJob],
        *,
        threats: Sequence[ThreatZone],
    ) -> list[PlannedRoute]:
        from planner.plan import finish_routes

        return finish_routes(world, problem, jobs, threats=threats, workers=self.workers)


def _fields(problem: Problem, indices: list[int]) -> Any:
    """Cost-to-go fields of some tasks, in a Ray worker (the problem from the object store)."""
    from planner.problem import task_fields

    return task_fields(problem, indices)


def _finish_one(shared: Any, job: FinishJob) -> Any:
    """One vehicle's route, in a Ray worker (the shared parts come from the object store)."""
    from planner.plan import finish_job

    world, problem, threats = shared
    return finish_job(world, problem, threats, job)


class RayBackend:
    """Each vehicle's route a Ray task.

    Parameters
    ----------
    address
        A running cluster to join (``ray.init(address=...)``: ``"auto"``, ``"ray://host:10001"``);
        None starts a Ray on this machine, with ``num_cpus`` workers (all cores when None),
        whatever cluster ``RAY_ADDRESS`` or an earlier ``ray start`` names.
    num_cpus
        For a Ray started here only.

    A Ray already initialised in this process is used as it is. :meth:`close` shuts down a
    Ray this backend started.
    """

    def __init__(self, address: str | None = None, *, num_cpus: int | None = None) -> None:
        # Both read when ray is first imported.
        if address is None or _on_loopback(address):
            # A Ray started here (or joined on the loopback address) is this machine's alone:
            # its services on the loopback address, not the machine's network address.
            os.environ.setdefault(LOOPBACK_ONLY_ENV, "0")
        if address is not None and AUTH_MODE_ENV not in os.environ and _token_at_hand():
            os.environ[AUTH_MODE_ENV] = "token"
        import ray

        self._ray = ray
        self._started = False
        if not ray.is_initialized():
            options: dict[str, Any] = {
                "include_dashboard": False,
                "log_to_driver": False,
                "configure_logging": False,
            }
            if address is None:
                # "local": a new Ray, never one that RAY_ADDRESS or the last `ray start` on
                # this machine (/tmp/ray/ray_current_cluster) names, running or not.
                options |= {"address": "local", "num_cpus": num_cpus}
                _start_here(ray, options)
            else:
                options["address"] = address
                ray.init(**options)
            self._started = True
        self._task = ray.remote(_finish_one)
        self._fields = ray.remote(_fields)

    def fill_fields(self, problem: Problem) -> None:
        from planner.plan import FIELDS_PER_CHUNK

        todo = problem.fields_missing()
        chunks = [todo[k : k + FIELDS_PER_CHUNK] for k in range(0, len(todo), FIELDS_PER_CHUNK)]
        shared = self._ray.put(problem)
        got = self._ray.get([self._fields.remote(shared, chunk) for chunk in chunks])
        for chunk, fields in zip(chunks, got, strict=True):
            problem.put_fields(chunk, fields)

    def finish_routes(
        self,
        world: World,
        problem: Problem,
        jobs: Sequence[FinishJob],
        *,
        threats: Sequence[ThreatZone],
    ) -> list[PlannedRoute]:
        shared = self._ray.put((world, problem, tuple(threats)))
        refs = [self._task.remote(shared, job) for job in jobs]
        # ray.get returns in the order asked; the first failing route raises its error.
        routes: list[PlannedRoute] = self._ray.get(refs)
        return routes

    def close(self) -> None:
        """Shut down the Ray this backend started (one it joined or found is left running)."""
        if self._started:
            self._ray.shutdown()
            self._started = False


def _start_here(ray: Any, options: dict[str, Any]) -> None:
    """Start a Ray on this machine, again (up to :data:`RAY_START_TRIES` in all) while its
    node times out registering; any other error at once."""
    for attempt in range(1, RAY_START_TRIES + 1):
        try:
            ray.init(**options)
            return
        except Exception as err:
            if RAY_START_TIMED_OUT not in str(err) or attempt == RAY_START_TRIES:
                raise
            ray.shutdown()


def _on_loopback(address: str) -> bool:
    """``address`` (``"host:port"`` or ``"ray://host:port"``) names a loopback host."""
    host = address.removeprefix("ray://").rsplit(":", 1)[0].strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _token_at_hand() -> bool:
    """A Ray authentication token where Ray looks for one."""
    if os.environ.get(AUTH_TOKEN_ENV):
        return True
    path = os.environ.get(AUTH_TOKEN_PATH_ENV)
    return Path(path).is_file() if path else (Path.home() / ".ray" / "auth_token").is_file()
