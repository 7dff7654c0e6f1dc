"""The truth recorder and scheduled blackouts, in-process on a hand-stepped team."""

from __future__ import annotations

import asyncio
import io
import json
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_stub.api import Home, SimTeam
from sitl_stub.autopilot import Mode
from sitl_stub.truth import TRUTH_FORMAT, TruthRecorder
from tests.sitl_stub.conftest import Client

HOMES = [Home(-35.36, 149.16, 584.0, 0.0), Home(-35.37, 149.17, 600.0, 90.0)]
START_UTC_S = 1_700_000_000.0


def read_lines(path: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in path.read_text().splitlines()]


async def test_truth_rows_match_true_state_every_period(tmp_path: Path) -> None:
    out = tmp_path / "truth.jsonl"
    async with SimTeam.start(
        homes=HOMES,
        tcp_base=0,
        speedup=200.0,
        start_utc_s=START_UTC_S,
        run=False,
        truth_out=out,
        truth_period_s=0.5,
    ) as team:
        # The header and the first row (sim time 0) are on disk at once.
        first = read_lines(out)
        assert first[0] == {
            "format": TRUTH_FORMAT,
            "vehicles": 2,
            "speedup": 200.0,
            "start_utc_s": START_UTC_S,
            "period_s": 0.5,
        }
        assert [r["sysid"] for r in first[1:]] == [1, 2]
        ap = team.vehicles[0].autopilot
        assert ap.arm(force=True)[0]
        assert ap.set_mode(Mode.TAKEOFF)
        expected: list[dict[str, Any]] = []
        for _ in range(12):  # 12 rows at 0.5 s = 60 steps of 0.1 s
            team.step(5)
            for i in range(2):
                s = team.true_state(i)
                expected.append(
                    {
                        "utc_s": team.utc_s,
                        "i": i,
                        "sysid": i + 1,
                        "lat": s.lat_deg,
                        "lon": s.lon_deg,
                        "alt": s.alt_m,
                        "gs": s.groundspeed_m_s,
                        "armed": team.vehicles[i].autopilot.armed,
                        "on_ground": s.on_ground,
                    }
                )
    rows = read_lines(out)[3:]  # closed: everything flushed
    assert len(rows) == len(expected) == 24
    for row, exp in zip(rows, expected, strict=True):
        assert row["utc_s"] == pytest.approx(exp["utc_s"], abs=1e-6)
        assert (row["i"], row["sysid"], row["armed"]) == (exp["i"], exp["sysid"], exp["armed"])
        assert row["on_ground"] == exp["on_ground"]
        assert row["lat_deg"] == pytest.approx(exp["lat"], abs=1e-8)
        assert row["lon_deg"] == pytest.approx(exp["lon"], abs=1e-8)
        assert row["alt_m"] == pytest.approx(exp["alt"], abs=1e-3)
        assert row["groundspeed_m_s"] == pytest.approx(exp["gs"], abs=1e-3)
    assert rows[-2]["utc_s"] == pytest.approx(START_UTC_S + 6.0)
    assert rows[-2]["armed"] and not rows[-1]["armed"]
    assert rows[-2]["groundspeed_m_s"] > 5.0  # vehicle 0 rolls; vehicle 1 stays put
    assert rows[-1]["lat_deg"] == pytest.approx(HOMES[1].lat_deg, abs=1e-9)


class _CountingIO(io.StringIO):
    def __init__(self) -> None:
        super().__init__()
        self.flushes = 0

    def flush(self) -> None:
        self.flushes += 1
        super().flush()


async def test_truth_is_flushed_in_whole_lines_at_least_every_50_lines() -> None:
    team = SimTeam.create(homes=HOMES * 2, tcp_base=0)  # 4 vehicles: 4 lines a row
    buf = _CountingIO()
    rec = TruthRecorder(buf, team.vehicles, team.clock, period_s=0.3, flush_wall_s=1e9)
    rec.start()
    team.server.add_step_listener(rec.on_step)
    seen = buf.getvalue()
    assert seen.count("\n") == 5 and buf.flushes == 1
    for _ in range(300):
        team.step()
        text = buf.getvalue()
        assert text.endswith("\n")
        # Never more than 50 recorded lines (plus one row) wait in the buffer.
        assert 1 + rec.lines_recorded - (text.count("\n") - 1) < 50 + 4
    # Period 0.3 s on 0.1 s steps: rows at 0.0, 0.3, ..., 30.0 s.
    rec.close()
    lines = buf.getvalue().splitlines()
    assert len(lines) == 1 + 4 * 101 == 1 + rec.lines_recorded
    utcs = sorted({json.loads(line)["utc_s"] for line in lines[1:]})
    assert [round(u - utcs[0], 6) for u in utcs[:4]] == [0.0, 0.3, 0.6, 0.9]
    rec.close()  # idempotent


def test_truth_period_must_be_positive() -> None:
    team = SimTeam.create(homes=HOMES, tcp_base=0)
    with pytest.raises(ValueError, match="truth period"):
        TruthRecorder(io.StringIO(), team.vehicles, team.clock, period_s=0.0)


async def _heard(c: Client, timeout: float = 0.3) -> int:
    """Messages that arrived within ``timeout`` wall seconds."""
    got = 0
    while await c.try_recv(lambda _m: True, timeout) is not None:
        got += 1
    return got


async def test_scheduled_blackout_silences_that_vehicle_only() -> None:
    async with SimTeam.start(homes=HOMES, tcp_base=0, run=False) as team:
        clients = [await Client.connect(p) for p in team.ports]
        try:
            await until_connected(team)
            team.schedule_blackout(1, start_sim_s=2.0, duration_s=3.0)
            links = [v.link for v in team.vehicles]
            team.step(15)  # to 1.5 s: both heard
            assert [await _heard(c) > 0 for c in clients] == [True, True]
            team.step(10)  # 2.5 s: vehicle 1 dark from 2.0 s
            for c in clients:
                await _heard(c)  # drain what was sent before 2.0 s
            assert links[1].in_blackout and not links[0].in_blackout
            assert links[1].blackout_until_sim_s == pytest.approx(5.0)
            # Vehicle 1's client is sent nothing now; commands to it are dropped too.
            clients[1].send(
                mavlink2.MAVLink_command_long_message(
                    2, 1, mavlink2.MAV_CMD_REQUEST_MESSAGE, 0, 0, 0, 0, 0, 0, 0, 0
                )
            )
            team.step(10)  # 3.5 s
            assert [await _heard(c) > 0 for c in clients] == [True, False]
            assert links[1].outbound.blacked_out > 0 and links[1].inbound.blacked_out == 1
            assert links[0].outbound.blacked_out == links[0].inbound.blacked_out == 0
            team.step(16)  # 5.1 s: over
            assert not links[1].in_blackout
            assert [await _heard(c) > 0 for c in clients] == [True, True]
        finally:
            for c in clients:
                await c.close()


async def until_connected(team: SimTeam) -> None:
    async with asyncio.timeout(5):
        while not all(p.connections for p in team.server.ports):
            await asyncio.sleep(0.01)


def test_blackout_already_due_starts_at_once_and_a_longer_one_is_kept() -> None:
    team = SimTeam.create(homes=HOMES, tcp_base=0)
    team.step(30)  # 3.0 s
    team.schedule_blackout(0, start_sim_s=1.0, duration_s=10.0)  # started late: ends at 11 s
    assert team.vehicles[0].link.blackout_until_sim_s == pytest.approx(11.0)
    team.schedule_blackout(0, start_sim_s=4.0, duration_s=1.0)  # inside: does not shorten it
    team.step(20)
    assert team.vehicles[0].link.blackout_until_sim_s == pytest.approx(11.0)
    team.schedule_blackout(0, start_sim_s=0.0, duration_s=1.0)  # over already: no effect
    assert team.vehicles[0].link.blackout_until_sim_s == pytest.approx(11.0)
    assert not team.server._step_listeners  # fired listeners are removed
    with pytest.raises(ValueError, match="no vehicle 2"):
        team.schedule_blackout(2, 0.0, 1.0)
    with pytest.raises(ValueError, match="duration"):
        team.schedule_blackout(0, 0.0, 0.0)


async def test_truth_keeps_true_airspeed_and_adds_eas_with_speed_bias(tmp_path: Path) -> None:
    """``airspeed_m_s`` is true airspeed, ``eas_m_s`` the true equivalent airspeed; vehicle 1's
    +5 % speed bias (SimTeam.start(speed_bias=...)) shows in both but not in its VFR_HUD."""
    out = tmp_path / "truth.jsonl"
    async with SimTeam.start(
        homes=HOMES, tcp_base=0, run=False, truth_out=out, speed_bias={1: 0.05}
    ) as team:
        assert [v.autopilot.params.speed_bias for v in team.vehicles] == [0.0, 0.05]
        for v in team.vehicles:
            assert v.autopilot.arm(force=True)[0]
            assert v.autopilot.set_mode(Mode.TAKEOFF)
        team.step(900)
        hud = [v.message("VFR_HUD").airspeed for v in team.vehicles]
    last = read_lines(out)[-2:]
    for row in last:
        assert row["airspeed_m_s"] > row["eas_m_s"]  # 600+ m AMSL: TAS above EAS
    assert last[0]["eas_m_s"] == pytest.approx(22.0, abs=0.3)
    assert last[1]["eas_m_s"] == pytest.approx(22.0 * 1.05, abs=0.3)
    assert hud == pytest.approx([22.0, 22.0], abs=0.3)


def test_speed_bias_is_checked() -> None:
    with pytest.raises(ValueError, match="no vehicle 2"):
        SimTeam.create(homes=HOMES, speed_bias={2: 0.05})
    with pytest.raises(ValueError, match="speed_bias"):
        SimTeam.create(homes=HOMES, speed_bias={0: 0.9})
