"""The flight tests' verdict on a flown team, by :mod:`tests.oracle` alone: the simulator's
truth log against the scenario as planned, nothing taken from the coordinator's figures but
which simulated vehicle each id is, the slots the schedule set before launch and how far the
team time moved (which the test bounds).

:func:`judge` measures a flight; :meth:`Verdict.check` (or :func:`assert_flown`, both at once)
asserts, all failures said together with the figures and the flight's story:

- the team time moved by no more than the test allows (``required_arrival_s`` against the
  ``planned_arrival_s`` set before launch);
- every vehicle that should arrive passed its goal within ``tolerance_s`` of its planned slot
  moved as the coordinator moved it (the record's ``target_arrival_utc_s``: ordered slots
  move apart, the ones before a late vehicle's staying), each move within the test's bound and
  the moved slots keeping the scenario's rule (spacing, waves, one time), checked here;
- every pair kept the scenario's separation in 3-D at every truth sample both were airborne,
  the whole flight long, and every pair flew together long enough for that to mean something;
- no airborne true sample lies inside a forbidden zone (the scenario's, from when each was
  there, and any the test adds).
"""

from __future__ import annotations

import itertools
from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tests import oracle
from tests.flightstory import routine_story, story


@dataclass(frozen=True)
class Verdict:
    """What the oracle measured of one flight (mission s are after ``start_utc_s``)."""

    start_utc_s: float
    tracks: dict[str, oracle.Track]
    ground: oracle.Ground
    passages_s: dict[str, float | None]
    slots_s: dict[str, oracle.Slot]
    shift_s: float
    """How far the team time moved (the first slot's, for ordered slots)."""
    slot_moves_s: dict[str, float]
    """How far each vehicle's slot moved in flight (0 for windows: the window is its slot)."""
    rule_breaks: list[str]
    """How the slots as moved break the scenario's arrival rule (:func:`tests.oracle.
    slot_rule_breaks`)."""
    separation: oracle.Separation
    together_s: float
    """The least time any pair was airborne together (truth samples times the period)."""
    zones: list[oracle.Zone]
    separation_m: float
    """The scenario's minimum."""
    tolerance_s: float
    team_shift_max_s: float
    together_min_s: float
    arriving: frozenset[str]
    """The vehicles that must pass their goals on their slots."""
    told: str
    """The flight's story, for a failure."""
    routine: dict[str, str]
    """Per vehicle, its routine events (:func:`tests.flightstory.routine_story`), for a
    vehicle off its slot."""

    def misses(self) -> dict[str, Any]:
        """The arriving vehicles off their slots (s off, or None: never passed)."""
        return oracle.arrival_misses(
            {v: t for v, t in self.passages_s.items() if v in self.arriving},
            {v: s for v, s in self.slots_s.items() if v in self.arriving},
            tolerance_s=self.tolerance_s,
            shift_s=self.slot_moves_s,
        )

    def entries(self) -> list[tuple[str, str, float]]:
        """Airborne true samples inside a forbidden zone: (vehicle, zone, UTC)."""
        return oracle.zone_entries(self.tracks, self.ground, self.zones)

    def problems(self) -> list[str]:
        """Every way the flight failed the verdict (the module's list), each with figures."""
        out = []
        if abs(self.shift_s) > self.team_shift_max_s:
            out.append(
                f"the team time moved {self.shift_s:+.1f} s (allowed {self.team_shift_max_s:g})"
            )
        moved = {
            v: round(s, 1) for v, s in self.slot_moves_s.items() if abs(s) > self.team_shift_max_s
        }
        if moved:
            out.append(f"slots moved by (s) {moved} (allowed {self.team_shift_max_s:g})")
        out.extend(f"the slots as moved break the arrival rule: {b}" for b in self.rule_breaks)
        misses = self.misses()
        if misses:
            out.append(f"off their slots by (s, None: never passed): {misses}")
        if self.together_s < self.together_min_s:
            out.append(f"a pair flew together only {self.together_s:.0f} s")
        if not self.separation.least_m >= self.separation_m:
            out.append(f"separation lost: {self.separation} < {self.separation_m:g} m")
        entries = self.entries()
        if entries:
            out.append(f"inside a forbidden zone: {oracle.summary(entries)}")
        return out

    def check(self) -> None:
        """Assert the flight has none of :meth:`problems` (all of them said at once)."""
        print(self)
        problems = self.problems()
        late = [
            f"{vid}'s speed, link and clock events:\n{self.routine.get(vid, '')}"
            for vid in self.misses()
        ]
        assert not problems, "\n".join([*problems, str(self), self.told, *late])

    def errors_s(self) -> dict[str, float | None]:
        """Each passage against its slot moved by the shift: s early (-), late (+), 0 inside
        a window; None if the goal was never passed."""
        out: dict[str, float | None] = {}
        for vid, (lo, hi) in self.slots_s.items():
            t = self.passages_s.get(vid)
            lo, hi = lo + self.slot_moves_s[vid], hi + self.slot_moves_s[vid]
            out[vid] = None if t is None else round(min(0.0, t - lo) + max(0.0, t - hi), 3)
        return out

    def __str__(self) -> str:
        apart = {
            v: round(s, 1) for v, s in self.slot_moves_s.items() if abs(s - self.shift_s) > 1e-3
        }
        return (
            f"team time moved {self.shift_s:+.1f} s"
            + (f" (slots moved apart: {apart})" if apart else "")
            + "; passages against the slots (s): "
            f"{self.errors_s()}; "
            f"least separation {self.separation}; pairs together at least "
            f"{self.together_s:.0f} s"
        )


def team_shift_s(record: Mapping[str, Any]) -> float:
    """How far the team time moved in flight: the final against the one set before launch
    (0 with no team time, as for windows)."""
    final, planned = record["required_arrival_s"], record["planned_arrival_s"]
    return 0.0 if final is None or planned is None else float(final) - float(planned)


def slot_moves_s(
    scenario: Mapping[str, Any], record: Mapping[str, Any]
) -> tuple[dict[str, float], dict[str, float]]:
    """How far each vehicle's slot moved in flight (the record's ``target_arrival_utc_s``
    against its ``planned_arrival_s``; 0 for windows, judged against the window itself), and
    each slot as moved (mission s)."""
    start = float(record["start_utc_s"])
    if scenario["arrival"]["kind"] == "windows":
        return {v["id"]: 0.0 for v in record["vehicles"]}, {}
    final = {v["id"]: float(v["target_arrival_utc_s"]) - start for v in record["vehicles"]}
    moves = {v["id"]: final[v["id"]] - float(v["planned_arrival_s"]) for v in record["vehicles"]}
    return moves, final


def least_overlap_s(tracks: Mapping[str, oracle.Track]) -> float:
    """The least time (truth samples both airborne, times the sampling period) any pair of
    vehicles flew together."""
    stamps = {v: set(np.round(tr.utc_s[tr.airborne], 3).tolist()) for v, tr in tracks.items()}
    periods = [float(np.median(np.diff(tr.utc_s))) for tr in tracks.values() if len(tr) > 1]
    period_s = min(periods) if periods else 0.0
    pairs = itertools.combinations(sorted(stamps), 2)
    return min((len(stamps[a] & stamps[b]) * period_s for a, b in pairs), default=0.0)


def judge(
    record: Mapping[str, Any],
    truth: Path | str,
    *,
    tolerance_s: float,
    team_shift_max_s: float,
    together_min_s: float,
    scenario: Mapping[str, Any] | None = None,
    arriving: Collection[str] | None = None,
    extra_zones: Iterable[oracle.Zone] = (),
) -> Verdict:
    """Measure a flight from its truth log (asserting nothing: :meth:`Verdict.check`).

    ``team_shift_max_s``: how far the team time may move in flight, either way (0 where
    nothing should move it). ``together_min_s``: every pair must have been airborne together
    this long, or the separation check says little. ``scenario``: the scenario as planned
    (by default the record's, as flown). ``arriving``: the vehicles that must pass their
    goal on their slot (by default every one). ``extra_zones``: forbidden zones the test
    adds (an operator's)."""
    scenario = record["scenario"] if scenario is None else scenario
    start = float(record["start_utc_s"])
    tracks = oracle.tracks_by_vehicle(truth, record)
    ground = oracle.Ground.of(scenario)
    slots = oracle.planned_slots(scenario, record)
    moves, final = slot_moves_s(scenario, record)
    zones = [*oracle.scenario_zones(scenario, start, oracle.takeoffs(tracks)), *extra_zones]
    return Verdict(
        start_utc_s=start,
        tracks=tracks,
        ground=ground,
        passages_s=oracle.passages(tracks, ground, oracle.goals(scenario), start),
        slots_s=slots,
        shift_s=team_shift_s(record),
        slot_moves_s=moves,
        rule_breaks=oracle.slot_rule_breaks(scenario, final),
        separation=oracle.separation(tracks),
        together_s=least_overlap_s(tracks),
        zones=zones,
        separation_m=float(scenario["separation_m"]),
        tolerance_s=tolerance_s,
        team_shift_max_s=team_shift_max_s,
        together_min_s=together_min_s,
        arriving=frozenset(slots if arriving is None else arriving),
        told=story(record["events"]),
        routine={vid: routine_story(record["events"], vid) for vid in slots},
    )


def assert_flown(record: Mapping[str, Any], truth: Path | str, **how: Any) -> Verdict:
    """:func:`judge` a flight (``how``: its keyword arguments) and assert it flew as planned
    (the module's list)."""
    verdict = judge(record, truth, **how)
    verdict.check()
    return verdict


def routes_into_disc(
    record: Mapping[str, Any], label: str, centre_en_m: tuple[float, float], radius_m: float
) -> set[str]:
    """The vehicles whose planned route ``label`` (the record's ``planned_paths``: what the
    coordinator planned, a decision, not a figure of the flight) comes inside a disc (local
    m): e.g. the ``initial`` routes a zone that pops up lies across."""
    out = set()
    for v in record["vehicles"]:
        for path in v["planned_paths"]:
            if path["label"] != label:
                continue
            p = np.asarray(path["en_m"], dtype=np.float64)
            a, d = p[:-1], p[1:] - p[:-1]
            w = np.asarray(centre_en_m) - a
            u = np.clip((w * d).sum(axis=1) / np.maximum((d * d).sum(axis=1), 1e-9), 0.0, 1.0)
            if (np.hypot(*(w - u[:, None] * d).T) < radius_m).any():
                out.add(v["id"])
    return out
