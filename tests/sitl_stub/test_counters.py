"""The counters file (--counters), read from outside the simulator process it comes from."""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_stub.api import Home, SimTeam
from sitl_stub.counters import COUNTERS_FORMAT, CountersWriter
from sitl_stub.model import displace_deg
from tests.sitl_stub.conftest import Client, wp
from tests.sitl_stub.test_cli import stub_cli

HOME = Home(-35.363261, 149.165230, 584.0, 0.0)
COUNTED = ("arms", "auto_mode_changes", "mission_uploads", "mission_downloads", "failed_uploads")

Document = dict[str, Any]


async def read_counters(path: Path, until: Callable[[Document], bool]) -> Document:
    """The file's document once ``until`` holds (it is rewritten about once a wall second).
    Every read must be a whole document: the file is replaced, never written in place."""
    async with asyncio.timeout(20.0):
        while True:
            with contextlib.suppress(FileNotFoundError):
                doc: Document = json.loads(path.read_text(encoding="utf-8"))
                if until(doc):
                    return doc
            await asyncio.sleep(0.05)


def counted(doc: Document, index: int) -> dict[str, int]:
    return {name: doc["vehicles"][index][name] for name in COUNTED}


def mission(n: int) -> list[Any]:
    points = [
        displace_deg(HOME.lat_deg, HOME.lon_deg, HOME.alt_m, 300.0 * i, 0.0) for i in range(n)
    ]
    return [wp(0, *points[0])] + [wp(i, *points[i]) for i in range(1, n)]


async def set_mode(c: Client, custom_mode: int) -> int:
    flags = mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    return await c.command(mavlink2.MAV_CMD_DO_SET_MODE, flags, custom_mode)


async def test_counters_file_of_a_simulator_process(tmp_path: Path) -> None:
    path = tmp_path / "counters.json"
    zero = dict.fromkeys(COUNTED, 0)
    async with stub_cli(
        "--vehicles", "2", "--tcp-base", "0", "--speedup", "5",
        "--home", f"{HOME.lat_deg},{HOME.lon_deg},{HOME.alt_m}", "--counters", str(path),
    ) as run:  # fmt: skip
        first = await read_counters(path, lambda d: True)
        assert first["format"] == COUNTERS_FORMAT and first["final"] is False
        assert [(v["index"], v["system_id"]) for v in first["vehicles"]] == [(0, 1), (1, 2)]
        assert counted(first, 0) == zero
        c = await Client.connect(run.ports[0])
        try:
            for _ in range(2):  # the second arm finds the vehicle armed: no transition
                arm = await c.command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
                assert arm == mavlink2.MAV_RESULT_ACCEPTED
            items = mission(4)
            assert await c.upload(items, retry_s=0.5) == mavlink2.MAV_MISSION_ACCEPTED
            assert len(await c.download(retry_s=0.5)) == len(items)
            for _ in range(2):  # AUTO twice: one change into AUTO
                assert await set_mode(c, 10) == mavlink2.MAV_RESULT_ACCEPTED
            # While it runs, the file catches up within about a wall second (the change into
            # AUTO came last: a document that has it has everything before it).
            live = await read_counters(path, lambda d: counted(d, 0)["auto_mode_changes"] > 0)
            assert live["final"] is False
            assert counted(live, 0) == {**zero, "arms": 1, "auto_mode_changes": 1,
                                        "mission_uploads": 1, "mission_downloads": 1}  # fmt: skip
            assert live["vehicles"][0]["received"] > 0 and live["vehicles"][0]["sent"] > 0
        finally:
            await c.close()
    # At exit (SIGINT), with everything the vehicles had handled.
    final = json.loads(path.read_text(encoding="utf-8"))
    assert final["final"] is True
    assert counted(final, 0) == counted(live, 0)
    assert counted(final, 1) == zero
    assert final["sim_time_s"] >= live["sim_time_s"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["counters.json"]  # no temporary left


async def test_counters_writer_replaces_the_file_each_period(tmp_path: Path) -> None:
    path = tmp_path / "counters.json"
    async with SimTeam.start(
        homes=[HOME], tcp_base=0, run=False, counters_out=path, counters_period_s=3600.0
    ) as team:
        writer = team.counters_file
        assert writer is not None and writer.writes == 1  # the first document, at start
        team.step(10)  # not yet due
        assert writer.writes == 1
        team.vehicles[0].autopilot.arm()
        writer.period_s = 0.0
        team.step()
        assert writer.writes == 2
        doc = json.loads(path.read_text(encoding="utf-8"))
        assert doc["vehicles"][0]["arms"] == 1 and doc["sim_time_s"] == pytest.approx(1.1)
        assert doc["vehicles"][0]["link_inbound"] == {
            "passed": 0, "lost": 0, "blacked_out": 0, "duplicated": 0, "reordered": 0,
        }  # fmt: skip
    assert json.loads(path.read_text(encoding="utf-8"))["final"] is True
    writer.close()  # idempotent: no second final write
    assert writer.writes == 3
    with pytest.raises(ValueError, match="period"):
        CountersWriter(path, team.vehicles, team.clock, period_s=0.0)
