"""The store on SQLite (a file) and on the PostgreSQL server these machines run, over TCP
(the ``store_url`` fixture of tests/gcs/conftest.py: in CI a PostgreSQL that cannot be
reached is a failure, not a skip)."""

from __future__ import annotations

import asyncio
import math
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
from alembic import command
from alembic.config import Config
from sqlalchemy import text

from gcs.coordination.bus import EventBus
from gcs.coordination.events import EventKind, FlightEvent
from gcs.store import repository
from gcs.store.repository import (
    CheckpointWriter,
    EventWriter,
    Store,
    StoreConflict,
    StoreError,
    StoreNotFound,
)
from planner.mission import Waypoint, compile_mission

SCENARIO = "name: demo\nvehicles: []\n"


@pytest.fixture
def store(store_url: str) -> Iterator[Store]:
    s = Store.open(store_url)
    try:
        yield s
    finally:
        s.close()


def _event(
    seq: int, kind: EventKind = EventKind.SPEED, vehicle: str | None = "UAV1"
) -> FlightEvent:
    return FlightEvent(1.7e9 + seq, float(seq), vehicle, kind, f"event {seq}", "speed", 21.5, seq)


def test_scenarios_are_kept_by_content_hash_and_never_changed(store: Store) -> None:
    a = store.save_scenario(SCENARIO, name="demo")
    assert store.save_scenario(SCENARIO, name="another name") == a  # same text, same id
    b = store.save_scenario(SCENARIO + "# changed\n", name="demo")
    assert a != b and len(a) == 64
    row = store.scenario(a)
    assert (row.name, row.body) == ("demo", SCENARIO)
    with pytest.raises(StoreNotFound, match="no scenario 'nope'"):
        store.scenario("nope")


def test_flight_state_and_team_time_move_with_a_version(store: Store) -> None:
    sid = store.save_scenario(SCENARIO, name="demo")
    fid = store.create_flight(sid, {"UAV1": "tcp:127.0.0.1:5760", "UAV2": None})
    f = store.flight(fid)
    assert (f.state, f.version, f.vehicles["UAV1"]) == (
        "planned",
        1,
        ("waiting_takeoff", "tcp:127.0.0.1:5760", None),
    )
    v2 = store.update_flight(fid, expected_version=1, state="running", team_time_s=5234.1)
    assert v2 == 2 and store.flight(fid).team_time_s == 5234.1
    with pytest.raises(StoreConflict, match="version 1 is stale"):
        store.update_flight(fid, expected_version=1, team_time_s=6000.0)
    assert store.flight(fid).team_time_s == 5234.1  # the refused change changed nothing
    with pytest.raises(StoreError, match="'flying' is not one of"):
        store.update_flight(fid, state="flying")
    store.set_vehicle(fid, "UAV1", phase="on_route", system_id=1)
    assert store.flight(fid).vehicles["UAV1"] == ("on_route", "tcp:127.0.0.1:5760", 1)
    with pytest.raises(StoreNotFound):
        store.update_flight("nope", state="running")


def test_a_vehicle_is_in_one_flight_at_a_time(store: Store) -> None:
    sid = store.save_scenario(SCENARIO, name="demo")
    first = store.create_flight(sid, {"UAV1": "tcp:127.0.0.1:5760"})
    with pytest.raises(StoreConflict, match=f"tcp:127.0.0.1:5760 is already in flight {first}"):
        store.create_flight(sid, {"UAV9": "tcp:127.0.0.1:5760"})
    store.update_flight(first, state="completed")
    store.create_flight(sid, {"UAV1": "tcp:127.0.0.1:5760"})  # free again


def test_events_are_kept_once_in_sequence(store: Store) -> None:
    sid = store.save_scenario(SCENARIO, name="demo")
    fid = store.create_flight(sid, {"UAV1": None})
    assert store.add_events(fid, [_event(k) for k in range(1, 6)]) == 5
    assert store.add_events(fid, [_event(k) for k in range(4, 9)]) == 3  # 4, 5 already kept
    got = store.events(fid)
    assert [e.seq for e in got] == list(range(1, 9))
    assert got[0] == _event(1)
    assert [e.seq for e in store.events(fid, after_seq=6)] == [7, 8]
    assert [e.seq for e in store.events(fid, after_seq=2, limit=2)] == [3, 4]
    no_clock = FlightEvent(math.nan, 0.0, None, EventKind.PLAN, "before the clock", seq=9)
    store.add_events(fid, [no_clock])
    assert math.isnan(store.events(fid, after_seq=8)[0].utc_s)


def test_the_flight_row_follows_the_events_kept_in_their_transaction(store: Store) -> None:
    """The team time, the flight's state and a vehicle's phase that events change are kept
    with those events, in one transaction: a batch refused keeps neither (a process killed
    between the two once left the row's team time ahead of its event), and an event sent
    again does not move the row back."""
    sid = store.save_scenario(SCENARIO, name="demo")
    fid = store.create_flight(sid, {"UAV1": None})

    def ev(seq: int, kind: EventKind, value: float | None = None, **payload: str) -> FlightEvent:
        vehicle = "UAV1" if kind is EventKind.STATE else None
        return FlightEvent(1.7e9 + seq, float(seq), vehicle, kind, "", None, value, seq, payload)

    first = [
        ev(1, EventKind.FLIGHT, state="running"),
        ev(2, EventKind.ARRIVAL, 1279.1),
        ev(3, EventKind.STATE, state="on_route"),
    ]
    assert store.add_events(fid, first) == 3
    f = store.flight(fid)
    assert (f.state, f.team_time_s, f.version, f.vehicles["UAV1"][0]) == (
        "running",
        1279.1,
        3,
        "on_route",
    )
    refused = [ev(4, EventKind.ARRIVAL, 1281.6), ev(5, EventKind.FLIGHT, state="flying")]
    with pytest.raises(StoreError, match="'flying' is not one of"):
        store.add_events(fid, refused)
    assert [e.seq for e in store.events(fid)] == [1, 2, 3]
    assert store.flight(fid) == f
    later = [ev(4, EventKind.ARRIVAL, 1281.6)]
    assert store.add_events(fid, later) == 1
    assert store.add_events(fid, first) == 0  # kept already: the row stays as it is
    f = store.flight(fid)
    assert (f.team_time_s, f.version, f.vehicles["UAV1"][0]) == (1281.6, 4, "on_route")


def test_uploaded_missions_come_back_item_for_item(store: Store) -> None:
    sid = store.save_scenario(SCENARIO, name="demo")
    fid = store.create_flight(sid, {"UAV1": None})
    home = Waypoint(-35.36, 149.16, 584.0)
    first = compile_mission(
        home=home, waypoints=[Waypoint(-35.35, 149.17, 700.5)], takeoff_alt_m=80.0
    )
    second = compile_mission(
        home=home, waypoints=[Waypoint(-35.34, 149.18, 650.25)], takeoff_alt_m=80.0
    )
    assert store.last_upload(fid, "UAV1") is None
    store.record_upload(fid, "UAV1", first, what="initial mission", utc_s=1.7e9)
    store.record_upload(fid, "UAV1", second, what="loiter inserted", utc_s=1.7e9 + 60)
    assert store.last_upload(fid, "UAV1") == second
    assert store.upload_count(fid) == 2


async def test_the_event_writer_keeps_every_event_of_a_bus(store: Store) -> None:
    sid = store.save_scenario(SCENARIO, name="demo")
    fid = store.create_flight(sid, {"UAV1": None})
    bus = EventBus()
    writer = EventWriter(store, fid, batch=7)
    sub = bus.subscribe(maxsize=10_000)
    task = asyncio.create_task(writer.run(sub))
    for k in range(50):
        bus.publish(FlightEvent(1.7e9 + k, float(k), "UAV1", EventKind.SPEED, f"e{k}"))
        if k % 10 == 0:
            await asyncio.sleep(0)
    sub.close()
    await task
    assert writer.written == 50
    assert [e.seq for e in store.events(fid)] == list(range(1, 51))


def test_a_bad_url_or_an_unreachable_server_is_one_clear_error() -> None:
    with pytest.raises(StoreError, match="database URL 'nosuch://x'"):
        Store.open("nosuch://x")
    with pytest.raises(StoreError, match="unreachable"):
        Store.open("postgresql+psycopg://postgres@127.0.0.1:1/test?connect_timeout=2")


async def test_the_newest_checkpoint_is_kept_and_a_state_event_moves_the_rows(
    store: Store,
) -> None:
    sid = store.save_scenario(SCENARIO, name="demo")
    fid = store.create_flight(sid, {"UAV1": "tcp:127.0.0.1:5760"})
    assert store.checkpoint(fid) is None
    writer = CheckpointWriter(store, fid)
    for k in range(50):  # offered faster than written: the last one wins
        writer.offer(bytes([k]) * 100_000)
    await writer.close()
    assert store.checkpoint(fid) == bytes([49]) * 100_000
    assert 1 <= writer.written <= 50
    bus = EventBus()
    events = bus.subscribe(after_seq=0)
    bus.publish(
        FlightEvent(
            1.7e9, 0.0, None, EventKind.FLIGHT, "flight running", payload={"state": "running"}
        )
    )
    bus.publish(
        FlightEvent(
            1.7e9, 1.0, "UAV1", EventKind.STATE, "climbing -> on_route",
            payload={"state": "on_route", "was": "climbing"},
        )
    )  # fmt: skip
    events.close()
    await EventWriter(store, fid).run(events)
    f = store.flight(fid)
    assert f.state == "running" and f.vehicles["UAV1"][0] == "on_route"
    with pytest.raises(StoreNotFound):
        store.checkpoint("nope")


async def test_a_checkpoint_is_kept_before_kept_returns_however_slow_the_database(
    store: Store, monkeypatch: pytest.MonkeyPatch
) -> None:
    """:meth:`CheckpointWriter.kept` (what a service flight waits for before it says it is
    ready) returns only once the newest checkpoint offered is in the store."""
    sid = store.save_scenario(SCENARIO, name="demo")
    fid = store.create_flight(sid, {"UAV1": "tcp:127.0.0.1:5760"})
    gate = threading.Event()
    save = store.save_checkpoint

    def held_save(flight_id: str, blob: bytes) -> None:
        gate.wait()
        save(flight_id, blob)

    monkeypatch.setattr(store, "save_checkpoint", held_save)
    writer = CheckpointWriter(store, fid)
    await writer.kept()  # nothing offered: at once
    writer.offer(b"first")
    writer.offer(b"ready")
    kept = asyncio.ensure_future(writer.kept())
    for _ in range(20):
        await asyncio.sleep(0)
    assert not kept.done() and store.checkpoint(fid) is None
    gate.set()
    await kept
    assert store.checkpoint(fid) == b"ready"
    await writer.close()


def test_a_database_at_the_first_revision_is_brought_up_to_date(tmp_path: Path) -> None:
    """A file made by the first schema keeps its rows and gains the checkpoint."""
    url = f"sqlite:///{tmp_path / 'old.db'}"
    old = Store.open(url, migrate=False)
    cfg = Config()
    cfg.set_main_option("script_location", str(Path(repository.__file__).with_name("migrations")))
    with old.engine.begin() as connection:
        cfg.attributes["connection"] = connection
        command.upgrade(cfg, "0001")
    with old.engine.begin() as connection:
        connection.execute(
            text("INSERT INTO scenarios VALUES ('s1', 'demo', 'application/yaml', 'x', 0.0);")
        )
        connection.execute(
            text("INSERT INTO flights (id, scenario_id, state, version, created_utc_s, "
                 "updated_utc_s) VALUES ('f1', 's1', 'running', 3, 0.0, 0.0)")
        )  # fmt: skip
    old.close()
    store = Store.open(url)
    try:
        assert store.flight("f1").state == "running"
        assert store.checkpoint("f1") is None
        store.save_checkpoint("f1", b"kept")
        assert store.checkpoint("f1") == b"kept"
    finally:
        store.close()
