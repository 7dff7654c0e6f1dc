"""Shared helpers for gcs tests: free ports, a hand-driven MAVLink vehicle over TCP/UDP, the
paper scenario planned once, the stub simulator started as an operator would, the stores."""

from __future__ import annotations

import asyncio
import os
import socket
import sys
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from sqlalchemy import create_engine, text

from gcs.coordination.config import FlightConfig
from gcs.coordination.team import TeamController
from gcs.store.repository import Store
from planner.plan import World, build_world, plan
from planner.retime import build_schedule
from planner.scenario import Scenario, load_scenario
from planner.schedule import Schedule
from sitl_stub.lockstep import Lockstep
from tests.flightstory import story

PG_ADMIN = "postgresql+psycopg://postgres@127.0.0.1:5432/test"

HOME = (-35.363261, 149.165230, 584.0)
SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
PAPER = SCENARIOS / "paper_three_uav.yaml"


@pytest.fixture(scope="module")
def paper() -> tuple[Scenario, World, Schedule]:
    """The paper scenario, its world and its schedule (planned with seed 1)."""
    scenario = load_scenario(PAPER)
    world = build_world(scenario)
    p = plan(scenario, rng=np.random.default_rng(1), world=world)
    return scenario, world, build_schedule(scenario, p, world=world)


START_UTC = 1_800_000_000.0
"""The UTC (s) the controller tests start their flights at."""


@pytest.fixture
def team(paper: tuple[Scenario, World, Schedule]) -> TeamController:
    """The paper team's controller, started at :data:`START_UTC` (seed 3)."""
    scenario, world, schedule = paper
    t = TeamController(scenario, schedule, world, FlightConfig(), rng=np.random.default_rng(3))
    t.start(START_UTC)
    return t


async def start_stub(
    scenario: Path, base: int, truth: Path, *extra: str, speedup: float = 200.0, vehicles: int = 3
) -> asyncio.subprocess.Process:
    """``python -m sitl_stub --scenario`` as an operator would start it: on its own, homes
    from the scenario (nose toward the goal), the scenario's airspeeds, default timeouts, one
    TCP client per port as ArduPilot's SITL serves; ``extra`` options after those."""
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "sitl_stub", "--scenario", str(scenario), "--vehicles", str(vehicles),
        "--tcp-base", str(base), "--speedup", repr(speedup), "--truth", str(truth),
        "--one-client-per-port", *extra,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    assert proc.stdout is not None
    async with asyncio.timeout(30):
        line = await proc.stdout.readline()
    assert b"ready" in line, line
    return proc


async def hold_while_away(pace_path: Path, away_s: float) -> None:
    """Stand in for a ground station that is away (killed, starting again) for ``away_s``
    seconds of flight: the simulator in lock step on ``pace_path`` flies that far past where
    it is now and waits there, however long the restart takes in wall time (a busy machine
    then sets no verdict), until a ground station acknowledges again (any pace time other
    than the one held here)."""
    pace = Lockstep(pace_path)
    try:
        held_s = (pace.pace_s() * pace.speedup + away_s - pace.lead_s) / pace.speedup
        while True:
            pace.acknowledge(held_s)
            await asyncio.sleep(0.05)
            if pace.acknowledged_s() != held_s:
                return
    finally:
        pace.close()


def postgres_schema() -> Iterator[str]:
    """A fresh schema on the local PostgreSQL (127.0.0.1:5432, database ``test``), dropped
    afterwards: yields its store URL. Skipped without the server, a failure in CI."""
    try:
        admin = create_engine(PG_ADMIN)
        with admin.connect() as conn:
            conn.execute(text("select 1"))
    except Exception as err:
        if os.environ.get("CI"):
            pytest.fail(f"PostgreSQL at 127.0.0.1:5432 is required in CI: {err}")
        pytest.skip(f"no PostgreSQL at 127.0.0.1:5432: {err}")
    schema = f"t_{uuid.uuid4().hex[:12]}"
    with admin.begin() as conn:
        conn.execute(text(f"create schema {schema}"))
    try:
        yield f"{PG_ADMIN}?options=-csearch_path%3D{schema}"
    finally:
        with admin.begin() as conn:
            conn.execute(text(f"drop schema {schema} cascade"))
        admin.dispose()


@pytest.fixture
def pg_url() -> Iterator[str]:
    yield from postgres_schema()


def store_url_of(kind: str, folder: Path) -> Iterator[str]:
    """A store URL of ``kind``: a SQLite file in ``folder``, or a PostgreSQL schema of its own
    (:func:`postgres_schema`)."""
    if kind == "sqlite":
        yield f"sqlite:///{folder / 'tcgcs.db'}"
    else:
        yield from postgres_schema()


@pytest.fixture(params=["sqlite", "postgresql"])
def store_url(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    """A store URL on SQLite (a file) and on PostgreSQL."""
    yield from store_url_of(request.param, tmp_path)


def assert_flight_kept(url: str, record: dict[str, Any]) -> None:
    """The store holds the flight of a rehearsal record as it was flown: every event in
    order, every upload, the final state and team time."""
    store = Store.open(url, migrate=False)
    try:
        flight = store.flight(record["flight_id"])
        assert flight.state == "completed", (
            f"{record['state']}: {record['state_reason']}\n{story(record['events'])}"
        )
        assert flight.resume is not None  # the schedule it was launched on
        planned = [v["id"] for v in flight.resume["schedule"]["vehicles"]]
        assert planned == [v["id"] for v in record["vehicles"]]
        assert flight.team_time_s is not None and record["required_arrival_s"] is not None
        assert abs(flight.team_time_s - record["required_arrival_s"]) < 1e-3
        assert {vid for vid, (phase, _, _) in flight.vehicles.items() if phase == "arrived"} == {
            v["id"] for v in record["vehicles"]
        }
        kept = store.events(flight.id)
        assert [(e.seq, str(e.kind), e.vehicle) for e in kept] == [
            (e["seq"], e["kind"], e["vehicle"]) for e in record["events"]
        ]
        # An upload event with its mission (payload "what") is one row of uploads.
        uploads = [e for e in kept if str(e.kind) == "upload" and "what" in e.payload]
        assert store.upload_count(flight.id) == len(uploads) >= len(record["vehicles"])
        for v in record["vehicles"]:
            assert store.last_upload(flight.id, v["id"]), v["id"]
    finally:
        store.close()


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def heartbeat(autopilot: int = mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA) -> Any:
    return mavlink2.MAVLink_heartbeat_message(
        mavlink2.MAV_TYPE_FIXED_WING, autopilot, 0, 0, mavlink2.MAV_STATE_STANDBY, 3
    )


class Packer:
    """Frames messages as system ``sysid`` would (its own sequence numbers)."""

    def __init__(self, sysid: int, compid: int = 1) -> None:
        self.mav = mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=compid)

    def pack(self, msg: Any) -> bytes:
        data = bytes(msg.pack(self.mav))
        self.mav.seq = (self.mav.seq + 1) % 256
        return data


class TcpVehicle:
    """A TCP server that plays a vehicle by hand: records what the GCS sends, sends bytes."""

    def __init__(self) -> None:
        self.server: asyncio.Server | None = None
        self.writers: list[asyncio.StreamWriter] = []
        self.parser = mavlink2.MAVLink(None)
        self.parser.robust_parsing = True
        self.received: list[Any] = []
        self.connections = 0

    async def start(self, port: int = 0) -> int:
        self.server = await asyncio.start_server(self._serve, "127.0.0.1", port)
        return int(self.server.sockets[0].getsockname()[1])

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.connections += 1
        self.writers.append(writer)
        while data := await reader.read(65536):
            for m in self.parser.parse_buffer(data) or []:
                if m.get_type() != "BAD_DATA":
                    self.received.append(m)

    def send(self, data: bytes) -> None:
        for w in self.writers:
            if not w.is_closing():
                w.write(data)

    def drop_clients(self) -> None:
        for w in self.writers:
            w.close()
        self.writers.clear()

    async def stop(self) -> None:
        self.drop_clients()
        if self.server is not None:
            self.server.close()
            await self.server.wait_closed()

    def of_type(self, name: str) -> list[Any]:
        return [m for m in self.received if m.get_type() == name]
