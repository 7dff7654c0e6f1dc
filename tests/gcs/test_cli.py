"""`python -m gcs` as operators run it: a subprocess against stub vehicles over loopback."""

from __future__ import annotations

import asyncio
import re
import sys
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from gcs.__main__ import ProgressLines
from gcs.mavlink.mission_protocol import Upload
from planner.mission import Autopilot, MissionItem, items_equal
from planner.missionfile import read_mission_file, to_wpl
from sitl_stub.api import Home, SimTeam
from sitl_stub.model import displace_deg
from tests.gcs.conftest import HOME


async def gcs(*args: str, timeout_s: float = 60.0) -> tuple[int, str, str]:
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "gcs", *args,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    async with asyncio.timeout(timeout_s):
        out, err = await proc.communicate()
    assert proc.returncode is not None
    return proc.returncode, out.decode(), err.decode()


def mission(n: int, command: int = mavlink2.MAV_CMD_NAV_WAYPOINT) -> list[MissionItem]:
    """Home, then ``n - 1`` waypoints 50 m apart heading north."""
    rel = mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
    items = []
    for i in range(n):
        lat, lon = displace_deg(HOME[0], HOME[1], HOME[2], 50.0 * i, 10.0 * (i % 3))
        if i == 0:
            frame, cmd, z = 0, mavlink2.MAV_CMD_NAV_WAYPOINT, HOME[2]
        else:
            frame, cmd, z = rel, command, 100.0 + i
        x, y = round(lat * 1e7), round(lon * 1e7)
        items.append(MissionItem(i, frame, cmd, 0, 1, 0.0, 0.0, 0.0, 0.0, x, y, z))
    return items


async def test_upload_verify_then_download_round_trips_200_items(tmp_path: Path) -> None:
    items = mission(200)
    src = tmp_path / "m.waypoints"
    src.write_text(to_wpl(items))
    async with SimTeam.start(homes=[Home(*HOME)], tcp_base=0, speedup=5.0) as team:
        conn = f"tcp:127.0.0.1:{team.ports[0]}"
        code, out, err = await gcs("mission", "upload", conn, str(src), "--verify")
        assert code == 0, err
        assert "uploaded 200 mission items to vehicle 1" in out and "verified" in out
        stored = team.vehicles[0].mission.items()
        assert items_equal(items[1:], list(stored[1:]), autopilot=Autopilot.ARDUPILOT)
        code, out, err = await gcs("mission", "download", conn, "--out", str(tmp_path / "d.plan"))
        assert code == 0, err
        back = read_mission_file(tmp_path / "d.plan")
        assert len(back) == 200 and items_equal(items[1:], back[1:], autopilot=Autopilot.ARDUPILOT)


async def test_rejected_item_exits_1_naming_the_item_and_reason(tmp_path: Path) -> None:
    items = mission(5)
    servo = mavlink2.MAV_CMD_DO_SET_SERVO
    items[3] = MissionItem(3, 3, servo, 0, 1, 1.0, 1500.0, 0.0, 0.0, 0, 0, 0.0)
    src = tmp_path / "bad.waypoints"
    src.write_text(to_wpl(items))
    async with SimTeam.start(homes=[Home(*HOME)], tcp_base=0, speedup=5.0) as team:
        before = team.vehicles[0].mission.items()
        code, _, err = await gcs("mission", "upload", f"tcp:127.0.0.1:{team.ports[0]}", str(src))
        assert code == 1
        assert "vehicle 1" in err and "item 3" in err and "UNSUPPORTED" in err, err
        assert team.vehicles[0].mission.items() == before  # nothing lost


async def test_bad_input_exits_2_without_touching_the_vehicle(tmp_path: Path) -> None:
    code, _, err = await gcs("mission", "upload", "tcp:127.0.0.1:9", str(tmp_path / "none.plan"))
    assert code == 2 and "none.plan" in err and "cannot read" in err
    code, _, err = await gcs("mission", "download", "bogus:1:2", "--out", "x.plan")
    assert code == 2 and "bogus:1:2" in err
    code, _, err = await gcs("status", "tcp:127.0.0.1:9", "--signing-key", "abc")
    assert code == 2 and "--signing-key" in err


async def test_no_vehicle_exits_1_after_the_wait() -> None:
    code, _, err = await gcs("command", "tcp:127.0.0.1:9", "arm", "--wait", "0.5")
    assert code == 1 and "no HEARTBEAT" in err and "0.5 s" in err


async def test_status_prints_a_line_per_vehicle_and_commands_take_effect() -> None:
    homes = [Home(*HOME), Home(HOME[0] + 0.001, HOME[1], HOME[2])]
    async with SimTeam.start(homes=homes, tcp_base=0, speedup=5.0) as team:
        conns = [f"tcp:127.0.0.1:{p}" for p in team.ports]
        code, out, err = await gcs("command", conns[1], "mode", "GUIDED")
        assert code == 0 and "vehicle 2: mode GUIDED accepted" in out, err
        code, _, err = await gcs("command", conns[1], "mode", "FLY")
        assert code == 2 and "valid modes" in err and "GUIDED" in err
        code, out, err = await gcs("status", *conns, "--count", "2", "--period", "0.5")
        assert code == 0, err
        lines = out.strip().splitlines()
        assert len(lines) == 4, out
        last = {line.split()[1]: line for line in lines[2:]}
        assert set(last) == {"1", "2"}
        assert "GUIDED" in last["2"] and "MANUAL" in last["1"]
        assert f"{homes[1].lat_deg:.5f}" in last["2"] and "link ok" in last["2"]


def test_progress_lines_say_nothing_in_the_first_second_then_one_a_second_at_most(
    capsys: pytest.CaptureFixture[str],
) -> None:
    now = [0.0]
    lines = ProgressLines(clock=lambda: now[0])
    up = Upload(mission(200), send_ahead=True, window=8, target_system=1)
    lines.watch(up)
    up.start(0.0)
    for seq in range(60):
        up.handle(request(seq), now[0])
        lines.poll()
        now[0] += 0.01  # 0.6 s: a fast transfer
    assert capsys.readouterr().err == ""
    up.tick(up.next_deadline() or 0.0)  # one resend
    for t in (1.0, 1.5, 1.99, 2.0, 2.7, 3.1):
        now[0] = t
        lines.poll()
    err = capsys.readouterr().err
    assert err.splitlines() == ["uploading 59/200 items, 1 resend"] * 3  # at 1.0, 2.0, 3.1 s
    up.handle(request(120), 3.2)
    now[0] = 4.2
    lines.poll()
    assert capsys.readouterr().err == "uploading 120/200 items, 1 resend\n"


def request(seq: int) -> object:
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    msg = mavlink2.MAVLink_mission_request_int_message(255, 0, seq, 0)
    (decoded,) = mavlink2.MAVLink(None).parse_buffer(msg.pack(mav)) or []
    return decoded


@pytest.mark.slow  # several seconds: left out of make test-quick
async def test_a_slow_upload_and_download_print_progress_on_stderr(tmp_path: Path) -> None:
    """100 ms each way: 120 items take at least 15 round trips of 0.2 s each way, in any load."""
    src = tmp_path / "m.waypoints"
    src.write_text(to_wpl(mission(120)))
    async with SimTeam.start(homes=[Home(*HOME)], tcp_base=0, speedup=5.0) as team:
        team.vehicles[0].link.faults(latency_ms=100.0)
        conn = f"tcp:127.0.0.1:{team.ports[0]}"
        code, _, err = await gcs("mission", "upload", conn, str(src))
        assert code == 0, err
        progress = re.findall(r"^uploading (\d+)/120 items, \d+ resends?$", err, re.MULTILINE)
        assert progress and len(progress) == len(err.splitlines()), err
        assert [int(n) for n in progress] == sorted(int(n) for n in progress)
        code, _, err = await gcs("mission", "download", conn, "--out", str(tmp_path / "d.plan"))
        assert code == 0, err
        assert re.search(r"^downloading \d+/120 items, \d+ resends?$", err, re.MULTILINE), err
