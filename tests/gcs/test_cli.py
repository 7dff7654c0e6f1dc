"""`python -m gcs` as operators run it: a subprocess against stub vehicles over loopback."""

from __future__ import annotations

import asyncio
import sys
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

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
