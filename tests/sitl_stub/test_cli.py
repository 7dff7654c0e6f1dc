"""The CLI as a subprocess: serves on the SITL port layout and exits 0 on SIGINT."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import math
import os
import re
import signal
import socket
import subprocess
import sys
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_stub.__main__ import (
    BlackoutSpec,
    blackouts_from_args,
    homes_from_args,
    main,
    params_from_args,
    parse_args,
    speed_bias_from_args,
)
from sitl_stub.api import Home
from tests.sitl_stub.conftest import Client, free_port_base

PAPER = Path(__file__).resolve().parents[2] / "scenarios" / "paper_three_uav.yaml"


@dataclass
class StubRun:
    """A ``python -m sitl_stub`` child: its ports once ready, its stderr once stopped."""

    proc: asyncio.subprocess.Process
    ports: list[int] = field(default_factory=list)
    err: str = ""


@contextlib.asynccontextmanager
async def stub_cli(*args: str, stdin: bool = False) -> AsyncIterator[StubRun]:
    """Start the CLI, wait for its ready line; on leaving, SIGINT and expect exit 0."""
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "sitl_stub", *args,
        stdin=asyncio.subprocess.PIPE if stdin else asyncio.subprocess.DEVNULL,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    run = StubRun(proc)
    try:
        assert proc.stdout is not None
        async with asyncio.timeout(30):
            line = (await proc.stdout.readline()).decode()
        found = re.search(r"ready, ports \[([\d, ]+)\]", line)
        assert found, line
        run.ports = [int(p) for p in found.group(1).split(",")]
        yield run
        proc.send_signal(signal.SIGINT)
        async with asyncio.timeout(20):
            _, err = await proc.communicate()
        run.err = err.decode()
        assert proc.returncode == 0, run.err
        assert "Traceback" not in run.err
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()


async def test_cli_serves_two_vehicles_and_stops_cleanly_on_sigint() -> None:
    base = free_port_base(2)
    async with stub_cli(
        "--vehicles", "2", "--tcp-base", str(base), "--speedup", "10",
        "--home", "-35.36,149.16,584,90", "--wind", "5,270",
    ) as run:  # fmt: skip
        assert run.ports == [base, base + 10]
        for i in range(2):
            c = await Client.connect(base + 10 * i)
            try:
                hb = await c.recv("HEARTBEAT")
                assert hb.get_srcSystem() == i + 1
            finally:
                await c.close()


@pytest.mark.slow  # several seconds: left out of make test-quick
async def test_idle_exit_stops_a_simulator_whose_clients_are_gone() -> None:
    """--idle-exit S: running while nobody has connected yet and while a client is there;
    stopped (exit 0) S wall seconds after the last client left."""
    base = free_port_base(1)
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "sitl_stub", "--vehicles", "1", "--tcp-base", str(base),
        "--home", "-35.36,149.16,584,90", "--idle-exit", "1.5",
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        async with asyncio.timeout(30):
            assert b"ready" in await proc.stdout.readline()
        await asyncio.sleep(3.0)  # no client yet: it waits for the first
        assert proc.returncode is None
        c = await Client.connect(base)
        await c.recv("HEARTBEAT")
        await asyncio.sleep(3.0)  # a client is there: it runs on
        assert proc.returncode is None
        left = asyncio.get_running_loop().time()  # before the simulator can see it leave
        await c.close()
        async with asyncio.timeout(20):
            out, err = await proc.communicate()
        took = asyncio.get_running_loop().time() - left
        assert proc.returncode == 0, err.decode()
        assert b"no client for 1.5 s; stopping" in out
        # Not before the 1.5 s; the upper bound only tells a stop from running on (how long
        # the exit takes after the 1.5 s is the machine's).
        assert 1.5 <= took < 15.0
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()


@pytest.mark.slow  # several seconds: left out of make test-quick
def test_idle_exit_stops_a_simulator_whose_parent_was_killed() -> None:
    """Its stdout and stderr are pipes to a ground station that is SIGKILLed (as a service
    killed mid-flight): writing its last words to the dead pipe must not keep it running."""
    base = free_port_base(1)
    child = (
        "import subprocess, sys, time\n"
        "p = subprocess.Popen([sys.executable, '-m', 'sitl_stub', '--vehicles', '1',"
        f" '--tcp-base', '{base}', '--home', '-35.36,149.16,584,90', '--idle-exit', '1.5'],"
        " stdout=subprocess.PIPE, stderr=subprocess.PIPE)\n"
        "p.stdout.readline(); print(p.pid, flush=True); time.sleep(120)\n"
    )
    parent = subprocess.Popen([sys.executable, "-c", child], stdout=subprocess.PIPE, text=True)
    assert parent.stdout is not None
    pid = int(parent.stdout.readline())  # once it is ready
    parent.stdout.close()
    try:
        with socket.create_connection(("127.0.0.1", base), timeout=5):
            time.sleep(2.0)
            parent.kill()
            parent.wait()
        deadline = time.monotonic() + 15.0
        while time.monotonic() < deadline:
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                return
            time.sleep(0.2)
        pytest.fail("the simulator ran on after its parent died and its client left")
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)


async def test_cli_rejects_bad_home_with_clear_message() -> None:
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "sitl_stub", "--home", "95,10,0",
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    async with asyncio.timeout(20):
        _, err = await proc.communicate()
    assert proc.returncode == 2
    assert b"latitude" in err


async def test_cli_scenario_places_each_vehicle_at_its_start() -> None:
    from planner.geo import geodesic_distance_m
    from planner.scenario import load_scenario
    from planner.terrain import build_terrain

    path = Path(__file__).resolve().parents[2] / "scenarios" / "paper_three_uav.yaml"
    scenario = load_scenario(path)
    frame = scenario.frame()
    terrain = build_terrain(scenario)
    starts = []
    for v in scenario.vehicles[:3]:
        lat, lon = frame.to_geodetic(*v.start.local(frame))
        goal = v.goal.local(frame)
        start = v.start.local(frame)
        # Grid bearing to the goal; true north differs by the meridian convergence (< 1 deg).
        grid_hdg = math.degrees(math.atan2(goal[0] - start[0], goal[1] - start[1])) % 360.0
        # On the ground: the terrain elevation at the start, not the start's flight altitude.
        ground_m = float(terrain.elevation_m(np.array([start[0]]), np.array([start[1]]))[0])
        assert ground_m < v.start.alt_m - 100.0
        starts.append((lat, lon, ground_m, grid_hdg))

    async with stub_cli(
        "--scenario", str(path), "--vehicles", "3", "--tcp-base", "0", "--speedup", "1"
    ) as run:  # fmt: skip
        ports = run.ports
        assert len(ports) == 3
        for i, (port, (lat, lon, alt, hdg)) in enumerate(zip(ports, starts, strict=True)):
            c = await Client.connect(port)
            try:
                pos = await c.recv("GLOBAL_POSITION_INT", timeout=10)
            finally:
                await c.close()
            assert pos.get_srcSystem() == i + 1
            assert geodesic_distance_m(lat, lon, pos.lat * 1e-7, pos.lon * 1e-7) < 5.0
            assert pos.alt == round(alt * 1000) and pos.relative_alt == 0
            assert abs((pos.hdg / 100.0 - hdg + 180.0) % 360.0 - 180.0) < 2.0
        # Without --airspeed, each vehicle flies its scenario airspeed range.
        for port, v in zip(ports, scenario.vehicles, strict=True):
            c = await Client.connect(port)
            try:
                for name, want in (
                    (b"AIRSPEED_MIN", v.speed_min_m_s),
                    (b"AIRSPEED_CRUISE", v.cruise_m_s),
                    (b"AIRSPEED_MAX", v.speed_max_m_s),
                ):
                    c.send(mavlink2.MAVLink_param_request_read_message(0, 1, name, -1))
                    param = await c.recv(lambda m, n=name: m.get_type() == "PARAM_VALUE"
                                         and m.param_id == n.decode())  # fmt: skip
                    assert param.param_value == pytest.approx(want), (v.id, name)
            finally:
                await c.close()


def test_home_once_per_vehicle_puts_each_vehicle_at_its_own_home() -> None:
    args = parse_args([
        "--vehicles", "3", "--home", "-35.36,149.16,584,90", "--home", "-35.0,149.0,600",
        "--home", "10,20,30,180",
    ])  # fmt: skip
    assert homes_from_args(args) == [
        Home(-35.36, 149.16, 584.0, 90.0),
        Home(-35.0, 149.0, 600.0, 0.0),
        Home(10.0, 20.0, 30.0, 180.0),
    ]


def test_one_home_is_shared_with_vehicles_spaced_30_m() -> None:
    from planner.geo import geodesic_distance_m

    homes = homes_from_args(parse_args(["--vehicles", "3", "--home", "-35.36,149.16,584,90"]))
    assert (homes[0].lat_deg, homes[0].lon_deg) == pytest.approx((-35.36, 149.16), abs=1e-12)
    assert all((h.alt_m, h.heading_deg) == (584.0, 90.0) for h in homes)
    gaps = [
        geodesic_distance_m(a.lat_deg, a.lon_deg, b.lat_deg, b.lon_deg)
        for a, b in itertools.pairwise(homes)
    ]
    assert gaps == [pytest.approx(30.0, abs=0.01)] * 2


def test_airspeed_once_or_per_vehicle_and_blackouts_parse() -> None:
    args = parse_args(["--vehicles", "2", "--home", "0,0,0", "--airspeed", "16,20,26"])
    p = params_from_args(args)
    assert p is not None and len(p) == 2
    low, cruise, high = p[1].airspeed_min_m_s, p[1].airspeed_cruise_m_s, p[1].airspeed_max_m_s
    assert (low, cruise, high) == (16, 20, 26)
    args = parse_args([
        "--vehicles", "2", "--home", "0,0,0", "--airspeed", "16,16,16", "--airspeed", "9,12,20",
        "--blackout", "1,30,60", "--blackout", "0,0,5.5",
    ])  # fmt: skip
    p = params_from_args(args)
    assert p is not None and [q.airspeed_max_m_s for q in p] == [16, 20]
    assert params_from_args(parse_args(["--home", "0,0,0"])) is None
    assert blackouts_from_args(args) == [BlackoutSpec(1, 30.0, 60.0), BlackoutSpec(0, 0.0, 5.5)]


def test_speed_bias_parses_per_vehicle() -> None:
    args = parse_args([
        "--vehicles", "3", "--home", "0,0,0", "--speed-bias", "1,0.05", "--speed-bias", "2,-0.05",
    ])  # fmt: skip
    assert speed_bias_from_args(args) == {1: 0.05, 2: -0.05}
    assert speed_bias_from_args(parse_args(["--home", "0,0,0"])) == {}


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--vehicles", "3", "--home", "0,0,0", "--home", "1,1,1"], "--home given 2 times"),
        (["--vehicles", "2", "--home", "0,0,0", "--home", "95,1,1"], "--home '95,1,1'"),
        (["--home", "0,0,0", "--airspeed", "20,15,30"], "--airspeed needs 0 < MIN"),
        (["--home", "0,0,0", "--airspeed", "0,15,30"], "--airspeed needs 0 < MIN"),
        (["--home", "0,0,0", "--airspeed", "15,22,20"], "--airspeed needs 0 < MIN"),
        (["--home", "0,0,0", "--airspeed", "15,22"], "--airspeed needs 3"),
        (["--home", "0,0,0", "--airspeed", "a,b,c"], "--airspeed"),
        (
            ["--vehicles", "2", "--home", "0,0,0"] + ["--airspeed", "15,22,30"] * 3,
            "--airspeed given 3 times for --vehicles 2",
        ),
        (["--home", "0,0,0", "--blackout", "1,0,5"], "--blackout '1,0,5': I"),
        (["--home", "0,0,0", "--blackout", "0.5,0,5"], "--blackout '0.5,0,5': I"),
        (["--home", "0,0,0", "--blackout", "0,-1,5"], "START_S"),
        (["--home", "0,0,0", "--blackout", "0,1,0"], "DURATION_S"),
        (["--home", "0,0,0", "--truth-period", "0"], "--truth-period"),
        (["--home", "0,0,0", "--speed-bias", "1,0.05"], "--speed-bias '1,0.05': I"),
        (["--home", "0,0,0", "--speed-bias", "0,0.6"], "FRACTION"),
        (["--home", "0,0,0", "--speed-bias", "0"], "--speed-bias needs 2"),
        (["--home", "0,0,0", "--start-utc", "-5"], "--start-utc"),
        (["--home", "0,0,0", "--truth", "/no/such/dir/t.jsonl"], "--truth"),
        (["--home", "0,0,0", "--counters", "/no/such/dir/c.json"], "--counters"),
        ([], "give --home (once, or once per vehicle) or --scenario"),
        (["--home", "0,0,0", "--hill", "0,0,500,100"], "--hill needs --scenario"),
        (["--scenario", str(PAPER), "--hill", "30,40,0,5"], "--hill '30,40,0,5': hill radius"),
        (["--scenario", str(PAPER), "--hill", "30,40,100"], "--hill needs 4"),
    ],
)
def test_cli_rejects_bad_values_naming_the_option(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("sitl_stub: error: ") and message in err, err
    assert err.count("\n") == 1


async def test_cli_homes_airspeed_blackout_and_truth_end_to_end(tmp_path: Path) -> None:
    truth = tmp_path / "truth.jsonl"
    homes = [(-35.36, 149.16, 584.0), (-35.40, 149.20, 610.0)]
    async with stub_cli(
        "--vehicles", "2", "--tcp-base", "0", "--speedup", "20",
        "--home", "-35.36,149.16,584", "--home", "-35.40,149.20,610",
        "--airspeed", "18,21,27", "--blackout", "1,0,100000", "--truth", str(truth),
        "--truth-period", "1", "--start-utc", "1704067200",
    ) as run:  # fmt: skip
        ports = run.ports
        c0, c1 = await Client.connect(ports[0]), await Client.connect(ports[1])
        try:
            c0.send(mavlink2.MAVLink_param_request_read_message(1, 1, b"AIRSPEED_MIN", -1))
            param = await c0.recv("PARAM_VALUE")
            assert param.param_value == pytest.approx(18.0)
            # Vehicle 1 is blacked out from the start: its client hears nothing.
            assert await c1.try_recv(lambda _m: True, 1.0) is None
            # Run until vehicle 0 tells 11 s of its clock: 11 rows of truth a vehicle at least,
            # however slowly a busy machine runs the simulation.
            await c0.recv(lambda m: getattr(m, "time_boot_ms", 0) >= 11_000, timeout=60.0)
        finally:
            await c0.close()
            await c1.close()
    lines = [json.loads(x) for x in truth.read_text().splitlines()]
    assert lines[0]["format"] == "tcgcs-truth/1" and lines[0]["vehicles"] == 2
    assert lines[0]["speedup"] == 20.0 and lines[0]["period_s"] == 1.0
    assert lines[0]["start_utc_s"] == 1704067200.0
    rows = lines[1:]
    assert len(rows) >= 22 and len(rows) % 2 == 0  # 0 to 10 s of simulation at least, whole rows
    for row in rows:
        lat, lon, alt = homes[row["i"]]
        assert row["sysid"] == row["i"] + 1
        assert (row["lat_deg"], row["lon_deg"], row["alt_m"]) == pytest.approx((lat, lon, alt))
        assert row["armed"] is False and row["groundspeed_m_s"] == 0.0
    utcs = [r["utc_s"] for r in rows[::2]]
    assert utcs[0] == pytest.approx(lines[0]["start_utc_s"])
    assert all(b - a == pytest.approx(1.0) for a, b in itertools.pairwise(utcs))


async def test_cli_control_stdin_blackout_and_mission_timeout(tmp_path: Path) -> None:
    """``--control-stdin`` blacks a vehicle out on request and reports bad lines without
    stopping; ``--mission-timeout`` sets how soon a lost upload item is asked for again."""
    async with stub_cli(
        "--vehicles", "2", "--tcp-base", "0", "--speedup", "20",
        "--home", "-35.36,149.16,584", "--control-stdin", "--mission-timeout", "0.2",
        stdin=True,
    ) as run:  # fmt: skip
        proc, ports = run.proc, run.ports
        assert proc.stdin is not None and proc.stdout is not None
        c0, c1 = await Client.connect(ports[0]), await Client.connect(ports[1])
        try:
            assert (await c1.recv("HEARTBEAT")).get_srcSystem() == 2
            proc.stdin.write(b"blackout 7 0 10\nhello\nblackout 1 0 100000\n")
            await proc.stdin.drain()
            async with asyncio.timeout(10):
                said = (await proc.stdout.readline()).decode()
            assert said.strip() == "sitl_stub: blackout vehicle 1 at 0 s for 100000 s", said
            # What was already on its way drains; then vehicle 2 is silent, vehicle 1 is not.
            for _ in range(20):
                if await c1.try_recv(lambda _m: True, 0.3) is None:
                    break
            assert await c1.try_recv(lambda _m: True, 1.0) is None
            assert (await c0.recv("HEARTBEAT")).get_srcSystem() == 1
            # An upload whose item never comes: the item is asked for again every 0.2 s wall
            # (ArduPilot's default, and ours, is 1.5 s). Timed from the count sent to the
            # third re-request: 0.6 s at least, 4.5 s at the default, so a busy machine's
            # delays neither pass the default nor fail these.
            loop = asyncio.get_running_loop()
            t0 = loop.time()
            c0.send(mavlink2.MAVLink_mission_count_message(1, 1, 3, 0))
            req = "MISSION_REQUEST_INT"
            first = await c0.recv(req)
            again = [await c0.recv(req, timeout=5.0) for _ in range(3)]
            waited_s = loop.time() - t0
            assert first.seq == 0 and [m.seq for m in again] == [0, 0, 0]
            assert 3 * 0.2 - 0.01 <= waited_s < 3.0, waited_s
        finally:
            await c0.close()
            await c1.close()
        proc.stdin.close()  # end of control input: the team keeps running
        await asyncio.sleep(0.3)
        assert proc.returncode is None
    err = run.err
    assert "control: 'blackout 7 0 10': index, start or duration out of range" in err, err
    assert "control: 'hello': expected 'blackout INDEX START_SIM_S DURATION_S'" in err, err
    assert "Traceback" not in err
