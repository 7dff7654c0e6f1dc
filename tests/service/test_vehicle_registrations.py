"""Live vehicles registered with ``POST /v1/vehicles`` outlive the service: a service started
again on the same data directory and database lists them under the same ids and connections,
opens their links again in the background (until the vehicle answers), and gives a new vehicle
an id never given before. A vehicle registered with a signing key waits for the key (it is not
kept): listed with ``signing_key_needed``, no link opened, until it is registered again with it.

On an embedded SQLite and on the PostgreSQL server at 127.0.0.1:5432 (a schema of its own,
dropped after; a server that cannot be reached fails these tests). The vehicles are the bundled
simulator's, started apart as an operator's autopilots are; the simulator does not sign, so the
signed vehicle is one the test plays itself over TCP (:class:`HandVehicle`), signing with
pymavlink's codec.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import time
from collections.abc import AsyncIterator, Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import yaml
from alembic import command
from alembic.config import Config
from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from sqlalchemy import create_engine, inspect, text

from gcs.api.app import create_app
from gcs.mavlink.signing import SigningConfig, apply_signing, key_from_passphrase
from gcs.service.stubs import free_tcp_base
from gcs.store import repository
from gcs.store.repository import Store, StoreConflict
from tests.api.conftest import auth, running, settings_for
from tests.gcs.conftest import PAPER, PG_ADMIN, Packer, heartbeat, postgres_schema, start_stub
from tests.service.conftest import serve
from tests.service.test_flights_http import _ok, _scheduled
from tests.teams import compact_paper

pytestmark = pytest.mark.slow  # two service starts a test, on each database

HANG_S = 120.0
"""A hang's bound, not a verdict: how long a link may take to come back (a vehicle that
returns is found within some 5 s of wall time)."""

DEAD_LINK = {
    "heartbeat_age_s": None,
    "healthy": False,
    "received": 0,
    "sent": 0,
    "malformed": 0,
    "rtt_s": None,
    "open": False,
}
"""``link`` of a vehicle whose link is not open."""
NOTHING_HEARD = {
    "flight_id": None,
    "mode": None,
    "armed": None,
    "last_mode": None,
    "last_armed": None,
    "lat_deg": None,
    "lon_deg": None,
    "alt_amsl_m": None,
    "battery_pct": None,
}
"""The rest of its view when nothing was heard from it since the service started."""


@pytest.fixture(params=["sqlite", "postgresql"])
def database_url(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'kept.db'}"
        return
    admin = create_engine(PG_ADMIN)
    try:
        with admin.connect() as conn:
            conn.execute(text("select 1"))
    except Exception as err:
        pytest.fail(f"PostgreSQL at 127.0.0.1:5432 is required: {err}")
    finally:
        admin.dispose()
    yield from postgres_schema()


def _tcp(port: int) -> str:
    return f"tcp:127.0.0.1:{port}"


async def _listed(client: httpx.AsyncClient) -> dict[str, dict[str, Any]]:
    return {v["id"]: v for v in _ok(await client.get("/v1/vehicles"))}


def _healthy(view: dict[str, Any]) -> bool:
    return bool(view["link"]["healthy"] and view["link"]["open"] and view["mode"] is not None)


async def _until(
    client: httpx.AsyncClient, holds: Callable[[dict[str, dict[str, Any]]], bool], what: str
) -> dict[str, dict[str, Any]]:
    """The vehicles listed, once ``holds`` of them (polled; :data:`HANG_S` catches a hang)."""
    views: dict[str, dict[str, Any]] = {}
    try:
        async with asyncio.timeout(HANG_S):
            while not holds(views := await _listed(client)):
                await asyncio.sleep(0.2)
    except TimeoutError:
        raise AssertionError(f"{what}: not within {HANG_S:g} s: {views}") from None
    return views


async def _register(client: httpx.AsyncClient, connection: str, **more: Any) -> dict[str, Any]:
    view: dict[str, Any] = _ok(
        await client.post("/v1/vehicles", json={"connection": connection, **more}), 201
    )
    return view


def _registrations(database_url: str) -> list[repository.Registration]:
    store = Store.open(database_url, migrate=False)
    try:
        return store.registered_vehicles()
    finally:
        store.close()


@contextlib.asynccontextmanager
async def _simulator(
    tmp_path: Path, base: int, vehicles: int
) -> AsyncIterator[asyncio.subprocess.Process]:
    """The bundled simulator's vehicles on the ground at ``base``, ``base + 10``, ...; stopped
    on exit."""
    stub = await start_stub(PAPER, base, tmp_path / "truth.jsonl", vehicles=vehicles)
    try:
        yield stub
    finally:
        if stub.returncode is None:
            stub.terminate()
        await stub.wait()


async def test_registered_vehicles_are_listed_and_reached_again_after_a_restart(
    database_url: str, tmp_path: Path
) -> None:
    data = tmp_path / "data"
    base = free_tcp_base(3)
    conns = [_tcp(base + 10 * i) for i in range(3)]
    async with _simulator(tmp_path, base, 3):
        async with serve(data, database_url) as service, service.client() as client:
            before_utc_s = time.time()
            first = await _register(client, conns[0])
            second = await _register(client, conns[1], system_id=2)
            after_utc_s = time.time()
            assert (first["id"], second["id"]) == ("v1", "v2")
            assert (first["signing_key_needed"], second["signing_key_needed"]) == (False, False)
            assert (await _register(client, conns[0]))["id"] == "v1"  # registered already
            await _until(client, lambda vs: all(_healthy(v) for v in vs.values()), "healthy")
        given = {"v1": conns[0], "v2": conns[1]}
        kept = _registrations(database_url)
        assert [(r.id, r.connection, r.system_id, r.signed) for r in kept] == [
            ("v1", conns[0], None, False),
            ("v2", conns[1], 2, False),
        ]
        assert all(before_utc_s <= r.registered_utc_s <= after_utc_s for r in kept), kept
        async with serve(data, database_url) as service, service.client() as client:
            # Listed at once, under the same ids and connections; the links come back.
            listed = await _listed(client)
            assert {vid: v["connection"] for vid, v in listed.items()} == given
            assert listed["v2"]["system_id"] == 2
            back = await _until(
                client, lambda vs: all(_healthy(vs[vid]) for vid in given), "links back"
            )
            assert all(v["flight_id"] is None for v in back.values()), back
            assert not any(v["signing_key_needed"] for v in back.values()), back
            assert (await _register(client, conns[1]))["id"] == "v2"  # its id, not a new one
            # A new vehicle: an id never given before.
            third = await _register(client, conns[2])
            assert third["id"] == "v3" and third["link"]["open"], third
            one = _ok(await client.get("/v1/vehicles/v1"))
            assert one["connection"] == conns[0] and _healthy(one), one
    assert [(r.id, r.connection) for r in _registrations(database_url)] == [
        ("v1", conns[0]),
        ("v2", conns[1]),
        ("v3", conns[2]),
    ]


async def test_a_vehicle_silent_after_a_restart_is_listed_dead_until_it_answers(
    database_url: str, tmp_path: Path
) -> None:
    data = tmp_path / "data"
    base = free_tcp_base(3)
    conns = [_tcp(base + 10 * i) for i in range(3)]
    async with (
        _simulator(tmp_path, base, 3),
        serve(data, database_url) as service,
        service.client() as client,
    ):
        ids = [(await _register(client, conn))["id"] for conn in conns]
        await _until(client, lambda vs: all(_healthy(v) for v in vs.values()), "healthy")
    # The simulator has stopped: nothing answers at either connection.
    async with serve(data, database_url) as service, service.client() as client:
        listed = await _listed(client)
        assert sorted(listed) == ids
        for vid, conn in zip(ids, conns, strict=True):
            for view in (listed[vid], _ok(await client.get(f"/v1/vehicles/{vid}"))):
                assert view["connection"] == conn
                assert view["link"] == DEAD_LINK, view
                assert {k: view[k] for k in NOTHING_HEARD} == NOTHING_HEARD, view
                assert view["signing_key_needed"] is False
        # No flight on them meanwhile: their links are not open.
        job = await _scheduled(client, yaml.safe_dump(compact_paper(), sort_keys=False))
        names = [v["id"] for v in job["result"]["vehicles"]]
        body = {"schedule_id": job["result"]["id"], "vehicles": dict(zip(names, ids, strict=True))}
        r = await client.post("/v1/flights", json=body)
        assert r.status_code == 409 and "link is not open" in r.json()["detail"], r.text
        # The simulator started again on the same connections: the links come back.
        async with _simulator(tmp_path, base, 3):
            back = await _until(
                client, lambda vs: all(_healthy(vs[vid]) for vid in ids), "links back"
            )
            assert [back[vid]["connection"] for vid in ids] == conns
            assert all(back[vid]["last_mode"] == back[vid]["mode"] for vid in ids), back


class HandVehicle:
    """A vehicle the test plays over TCP: system ``system_id``, a HEARTBEAT every 0.2 s to
    each ground station connected, every message signed with ``key`` if one is given (and
    what it receives checked against it). It counts the ground stations that connected and
    keeps the messages it accepted from them."""

    def __init__(self, system_id: int, key: bytes | None = None) -> None:
        self.system_id = system_id
        self.signing = None if key is None else SigningConfig(secret_key=key)
        self.connections = 0
        self.accepted: list[Any] = []
        self._server: asyncio.Server | None = None
        self._clients: set[asyncio.Task[None]] = set()

    async def start(self) -> int:
        self._server = await asyncio.start_server(self._serve, "127.0.0.1", 0)
        return int(self._server.sockets[0].getsockname()[1])

    def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.connections += 1
        task = asyncio.get_running_loop().create_task(self._client(reader, writer))
        self._clients.add(task)
        task.add_done_callback(self._clients.discard)

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        packer = Packer(self.system_id)
        parser = mavlink2.MAVLink(None)
        parser.robust_parsing = True
        if self.signing is not None:
            apply_signing(packer.mav, self.signing, outgoing=True)
            apply_signing(parser, self.signing, outgoing=False)
        beats = asyncio.get_running_loop().create_task(self._beat(writer, packer))
        try:
            while data := await reader.read(65536):
                for m in parser.parse_buffer(data) or []:
                    if m.get_type() != "BAD_DATA":
                        self.accepted.append(m)
        except ConnectionError:
            pass
        finally:
            beats.cancel()
            with contextlib.suppress(asyncio.CancelledError, ConnectionError):
                await beats
            writer.close()
            with contextlib.suppress(ConnectionError):
                await writer.wait_closed()

    @staticmethod
    async def _beat(writer: asyncio.StreamWriter, packer: Packer) -> None:
        while not writer.is_closing():
            writer.write(packer.pack(heartbeat()))
            await writer.drain()
            await asyncio.sleep(0.2)

    def gcs_heartbeats(self) -> list[Any]:
        """The ground stations' HEARTBEATs it accepted (signed with its key, if it has one)."""
        return [
            m
            for m in self.accepted
            if m.get_type() == "HEARTBEAT" and m.type == mavlink2.MAV_TYPE_GCS
        ]

    async def disconnected(self) -> None:
        """Until every ground station connected has gone and all it sent is read."""
        while self._clients:
            await asyncio.wait(self._clients)

    async def stop(self) -> None:
        if self._server is not None:
            self._server.close()
        for task in list(self._clients):
            task.cancel()
        if self._clients:
            await asyncio.wait(self._clients)
        if self._server is not None:
            await self._server.wait_closed()


async def test_a_vehicle_registered_with_a_signing_key_waits_for_the_key_after_a_restart(
    database_url: str, tmp_path: Path
) -> None:
    data = tmp_path / "data"
    key = key_from_passphrase("registered vehicles")
    signed = HandVehicle(1, key)
    plain = HandVehicle(2)
    signed_conn, plain_conn = _tcp(await signed.start()), _tcp(await plain.start())
    try:
        async with serve(data, database_url) as service, service.client() as client:
            first = await _register(client, signed_conn, signing_key=key.hex())
            assert first["id"] == "v1" and not first["signing_key_needed"], first
            assert (await _register(client, plain_conn))["id"] == "v2"
            await _until(client, lambda vs: all(_healthy(v) for v in vs.values()), "healthy")
            # Its link signs: the vehicle accepts the ground station's HEARTBEATs.
            async with asyncio.timeout(HANG_S):
                while not signed.gcs_heartbeats():
                    await asyncio.sleep(0.1)
        kept = {r.id: r for r in _registrations(database_url)}
        assert (kept["v1"].signed, kept["v2"].signed) == (True, False)
        async with asyncio.timeout(HANG_S):
            await signed.disconnected()
        connected = signed.connections
        heard = len(signed.accepted)
        async with serve(data, database_url) as service, service.client() as client:
            listed = await _listed(client)
            assert listed["v1"]["connection"] == signed_conn
            assert listed["v1"]["signing_key_needed"] is True
            assert listed["v1"]["link"] == DEAD_LINK, listed["v1"]
            assert listed["v2"]["signing_key_needed"] is False
            # The vehicle without a key comes back; the one with a key is not reached for.
            await _until(client, lambda vs: _healthy(vs["v2"]), "the unsigned vehicle back")
            listed = await _listed(client)
            assert listed["v1"]["signing_key_needed"] is True
            assert listed["v1"]["link"] == DEAD_LINK, listed["v1"]
            assert (signed.connections, len(signed.accepted)) == (connected, heard)
            # Registered again: without its key, refused; with it, the same id, linked.
            r = await client.post("/v1/vehicles", json={"connection": signed_conn})
            assert r.status_code == 422 and "signing_key" in r.json()["detail"], r.text
            again = await _register(client, signed_conn, signing_key=key.hex())
            assert again["id"] == "v1" and not again["signing_key_needed"], again
            assert again["link"]["open"], again
            await _until(client, lambda vs: _healthy(vs["v1"]), "the signed vehicle back")
            assert signed.connections == connected + 1
            async with asyncio.timeout(HANG_S):
                while len(signed.gcs_heartbeats()) <= heard:
                    await asyncio.sleep(0.1)
            assert all(m._signed for m in signed.accepted[heard:])
            assert len(await _listed(client)) == 2  # no new registration
        assert [(r.id, r.signed) for r in _registrations(database_url)] == [
            ("v1", True),
            ("v2", False),
        ]
    finally:
        await signed.stop()
        await plain.stop()


LINK_WAIT_S = 0.5
"""How long the in-process service waits on a connection for a HEARTBEAT (15 s by default)."""


async def test_a_registration_no_vehicle_answers_keeps_nothing(
    database_url: str, tmp_path: Path
) -> None:
    """In process (the wait on a silent connection made short): a failed registration is
    not kept, and gives away no id."""
    vehicle = HandVehicle(1)
    conn = _tcp(await vehicle.start())
    silent = _tcp(free_tcp_base(1))
    try:
        app = create_app(settings_for(tmp_path / "data", database_url))
        async for client in running(app):
            app.state.engine.fleet.wait_s = LINK_WAIT_S
            r = await client.post("/v1/vehicles", json={"connection": silent}, headers=auth())
            assert r.status_code == 400 and "no vehicle answered" in r.json()["detail"], r.text
            r = await client.post("/v1/vehicles", json={"connection": conn}, headers=auth())
            assert r.status_code == 201 and r.json()["id"] == "v1", r.text
        app = create_app(settings_for(tmp_path / "data", database_url))
        async for client in running(app):
            r = await client.get("/v1/vehicles", headers=auth())
            assert [(v["id"], v["connection"]) for v in r.json()] == [("v1", conn)], r.text
    finally:
        await vehicle.stop()
    assert [r.connection for r in _registrations(database_url)] == [conn]


def test_a_database_at_revision_0003_gains_the_vehicles_table(database_url: str) -> None:
    """Brought up to date, a database of the schema before keeps its rows and keeps
    registrations, once per id and connection; taken back to 0003, it loses the table."""
    old = Store.open(database_url, migrate=False)
    cfg = Config()
    cfg.set_main_option("script_location", str(Path(repository.__file__).with_name("migrations")))
    with old.engine.begin() as connection:
        cfg.attributes["connection"] = connection
        command.upgrade(cfg, "0003")
    with old.engine.begin() as connection:
        assert "vehicles" not in inspect(connection).get_table_names()
        connection.execute(
            text("INSERT INTO scenarios VALUES ('s1', 'demo', 'application/yaml', 'x', 0.0)")
        )
    old.close()
    store = Store.open(database_url)
    try:
        assert store.scenario("s1").body == "x"
        assert store.registered_vehicles() == []
        first = store.register_vehicle("v1", "tcp:127.0.0.1:5760", system_id=None, signed=True)
        assert (first.id, first.connection, first.system_id, first.signed) == (
            "v1", "tcp:127.0.0.1:5760", None, True,
        )  # fmt: skip
        again = store.register_vehicle("v1", "tcp:127.0.0.1:5760", system_id=3, signed=False)
        assert again == dataclasses.replace(first, system_id=3, signed=False)  # its time kept
        with pytest.raises(StoreConflict, match="another vehicle"):
            store.register_vehicle("v2", "tcp:127.0.0.1:5760", system_id=None, signed=False)
        with pytest.raises(StoreConflict, match=r"kept at tcp:127\.0\.0\.1:5760"):
            store.register_vehicle("v1", "tcp:127.0.0.1:5770", system_id=None, signed=False)
        second = store.register_vehicle("v2", "udpin:0.0.0.0:14550", system_id=1, signed=False)
        assert store.registered_vehicles() == [again, second]
        with store.engine.begin() as connection:
            cfg.attributes["connection"] = connection
            command.downgrade(cfg, "0003")
        with store.engine.connect() as connection:
            assert "vehicles" not in inspect(connection).get_table_names()
        store.upgrade()
        assert store.registered_vehicles() == []
    finally:
        store.close()
