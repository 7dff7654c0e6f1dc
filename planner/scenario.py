"""Scenario files: the pydantic model of the file format and its loader.

A scenario names the planning area (a geographic origin and a rectangle in local metres about
it), the terrain source, the threats, the vehicles with their limits, the team's time
constraint, the separation minimum ``d_s``, loiter buffer areas and pop-up threats.

Positions are given either in local metres about the origin (``east_m``/``north_m``) or as
WGS84 degrees (``lat_deg``/``lon_deg``); altitudes are metres above mean sea level.
Times are mission seconds: ``0`` is the moment the mission is started.

The models here are the edge of the planner: :func:`load_scenario` validates a file and raises
one :class:`~planner.errors.ScenarioError` naming the field; the pure code downstream works on
the validated model.
"""

from __future__ import annotations

import functools
import json
import math
from itertools import pairwise
from pathlib import Path
from typing import Annotated, Any, Literal, Self

import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    TypeAdapter,
    ValidationError,
    field_validator,
    model_validator,
)

from planner.errors import ScenarioError
from planner.geo import LocalFrame
from planner.goals import assign_goals
from planner.wind import CALM, Wind

PositiveM = Annotated[float, Field(gt=0.0)]
_FLAG: TypeAdapter[bool] = TypeAdapter(bool)
PositiveSpeed = Annotated[float, Field(gt=0.0, le=400.0)]
MissionTimeS = Annotated[float, Field(ge=0.0)]


class _Model(BaseModel):
    # NaN and infinities are refused wherever a number is expected (a NaN would pass every
    # range check, since each comparison with it is false).
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class Point(_Model):
    """A horizontal position, local (``east_m``, ``north_m``) or geographic (degrees)."""

    east_m: float | None = None
    north_m: float | None = None
    lat_deg: Annotated[float, Field(ge=-90.0, le=90.0)] | None = None
    lon_deg: Annotated[float, Field(ge=-180.0, le=180.0)] | None = None

    @model_validator(mode="after")
    def _one_form(self) -> Self:
        local = self.east_m is not None or self.north_m is not None
        geo = self.lat_deg is not None or self.lon_deg is not None
        if local == geo:
            raise ValueError("give either east_m and north_m, or lat_deg and lon_deg")
        if local and (self.east_m is None or self.north_m is None):
            raise ValueError("east_m and north_m must both be given")
        if geo and (self.lat_deg is None or self.lon_deg is None):
            raise ValueError("lat_deg and lon_deg must both be given")
        return self

    def local(self, frame: LocalFrame) -> tuple[float, float]:
        """Local (east_m, north_m) of this point in ``frame``."""
        if self.east_m is not None and self.north_m is not None:
            return float(self.east_m), float(self.north_m)
        assert self.lat_deg is not None and self.lon_deg is not None
        east, north = frame.to_local(self.lat_deg, self.lon_deg)
        return float(east), float(north)


class Point3(Point):
    """A position with an altitude in metres above mean sea level."""

    alt_m: Annotated[float, Field(ge=-500.0, le=20000.0)]


class Origin(_Model):
    lat_deg: Annotated[float, Field(ge=-85.0, le=85.0)]
    lon_deg: Annotated[float, Field(ge=-180.0, le=180.0)]


@functools.lru_cache(maxsize=256)
def _frame_at(lat_hex: str, lon_hex: str) -> LocalFrame:
    """The frame about an origin given by its exact bits (``float.hex``), made once: it is
    immutable, and a loiter site is looked for with it at every timing tried."""
    return LocalFrame(float.fromhex(lat_hex), float.fromhex(lon_hex))


class Area(_Model):
    """The planning rectangle: local metres about a geographic origin."""

    origin: Origin
    min_east_m: float = 0.0
    min_north_m: float = 0.0
    width_m: Annotated[float, Field(gt=0.0, le=2_000_000.0)]
    height_m: Annotated[float, Field(gt=0.0, le=2_000_000.0)]
    resolution_m: Annotated[float, Field(gt=0.0)] = 1000.0

    @model_validator(mode="after")
    def _grid_size(self) -> Self:
        cells = (self.width_m / self.resolution_m + 1) * (self.height_m / self.resolution_m + 1)
        if cells > 4_000_000:
            raise ValueError(
                f"resolution_m {self.resolution_m:g} gives {cells:.0f} grid nodes (limit 4000000)"
            )
        if self.width_m / self.resolution_m < 2 or self.height_m / self.resolution_m < 2:
            raise ValueError("resolution_m is too coarse: the grid needs at least 3 x 3 nodes")
        return self

    @property
    def max_east_m(self) -> float:
        return self.min_east_m + self.width_m

    @property
    def max_north_m(self) -> float:
        return self.min_north_m + self.height_m

    def frame(self) -> LocalFrame:
        return _frame_at(float(self.origin.lat_deg).hex(), float(self.origin.lon_deg).hex())

    def contains(self, east_m: float, north_m: float) -> bool:
        return (
            self.min_east_m <= east_m <= self.max_east_m
            and self.min_north_m <= north_m <= self.max_north_m
        )


class FlatTerrain(_Model):
    kind: Literal["flat"]
    elevation_m: float = 0.0


class SyntheticTerrainSpec(_Model):
    kind: Literal["synthetic"]
    seed: int = 0
    base_m: float = 200.0
    peak_m: Annotated[float, Field(ge=0.0)] = 1800.0
    hills: Annotated[int, Field(ge=0, le=10_000)] = 40


class SrtmTerrainSpec(_Model):
    kind: Literal["srtm"]
    directory: str = Field(description="folder of .hgt tiles; relative to the scenario file")


TerrainSpec = Annotated[
    FlatTerrain | SyntheticTerrainSpec | SrtmTerrainSpec, Field(discriminator="kind")
]


class Appearance(_Model):
    """When a pop-up threat appears: a mission time, or a delay after a vehicle's takeoff."""

    at_s: MissionTimeS | None = None
    after_takeoff_of: str | None = None
    delay_s: Annotated[float, Field(ge=0.0)] = 0.0

    @model_validator(mode="after")
    def _one_form(self) -> Self:
        if (self.at_s is None) == (self.after_takeoff_of is None):
            raise ValueError("give either at_s, or after_takeoff_of with delay_s")
        return self


class Radar(_Model):
    """A radar site: detects below ``ceiling_m`` (AMSL) within ``radius_m``."""

    kind: Literal["radar"]
    id: str
    center: Point
    radius_m: PositiveM
    ceiling_m: float = 30_000.0
    forbidden: bool = False
    appears: Appearance | None = None


class NoFly(_Model):
    """A no-fly polygon (vertices in order, not closed), below ``ceiling_m``."""

    kind: Literal["no_fly"]
    id: str
    polygon: Annotated[list[Point], Field(min_length=3)]
    ceiling_m: float = 30_000.0
    forbidden: bool = True
    appears: Appearance | None = None


Threat = Annotated[Radar | NoFly, Field(discriminator="kind")]


class Buffer(_Model):
    """A loiter buffer area: a disc where holding turns are allowed."""

    id: str
    center: Point
    radius_m: PositiveM
    vehicles: list[str] | None = Field(
        default=None, description="vehicles allowed to loiter here; all when absent"
    )


class Vehicle(_Model):
    id: Annotated[str, Field(min_length=1, max_length=32, pattern=r"^[A-Za-z0-9_.-]+$")]
    start: Point3
    goal: Point3
    speed_min_m_s: PositiveSpeed
    speed_max_m_s: PositiveSpeed
    cruise_speed_m_s: PositiveSpeed | None = Field(
        default=None, description="planned cruise speed; the middle of the range when absent"
    )
    min_turn_radius_m: PositiveM
    max_range_m: PositiveM
    alt_min_m: float = 0.0
    alt_max_m: float = 5000.0
    clearance_m: Annotated[float, Field(ge=0.0)] = 150.0
    climb_gradient: Annotated[float, Field(gt=0.0, le=1.0)] = Field(
        default=0.1, description="steepest climb or descent, metres per metre flown"
    )
    max_turn_deg: Annotated[float, Field(gt=0.0, le=180.0)] = 135.0
    min_leg_m: Annotated[float, Field(ge=0.0)] | None = Field(
        default=None, description="shortest straight leg; 2 x min_turn_radius_m when absent"
    )
    takeoff_window_s: tuple[MissionTimeS, MissionTimeS] = (0.0, 0.0)
    takeoff_climb_m_s: Annotated[float, Field(gt=0.0, le=50.0)] = Field(
        default=9.0,
        description="full-throttle climb rate of the takeoff climb-out, m/s (ArduPlane climbs "
        "to the NAV_TAKEOFF altitude on the takeoff heading at TKOFF_THR_MAX)",
    )
    airborne: bool = Field(default=False, description="already flying at start (no takeoff)")

    @model_validator(mode="after")
    def _limits(self) -> Self:
        if self.speed_min_m_s > self.speed_max_m_s:
            raise ValueError(
                f"speed_min_m_s {self.speed_min_m_s:g} is above "
                f"speed_max_m_s {self.speed_max_m_s:g}"
            )
        cruise = self.cruise_speed_m_s
        if cruise is not None and not self.speed_min_m_s <= cruise <= self.speed_max_m_s:
            raise ValueError(
                f"cruise_speed_m_s {cruise:g} is outside "
                f"[{self.speed_min_m_s:g}, {self.speed_max_m_s:g}]"
            )
        if self.alt_min_m > self.alt_max_m:
            raise ValueError(f"alt_min_m {self.alt_min_m:g} is above alt_max_m {self.alt_max_m:g}")
        for name, point in (("start", self.start), ("goal", self.goal)):
            if not self.alt_min_m <= point.alt_m <= self.alt_max_m:
                raise ValueError(
                    f"{name}.alt_m {point.alt_m:g} is outside "
                    f"[alt_min_m {self.alt_min_m:g}, alt_max_m {self.alt_max_m:g}]"
                )
        lo, hi = self.takeoff_window_s
        if lo > hi:
            raise ValueError(f"takeoff_window_s [{lo:g}, {hi:g}] ends before it begins")
        return self

    @property
    def cruise_m_s(self) -> float:
        if self.cruise_speed_m_s is not None:
            return self.cruise_speed_m_s
        return 0.5 * (self.speed_min_m_s + self.speed_max_m_s)

    @property
    def min_leg_length_m(self) -> float:
        return self.min_leg_m if self.min_leg_m is not None else 2.0 * self.min_turn_radius_m


class Simultaneous(_Model):
    """Every vehicle arrives at the same time."""

    kind: Literal["simultaneous"]
    required_s: MissionTimeS | None = Field(
        default=None, description="requested arrival; the earliest common feasible time if absent"
    )


class Spaced(_Model):
    """Arrivals in order, ``interval_s`` apart (waves or landing slots)."""

    kind: Literal["spaced"]
    interval_s: Annotated[float, Field(gt=0.0)]
    first_s: MissionTimeS | None = None
    order: list[str] | None = Field(default=None, description="arrival order; file order if absent")


class Window(_Model):
    vehicle: str
    earliest_s: MissionTimeS
    latest_s: MissionTimeS

    @model_validator(mode="after")
    def _ordered(self) -> Self:
        if self.earliest_s > self.latest_s:
            raise ValueError(f"earliest_s {self.earliest_s:g} is after latest_s {self.latest_s:g}")
        return self


class Windows(_Model):
    """Each vehicle arrives within its own window."""

    kind: Literal["windows"]
    windows: Annotated[list[Window], Field(min_length=1)]


_Group = Annotated[list[str], Field(min_length=1)]


class Waves(_Model):
    """Groups of vehicles that arrive together, ``gap_s`` between one group and the next:
    the groups named (``groups``, every vehicle in one), or only their sizes (``sizes``,
    summing to the team: the vehicles that can arrive soonest fly in the first)."""

    kind: Literal["waves"]
    gap_s: Annotated[float, Field(gt=0.0)]
    first_s: MissionTimeS | None = Field(
        default=None, description="the first wave's arrival; the earliest feasible if absent"
    )
    groups: (
        Annotated[list[Annotated[list[str], Field(min_length=1)]], Field(min_length=1)] | None
    ) = None
    sizes: Annotated[list[Annotated[int, Field(ge=1)]], Field(min_length=1)] | None = None

    @model_validator(mode="after")
    def _one_of(self) -> Self:
        if (self.groups is None) == (self.sizes is None):
            raise ValueError("give either groups (vehicles by wave) or sizes (vehicles per wave)")
        return self


ArrivalConstraint = Annotated[Simultaneous | Spaced | Windows | Waves, Field(discriminator="kind")]


class Landing(_Model):
    """The runway the slots lead to: each vehicle's goal is its slot fix on the extended
    centreline, crossed on the approach course (the runway heading) after a straight final of
    ``approach_m``; after the fix the aircraft glides to ``touchdown`` and lands (ArduPlane's
    DO_LAND_START then NAV_LAND)."""

    touchdown: Point3 = Field(description="touchdown point; alt_m is the runway's elevation")
    heading_deg: Annotated[float, Field(ge=0.0, lt=360.0)] = Field(
        description="landing direction, degrees clockwise from north (the approach course)"
    )
    approach_m: Annotated[float, Field(gt=0.0, le=50_000.0)] = Field(
        default=2000.0, description="straight final flown on the course before the slot fix"
    )


LANDING_CENTRELINE_TOL_M = 30.0
"""How far a slot fix may lie off the runway's extended centreline."""


class CostWeights(_Model):
    """Weights of the planning cost: length x (1 + threat x exposure + terrain x penalty)."""

    threat: Annotated[float, Field(ge=0.0)] = 4.0
    terrain: Annotated[float, Field(ge=0.0)] = 1.0


class ForecastWind(_Model):
    """The wind forecast for the flight: what the schedule is timed in before the vehicles
    measure it."""

    speed_m_s: Annotated[float, Field(ge=0.0, le=60.0)]
    from_deg: Annotated[float, Field(ge=0.0, lt=360.0)] = Field(
        description="compass direction the wind blows from, degrees (270: a westerly)"
    )


def parse_wind(text: str, option: str) -> ForecastWind:
    """``SPEED_M_S,FROM_DEG`` (a command line's wind) as a :class:`ForecastWind`.

    Raises
    ------
    ScenarioError
        Not two numbers, or a speed outside [0, 60] m/s; the message names ``option``.
    """
    parts = text.split(",")
    try:
        speed, from_deg = (float(x) for x in parts)
    except ValueError:
        raise ScenarioError(f"{option}: expected SPEED_M_S,FROM_DEG, got {text!r}") from None
    if not (math.isfinite(speed) and math.isfinite(from_deg)):
        raise ScenarioError(f"{option}: {text!r} is not a number")
    if not 0.0 <= speed <= 60.0:
        raise ScenarioError(f"{option}: speed {speed:g} m/s is outside [0, 60]")
    return ForecastWind(speed_m_s=speed, from_deg=from_deg % 360.0)


class Scenario(_Model):
    name: str = "scenario"
    area: Area
    terrain: TerrainSpec = Field(default_factory=lambda: FlatTerrain(kind="flat"))
    separation_m: PositiveM = Field(description="minimum safe distance d_s between vehicles")
    arrival: ArrivalConstraint
    vehicles: Annotated[list[Vehicle], Field(min_length=1, max_length=1000)]
    threats: list[Threat] = Field(default_factory=list)
    buffers: list[Buffer] = Field(default_factory=list)
    weights: CostWeights = Field(default_factory=CostWeights)
    landing: Landing | None = Field(
        default=None, description="landing slots: the runway every goal (slot fix) leads to"
    )
    wind: ForecastWind | None = Field(
        default=None, description="forecast wind the schedule is timed in; still air if absent"
    )
    assign_goals: bool = Field(
        default=False,
        description=(
            "the vehicles' goals are approach points any of them may fly to: they are shared "
            "out so that the sum of squared start-goal distances is least (routes that fan "
            "in rather than cross near the goals); each vehicle's goal is the one assigned"
        ),
    )

    altitude_layers_m: list[PositiveM] = Field(
        default_factory=list,
        max_length=8,
        description=(
            "heights above its planned profile (m) at which a vehicle may fly to keep the "
            "separation from vehicles sharing its corridor, where its alt_max_m allows "
            "(planner.layers); none by default: every vehicle flies its profile"
        ),
    )

    def forecast_wind(self) -> Wind:
        """The forecast wind as the air mass's velocity (still air without one)."""
        if self.wind is None:
            return CALM
        return Wind.from_speed_from(self.wind.speed_m_s, self.wind.from_deg)

    @model_validator(mode="before")
    @classmethod
    def _share_out_goals(cls, data: Any) -> Any:
        """With ``assign_goals``, each vehicle's goal replaced by the one assigned to it
        (:func:`planner.goals.assign_goals`) before the fields are validated."""
        if not isinstance(data, dict):
            return data
        try:  # read as the field reads it ("true", 1 and yes are true too)
            assigned = _FLAG.validate_python(data.get("assign_goals", False))
        except ValidationError:
            return data  # the field's own validation says what is wrong
        if not assigned:
            return data
        vehicles = data.get("vehicles")
        if not isinstance(vehicles, list) or not all(isinstance(v, dict) for v in vehicles):
            return data
        try:
            frame = Area.model_validate(data["area"]).frame()
            starts = [Point3.model_validate(v["start"]).local(frame) for v in vehicles]
            goals = [Point3.model_validate(v["goal"]).local(frame) for v in vehicles]
        except (KeyError, TypeError, ValueError):
            return data  # the fields' own validation says what is wrong
        order = assign_goals(starts, goals)
        shared = [{**v, "goal": vehicles[k]["goal"]} for v, k in zip(vehicles, order, strict=True)]
        return {**data, "vehicles": shared}

    @field_validator("vehicles")
    @classmethod
    def _unique_ids(cls, vehicles: list[Vehicle]) -> list[Vehicle]:
        seen: set[str] = set()
        for v in vehicles:
            if v.id in seen:
                raise ValueError(f"vehicle id {v.id!r} is used twice")
            seen.add(v.id)
        return vehicles

    @model_validator(mode="after")
    def _cross_references(self) -> Self:
        ids = {v.id for v in self.vehicles}
        frame = self.area.frame()
        for i, v in enumerate(self.vehicles):
            for name, p in (("start", v.start), ("goal", v.goal)):
                e, n = p.local(frame)
                if not self.area.contains(e, n):
                    raise ValueError(
                        f"vehicles[{i}] ({v.id}).{name} at ({e:.0f}, {n:.0f}) m is outside the area"
                    )
        if self.assign_goals and self.landing is not None:
            raise ValueError(
                "assign_goals: not with landing slots (each vehicle's slot is given in order)"
            )
        if self.altitude_layers_m and self.landing is not None:
            raise ValueError(
                "altitude_layers_m: not with landing slots (each slot's final is flown at "
                "its fix's altitude)"
            )
        layers = self.altitude_layers_m
        if any(b <= a for a, b in pairwise(layers)):
            raise ValueError(f"altitude_layers_m: {layers} must rise, each height once")
        threat_ids: set[str] = set()
        for t in self.threats:
            if t.id in threat_ids:
                raise ValueError(f"threat id {t.id!r} is used twice")
            threat_ids.add(t.id)
            if t.appears is not None and t.appears.after_takeoff_of not in (None, *ids):
                raise ValueError(
                    f"threat {t.id}: appears.after_takeoff_of names unknown vehicle "
                    f"{t.appears.after_takeoff_of!r}"
                )
        for b in self.buffers:
            for vid in b.vehicles or []:
                if vid not in ids:
                    raise ValueError(f"buffer {b.id}: vehicles names unknown vehicle {vid!r}")
        arrival = self.arrival
        if isinstance(arrival, Spaced) and arrival.order is not None:
            named = [(f"arrival.order[{k}]", vid) for k, vid in enumerate(arrival.order)]
            _names_every_vehicle(
                "arrival.order", named, ids, rule="the order names each vehicle exactly once"
            )
        if isinstance(arrival, Waves) and arrival.groups is not None:
            named = [
                (f"arrival.groups[{k}][{j}]", vid)
                for k, group in enumerate(arrival.groups)
                for j, vid in enumerate(group)
            ]
            _names_every_vehicle(
                "arrival.groups", named, ids, rule="each vehicle flies in exactly one wave"
            )
        if (
            isinstance(arrival, Waves)
            and arrival.sizes is not None
            and sum(arrival.sizes) != len(self.vehicles)
        ):
            raise ValueError(
                f"arrival.sizes: the waves hold {sum(arrival.sizes)} vehicles, the team "
                f"has {len(self.vehicles)}"
            )
        if isinstance(arrival, Windows):
            named = [
                (f"arrival.windows[{k}].vehicle", w.vehicle) for k, w in enumerate(arrival.windows)
            ]
            _names_every_vehicle(
                "arrival.windows", named, ids, rule="each vehicle needs exactly one window"
            )
        if self.landing is not None:
            self._check_landing(self.landing)
        return self

    def _check_landing(self, landing: Landing) -> None:
        """Each goal is a slot fix on the extended centreline short of the touchdown, high
        enough above it to glide down no steeper than the vehicle climbs."""
        frame = self.frame()
        te, tn = landing.touchdown.local(frame)
        if not self.area.contains(te, tn):
            raise ValueError(f"landing.touchdown at ({te:.0f}, {tn:.0f}) m is outside the area")
        course = math.radians(landing.heading_deg)
        ue, un = math.sin(course), math.cos(course)
        for i, v in enumerate(self.vehicles):
            ge, gn = v.goal.local(frame)
            along = (te - ge) * ue + (tn - gn) * un
            across = -(te - ge) * un + (tn - gn) * ue
            where = f"vehicles[{i}] ({v.id}).goal"
            if along <= 0.0 or abs(across) > LANDING_CENTRELINE_TOL_M:
                raise ValueError(
                    f"{where} is not a slot fix: it lies {along:.0f} m short of the touchdown "
                    f"and {across:+.0f} m off the centreline on heading "
                    f"{landing.heading_deg:g} deg (it must be short of it and within "
                    f"{LANDING_CENTRELINE_TOL_M:g} m of the centreline)"
                )
            height = v.goal.alt_m - landing.touchdown.alt_m
            if height <= 0.0 or height / along > v.climb_gradient:
                raise ValueError(
                    f"{where}: alt_m {v.goal.alt_m:g} is {height:.0f} m above the touchdown "
                    f"{along:.0f} m away: the glide must descend, no steeper than "
                    f"climb_gradient {v.climb_gradient:g}"
                )

    def arrival_offsets_s(self) -> dict[str, float]:
        """Each vehicle's arrival after the team's reference time (s): 0 for simultaneous
        arrivals and windows, its place in the order times ``interval_s`` when spaced, its
        wave's index times ``gap_s`` in waves. Waves given by size are filled in the order of
        each vehicle's soonest arrival: its takeoff window's start plus the straight line to
        its goal at its top speed (an airborne vehicle from 0)."""
        arrival = self.arrival
        ids = [v.id for v in self.vehicles]
        if isinstance(arrival, Spaced):
            return {vid: k * arrival.interval_s for k, vid in enumerate(arrival.order or ids)}
        if isinstance(arrival, Waves):
            groups = arrival.groups
            if groups is None:
                assert arrival.sizes is not None
                frame = self.frame()

                def soonest_s(v: Vehicle) -> float:
                    (se, sn), (ge, gn) = v.start.local(frame), v.goal.local(frame)
                    t0 = 0.0 if v.airborne else v.takeoff_window_s[0]
                    return t0 + math.hypot(ge - se, gn - sn) / v.speed_max_m_s

                ranked = [v.id for v in sorted(self.vehicles, key=soonest_s)]
                groups, k = [], 0
                for size in arrival.sizes:
                    groups.append(ranked[k : k + size])
                    k += size
            return {vid: k * arrival.gap_s for k, group in enumerate(groups) for vid in group}
        return dict.fromkeys(ids, 0.0)

    def with_team_arrival_s(self, t_s: float) -> Scenario | None:
        """The scenario with its team arrival requested at ``t_s`` (``required_s``, or the
        first slot or wave's ``first_s``); None for windows, which have no team time."""
        arrival = self.arrival
        if isinstance(arrival, Simultaneous):
            arrival = arrival.model_copy(update={"required_s": t_s})
        elif isinstance(arrival, Spaced | Waves):
            arrival = arrival.model_copy(update={"first_s": t_s})
        else:
            return None
        return self.model_copy(update={"arrival": arrival})

    def with_forecast_wind(self, wind: ForecastWind | None) -> Scenario:
        """The scenario with ``wind`` as its forecast (None: still air)."""
        return self.model_copy(update={"wind": wind})

    def vehicle(self, vehicle_id: str) -> Vehicle:
        for v in self.vehicles:
            if v.id == vehicle_id:
                return v
        raise KeyError(vehicle_id)

    def frame(self) -> LocalFrame:
        return self.area.frame()


def _names_every_vehicle(
    field: str, named: list[tuple[str, str]], ids: set[str], *, rule: str
) -> None:
    """``named`` (field path, vehicle id) must name each of ``ids`` exactly once; an error
    names the path and the vehicle."""
    seen: set[str] = set()
    for where, vid in named:
        if vid not in ids:
            raise ValueError(f"{where}: unknown vehicle {vid!r}")
        if vid in seen:
            raise ValueError(f"{where}: vehicle {vid!r} is named twice")
        seen.add(vid)
    missing = sorted(ids - seen)
    if missing:
        raise ValueError(
            f"{field}: vehicle{'s' if len(missing) > 1 else ''} "
            f"{', '.join(repr(m) for m in missing)} missing ({rule})"
        )


def _not_finite(value: Any) -> str:
    """Why a value the model refused as not finite is not a number: NaN or an infinity."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        return "not a finite number"
    return "not a number (NaN)" if math.isnan(x) else f"not a finite number ({x})"


def field_path(loc: tuple[int | str, ...], data: Any) -> list[int | str]:
    """An error's location as the file has it: without the ``kind`` tags pydantic inserts
    for a tagged union (``threats[0].radar.radius_m`` is ``threats[0].radius_m``)."""
    out: list[int | str] = []
    node = data
    for key in loc:
        if (
            isinstance(key, str)
            and isinstance(node, dict)
            and key not in node
            and node.get("kind") == key
        ):
            continue
        out.append(key)
        if isinstance(node, dict):
            node = node.get(key)
        elif isinstance(node, list | tuple) and isinstance(key, int) and 0 <= key < len(node):
            node = node[key]
        else:
            node = None
    return out


def _error_line(source: str, err: ValidationError, data: Any = None) -> str:
    first = err.errors()[0]
    path = field_path(tuple(first["loc"]), data)
    loc = ".".join(str(p) if not isinstance(p, int) else f"[{p}]" for p in path)
    loc = loc.replace(".[", "[")
    msg = first["msg"]
    if msg.startswith("Value error, "):
        msg = msg[len("Value error, ") :]
    if first["type"] == "extra_forbidden":
        msg = "unknown field"
    if first["type"] == "finite_number":
        msg = _not_finite(first.get("input"))
    more = err.error_count() - 1
    tail = f" (and {more} more error{'s' if more > 1 else ''})" if more else ""
    where = f"{source}: {loc}" if loc else source
    return f"{where}: {msg}{tail}"


def parse_scenario(data: Any, source: str = "scenario") -> Scenario:
    """Validate already-parsed data; raise ScenarioError with one line naming the field."""
    if not isinstance(data, dict):
        raise ScenarioError(f"{source}: the top level must be a mapping")
    try:
        return Scenario.model_validate(data)
    except ValidationError as err:
        raise ScenarioError(_error_line(source, err, data)) from None


def scenario_text(data: bytes, source: str = "scenario") -> str:
    """The text of a scenario file's bytes (UTF-8, an optional byte-order mark dropped).

    Raises
    ------
    ScenarioError
        One line naming ``source``: not a text file (NUL bytes), or not UTF-8 (the first
        bad byte and its offset).
    """
    if b"\x00" in data:
        raise ScenarioError(
            f"{source}: not a text file (NUL byte at offset {data.index(0)}); "
            "a scenario is YAML or JSON text"
        )
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        bad = data[err.start : err.start + 1].hex()
        raise ScenarioError(
            f"{source}: not UTF-8 text (byte 0x{bad} at offset {err.start}); "
            "a scenario is YAML or JSON text in UTF-8"
        ) from None


def _yaml_error_line(source: str, err: yaml.YAMLError) -> str:
    """One line for a YAML error: where (line, column) and what."""
    if isinstance(err, yaml.MarkedYAMLError) and err.problem_mark is not None:
        mark = err.problem_mark
        problem = err.problem or err.context or type(err).__name__
        context = ""
        if err.context and err.problem and err.context_mark is not None:
            cm = err.context_mark
            context = f" ({err.context} at line {cm.line + 1}, column {cm.column + 1})"
        where = f"line {mark.line + 1}, column {mark.column + 1}"
        return f"{source}: {where}: not valid YAML: {problem}{context}"
    if isinstance(err, yaml.reader.ReaderError):
        return (
            f"{source}: not valid YAML: unacceptable character #x{err.character:04x} "
            f"at offset {err.position}"
        )
    first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
    return f"{source}: not valid YAML: {first}"


def parse_scenario_text(text: str, source: str = "scenario", *, is_json: bool = False) -> Scenario:
    """Parse and validate a scenario's YAML (or, ``is_json``, JSON) text.

    Raises
    ------
    ScenarioError
        One line naming ``source``: a syntax error with its line and column, or the first
        field that does not validate (:func:`parse_scenario`).
    """
    try:
        data = json.loads(text) if is_json else yaml.safe_load(text)
    except json.JSONDecodeError as err:
        raise ScenarioError(
            f"{source}: line {err.lineno}, column {err.colno}: not valid JSON: {err.msg}"
        ) from None
    except yaml.YAMLError as err:
        raise ScenarioError(_yaml_error_line(source, err)) from None
    except RecursionError:
        raise ScenarioError(f"{source}: nested too deeply") from None
    return parse_scenario(data, source)


def load_scenario(path: str | Path) -> Scenario:
    """Read a YAML or JSON (``.json``) scenario file.

    Relative terrain directories are resolved against the file's folder.

    Raises
    ------
    ScenarioError
        One line naming the file: unreadable, not UTF-8 text, a syntax error (line and
        column) or the first field that does not validate.
    """
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as err:
        raise ScenarioError(f"{p}: cannot read scenario file ({err.strerror})") from None
    text = scenario_text(data, str(p))
    scenario = parse_scenario_text(text, str(p), is_json=p.suffix.lower() == ".json")
    if isinstance(scenario.terrain, SrtmTerrainSpec):
        directory = Path(scenario.terrain.directory)
        if not directory.is_absolute():
            directory = (p.parent / directory).resolve()
        scenario = scenario.model_copy(
            update={"terrain": SrtmTerrainSpec(kind="srtm", directory=str(directory))}
        )
    return scenario


def json_schema() -> dict[str, Any]:
    """The JSON Schema of scenario files (published as docs/scenario.schema.json)."""
    schema = Scenario.model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "Time-coordinated UAV team scenario"
    return schema


def heading_between(a: tuple[float, float], b: tuple[float, float]) -> float:
    """Compass heading in radians from local point ``a`` to ``b``."""
    return math.atan2(b[0] - a[0], b[1] - a[1]) % (2.0 * math.pi)
