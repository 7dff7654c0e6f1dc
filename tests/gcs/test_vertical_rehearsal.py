"""A vertical resolution flown against the simulator: ``python -m gcs rehearse --connect`` on
a simulator started on its own (lock step), two aircraft on one line head-on. The plan cannot
keep them apart (no timing does on one line: its schedule passes them 100 m apart; launched
with ``--allow-conflicts``, said and alarmed before launch), and no speed can in flight; one
of them climbs out of the way with MAV_CMD_DO_CHANGE_ALTITUDE, asked again at each waypoint
it starts (ArduPlane/GCS_Mavlink.cpp handle_command_int_DO_CHANGE_ALTITUDE sets the altitude
of the waypoint flown to; the next brings the mission's back), and comes back to its profile
once past. Judged by the simulator's truth log: the separation in 3-D for the whole flight,
each arrival on its slot, the mover's height."""

from __future__ import annotations

import asyncio
import json
import signal
import sys
from pathlib import Path

import pytest
import yaml

from planner.deconflict import pair_separation
from planner.plan import build_world, plan
from planner.retime import build_schedule
from planner.scenario import parse_scenario
from tests.gcs.conftest import start_stub
from tests.planner.conftest import head_on_scenario
from tests.sitl_stub.conftest import free_port_base
from tests.verdict import assert_flown

pytestmark = pytest.mark.slow  # a 25-minute flight at 200x: about 15 s of wall time


async def test_a_head_on_pair_flown_on_the_simulator_passes_apart_by_height(
    tmp_path: Path,
) -> None:
    data = head_on_scenario(arrival={"kind": "simultaneous", "required_s": 1500})
    scenario = parse_scenario(data)
    world = build_world(scenario)
    planned = build_schedule(scenario, plan(scenario, "astar", world=world), world=world)
    assert pair_separation(*planned.vehicles, step_s=0.5).distance_m < scenario.separation_m
    path = tmp_path / "head_on.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    base = free_port_base(2)
    truth, pace, out = tmp_path / "truth.jsonl", tmp_path / "pace", tmp_path / "flight.json"
    stub = await start_stub(path, base, truth, "--lockstep", str(pace), vehicles=2)
    try:
        engine = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "gcs", "rehearse", str(path),
            "--connect", f"tcp:127.0.0.1:{base}", f"tcp:127.0.0.1:{base + 10}",
            "--truth", str(truth), "--lockstep", str(pace), "--seed", "1", "--quiet",
            "--json", str(out), "--allow-conflicts",
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
        )  # fmt: skip
        async with asyncio.timeout(300):
            printed, err = await engine.communicate()
    finally:
        if stub.returncode is None:
            stub.send_signal(signal.SIGINT)
        async with asyncio.timeout(20):
            await stub.communicate()
    assert engine.returncode == 0, (printed.decode()[-3000:], err.decode()[-3000:])
    record = json.loads(out.read_text())
    # The planned conflict, said before launch.
    said = [
        e for e in record["events"]
        if e["kind"] == "alarm" and e["payload"].get("pair") == ["A", "B"]
    ]  # fmt: skip
    assert said and said[0]["payload"]["distance_m"] < scenario.separation_m, said
    moved = [
        e for e in record["events"]
        if e["kind"] == "conflict" and e["payload"].get("resolution") == "altitude"
    ]  # fmt: skip
    assert len(moved) == 1, [e["reason"] for e in record["events"] if e["kind"] == "conflict"]
    mover, offset_m = moved[0]["vehicle"], float(moved[0]["payload"]["offset_m"])
    # By the truth log: 3-D separation kept all flight, every arrival on its slot.
    verdict = assert_flown(
        record, truth, tolerance_s=1.0, team_shift_max_s=0.0, together_min_s=600.0
    )
    # The mover flew the manoeuvre: its height moved by most of the offset over the
    # encounter (the planned height is 500 m: the start's and the goal's), and was back on it
    # a minute after the manoeuvre's end.
    track = verdict.tracks[mover]
    start = float(record["start_utc_s"])
    until_s = float(moved[0]["payload"]["until_s"])
    during = track.between(start + float(moved[0]["t_s"]), start + until_s).alt_m
    away_m = float(max(during - 500.0, key=abs))
    assert away_m * offset_m > 0 and abs(away_m) >= 0.8 * abs(offset_m), (away_m, offset_m)
    back = track.between(start + until_s + abs(offset_m) / 2.0 + 60.0, start + 1400.0).alt_m
    assert back.size and abs(back - 500.0).max() <= 30.0, back
