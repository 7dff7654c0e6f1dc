"""A coordinator whose event loop is held longer than the lock step waits for it: the simulator
flies on without it (as real aircraft would), and the coordinator says so when its loop turns
again: an alarm with the flight seconds that ran unwatched. The team, on its missions at the
speeds last commanded meanwhile, is then judged from the truth log by the independent oracle:
every aircraft on its slot and the separation kept, the whole flight long.

The hold is a subscriber of the flight's event bus that blocks the loop (``time.sleep``, as a
careless client's callback or a long computation in the loop would) for 4 s of wall time once
every aircraft is timed on its route: 1 s past :data:`sitl_stub.lockstep.STALE_WALL_S`, some
50 s of flight at 50x.
"""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

import pytest
import yaml

from gcs.coordination.bus import EventBus
from gcs.coordination.config import FlightConfig
from gcs.coordination.events import EventKind
from gcs.rehearsal.rehearse import RehearsalOptions, rehearse
from planner.scenario import load_scenario
from sitl_stub.lockstep import STALE_WALL_S
from tests import oracle
from tests.flightstory import story
from tests.teams import ring_team

pytestmark = pytest.mark.slow

HOLD_WALL_S = STALE_WALL_S + 1.0
SPEEDUP = 50.0
REQUIRED_S = 560.0
"""Later than the earliest common arrival (about 468 s, at top speed): the team flies with
room to make up a lag, and its team time has no reason to move."""


async def test_a_held_event_loop_is_an_alarm_and_the_team_still_keeps_its_slots(
    tmp_path: Path,
) -> None:
    data = ring_team(3)
    path = tmp_path / "scenario.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    truth = tmp_path / "truth.jsonl"
    bus = EventBus()
    held = asyncio.Event()

    async def hold_once_all_are_on_route() -> None:
        on_route: set[str] = set()
        with bus.subscribe() as sub:
            async for ev in sub:
                if ev.kind is EventKind.ROUTE and ev.vehicle is not None:
                    on_route.add(ev.vehicle)
                if len(on_route) == len(data["vehicles"]):
                    time.sleep(HOLD_WALL_S)  # the loop is held: nothing else runs
                    held.set()
                    return

    holder = asyncio.create_task(hold_once_all_are_on_route())
    record = await rehearse(
        RehearsalOptions(
            scenario_path=path,
            scenario=load_scenario(path),
            speedup=SPEEDUP,
            truth=truth,
            required_arrival_s=REQUIRED_S,
            quiet=True,
            bus=bus,
            config=FlightConfig(seed=0),
        )
    )
    holder.cancel()
    told = story(record["events"])
    assert held.is_set(), f"never held\n{told}"
    said = [e for e in record["events"] if e["kind"] == "alarm" and "unwatched" in e["reason"]]
    assert len(said) == 1, told
    # A held loop of 4 s lets the simulator run free for about 1 s of wall time at 50x.
    unwatched_s = said[0]["payload"]["unwatched_s"]
    assert 10.0 <= unwatched_s <= HOLD_WALL_S * SPEEDUP, said
    assert record["state"] == "completed", f"{record['state_reason']}\n{told}"

    scenario = record["scenario"]
    tracks = oracle.tracks_by_vehicle(truth, record)
    passed = oracle.passages(
        tracks, oracle.Ground.of(scenario), oracle.goals(scenario), record["start_utc_s"]
    )
    # The aircraft flew their planned speeds while unwatched, in still air, with room to make
    # up any lag after: the team time does not move.
    assert record["required_arrival_s"] == record["planned_arrival_s"], told
    slots = oracle.planned_slots(scenario, record)
    misses = oracle.arrival_misses(passed, slots, tolerance_s=1.0)
    assert not misses, f"{misses}\n{told}"
    sep = oracle.separation(tracks)
    assert sep.compared > 2_000
    assert sep.least_m >= scenario["separation_m"], f"{sep}\n{told}"
