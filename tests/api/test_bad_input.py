"""Bad input is refused with the place it is wrong, and changes nothing: malformed scenarios
(YAML syntax with line and column, a wrong type with its field path, binary, NaN), unknown ids
(404 naming the id), a retried POST with one ``Idempotency-Key`` (the first response again, no
second action), a stale ``If-Match`` on a flight's team time (412). On SQLite and PostgreSQL."""

from __future__ import annotations

import asyncio
import json
import re
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import pytest_asyncio
import yaml
from fastapi import FastAPI
from sqlalchemy import func, select

from gcs.api.app import create_app
from gcs.service.engine import Engine
from gcs.store.models import Base
from sitl_stub.lockstep import Lockstep
from tests.api.conftest import PAPER, app_with, auth, problem, running, settings_for
from tests.gcs.conftest import store_url_of

YAML = {**auth("plan"), "Content-Type": "application/yaml"}
JSON = {**auth("plan"), "Content-Type": "application/json"}


pytestmark = pytest.mark.asyncio(loop_scope="module")
"""The tests run in the module's loop, where its one app per store (:func:`app`) runs."""


@pytest.fixture(scope="module", params=["sqlite", "postgresql"])
def shared_url(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[str]:
    """The module's store: a SQLite file, and a PostgreSQL schema of its own."""
    yield from store_url_of(request.param, tmp_path_factory.mktemp("bad-input"))


@pytest.fixture(scope="module")
def app(shared_url: str, tmp_path_factory: pytest.TempPathFactory) -> FastAPI:
    """One app per store for the module's refusals (each checks that it changed nothing,
    so they need no store of their own), its routes and store set up once, not per check.
    The tests that count what the service holds take a :func:`fresh` one."""
    return create_app(settings_for(tmp_path_factory.mktemp("bad-input") / "data", shared_url))


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def client(app: FastAPI) -> AsyncIterator[httpx.AsyncClient]:
    async for c in running(app):
        yield c


@pytest_asyncio.fixture(loop_scope="module")
async def fresh(store_url: str, tmp_path: Path) -> AsyncIterator[tuple[httpx.AsyncClient, FastAPI]]:
    """An app of its own on SQLite and on PostgreSQL, and its client."""
    app = create_app(settings_for(tmp_path / "data", store_url))
    async for c in running(app):
        yield c, app


def _paper_with(path: str, value: Any) -> dict[str, Any]:
    """The paper scenario as data, the field at ``path`` (dotted, list indices as numbers)
    set to ``value``."""
    data: dict[str, Any] = yaml.safe_load(PAPER.read_text(encoding="utf-8"))
    *parents, last = path.split(".")
    node: Any = data
    for key in parents:
        node = node[int(key)] if isinstance(node, list) else node[key]
    node[int(last) if isinstance(node, list) else last] = value
    return data


def row_counts(app: FastAPI) -> dict[str, int]:
    """Rows in each table of the app's store."""
    with app.state.store.engine.connect() as conn:
        return {
            name: int(conn.execute(select(func.count()).select_from(table)).scalar_one())
            for name, table in Base.metadata.tables.items()
        }


def _stored(app: FastAPI) -> dict[str, list[tuple[Any, ...]]]:
    """Every row of every table of the store, in key order."""
    with app.state.store.engine.connect() as conn:
        return {
            name: [
                tuple(row)
                for row in conn.execute(select(table).order_by(*table.primary_key.columns))
            ]
            for name, table in Base.metadata.tables.items()
        }


async def _keep_paper(client: httpx.AsyncClient) -> str:
    r = await client.post("/v1/scenarios", content=PAPER.read_bytes(), headers=YAML)
    assert r.status_code == 201, r.text
    scenario_id: str = r.json()["id"]
    return scenario_id


async def _planned(client: httpx.AsyncClient, scenario_id: str) -> dict[str, Any]:
    """A schedule of the scenario, planned (the job polled until done): its view."""
    r = await client.post("/v1/schedules", json={"scenario_id": scenario_id}, headers=JSON)
    assert r.status_code == 202, r.text
    job = r.json()
    while job["state"] in ("queued", "running"):  # however long a busy machine takes
        await asyncio.sleep(0.05)
        job = (await client.get(f"/v1/jobs/{job['id']}", headers=auth("observe"))).json()
    assert job["state"] == "succeeded", job
    result: dict[str, Any] = job["result"]
    return result


async def _rehearsal_of(client: httpx.AsyncClient, scenario_id: str) -> str:
    """A flight of the scenario's schedule on bundled simulator vehicles (planned, not
    launched): its id."""
    schedule = await _planned(client, scenario_id)
    r = await client.post(
        "/v1/flights",
        json={"schedule_id": schedule["id"], "rehearsal": {"speedup": 200, "seed": 1}},
        headers=auth("operate"),
    )
    assert r.status_code == 201, r.text
    fid: str = r.json()["flight_id"]
    return fid


# -- malformed scenarios ----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "line", "column"),
    [
        ("name: a\n  b: c\n", 2, 4),
        ("name: broken\nvehicles:\n  - id: UAV1\n\tspeed_min_m_s: 20\n", 4, 1),
        ("name: broken\nvehicles:\n  - id: UAV1\n    speed_min_m_s: [20\n    x: 1\n", 5, 6),
    ],
)
async def test_yaml_syntax_error_says_where(
    client: httpx.AsyncClient, app: FastAPI, text: str, line: int, column: int
) -> None:
    before = _stored(app)
    body = problem(await client.post("/v1/scenarios", content=text, headers=YAML), 422)
    assert "YAML" in body["detail"]
    found = re.search(r"line (\d+) column (\d+)", body["detail"])
    assert found is not None, body
    assert (int(found[1]), int(found[2])) == (line, column), body
    assert _stored(app) == before


async def test_json_syntax_error_says_where(client: httpx.AsyncClient) -> None:
    r = await client.post("/v1/scenarios", content='{"name": "a",\n "area": }', headers=JSON)
    assert "line 2 column" in problem(r, 422)["detail"]


@pytest.mark.parametrize("media", ["yaml", "json"])
async def test_wrong_type_names_the_field(
    client: httpx.AsyncClient, app: FastAPI, media: str
) -> None:
    data = _paper_with("vehicles.0.speed_min_m_s", "fast")
    text = yaml.safe_dump(data) if media == "yaml" else json.dumps(data)
    before = _stored(app)
    r = await client.post("/v1/scenarios", content=text, headers=YAML if media == "yaml" else JSON)
    body = problem(r, 422)
    assert "vehicles.0.speed_min_m_s" in body["detail"], body
    assert body["errors"][0]["loc"] == ["vehicles", "0", "speed_min_m_s"], body
    assert _stored(app) == before


@pytest.mark.parametrize(
    "content",
    [
        bytes(range(256)) * 4,  # not UTF-8
        b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR",  # not UTF-8 either
        b"name: a\x00\x01\x02\n",  # UTF-8, but control characters YAML refuses
        "name: caf\u00e9\ufffe\n".encode(),
    ],
)
@pytest.mark.parametrize("media", ["application/yaml", "application/json", "application/x-tar"])
async def test_binary_scenario_is_422(
    client: httpx.AsyncClient, app: FastAPI, content: bytes, media: str
) -> None:
    before = _stored(app)
    headers = {**auth("plan"), "Content-Type": media}
    problem(await client.post("/v1/scenarios", content=content, headers=headers), 422)
    assert _stored(app) == before


@pytest.mark.parametrize(
    ("method", "path", "body"),
    [
        ("POST", "/v1/schedules", b'{"scenario_id": "x", "required_arrival_s": NaN}'),
        ("POST", "/v1/flights", b'{"schedule_id": "x", "rehearsal": {"speedup": NaN}}'),
        ("POST", "/v1/flights/f/launch", b'{"delay_s": Infinity}'),
        ("PUT", "/v1/flights/f/team-time", b'{"arrival_s": NaN}'),
        ("PUT", "/v1/flights/f/team-time", b'{"arrival_s": -Infinity}'),
    ],
)
async def test_nan_in_a_body_names_the_field(
    client: httpx.AsyncClient, method: str, path: str, body: bytes
) -> None:
    headers = {**auth("admin"), "Content-Type": "application/json"}
    r = await client.request(method, path, content=body, headers=headers)
    got = problem(r, 422)
    field = re.search(rb'"(\w+)": (NaN|-?Infinity)', body)
    assert field is not None
    assert got["errors"][0]["loc"][-1] == field[1].decode(), got
    assert field[1].decode() in got["detail"], got


@pytest.mark.parametrize(
    "field",
    [
        "vehicles.1.speed_max_m_s",
        "threats.0.center.east_m",
    ],
)
async def test_nan_in_a_json_scenario_names_the_field(
    client: httpx.AsyncClient, app: FastAPI, field: str
) -> None:
    text = json.dumps(_paper_with(field, float("nan")))
    assert "NaN" in text
    before = _stored(app)
    body = problem(await client.post("/v1/scenarios", content=text, headers=JSON), 422)
    assert field in body["detail"], body
    assert ".".join(body["errors"][0]["loc"]) == field, body
    assert _stored(app) == before


async def test_wrong_body_type_names_the_field(client: httpx.AsyncClient) -> None:
    r = await client.put(
        "/v1/flights/f/team-time", json={"arrival_s": "soon"}, headers=auth("operate")
    )
    body = problem(r, 422)
    assert body["errors"][0]["loc"] == ["body", "arrival_s"] and "arrival_s" in body["detail"]


async def test_binary_json_body_is_refused(client: httpx.AsyncClient) -> None:
    """A JSON route sent bytes that are not text: refused (FastAPI answers 400 when the body
    cannot be read at all, 422 when it is text but not JSON), never a 5xx."""
    headers = {**auth("admin"), "Content-Type": "application/json"}
    for content in (b"\xff\xfe\x00\x01", b"\x00\x00\x00", b"{\x80}"):
        r = await client.post("/v1/flights", content=content, headers=headers)
        assert r.status_code in (400, 422), (content, r.status_code, r.text)
        assert r.json()["detail"]


# -- unknown ids ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("method", "path", "body", "named"),
    [
        ("GET", "/v1/flights/nof-1", None, "flight 'nof-1'"),
        ("GET", "/v1/flights/nof-1/team-time", None, "flight 'nof-1'"),
        ("GET", "/v1/flights/nof-1/events", None, "flight 'nof-1'"),
        ("POST", "/v1/flights/nof-1/upload", None, "flight 'nof-1'"),
        ("PUT", "/v1/flights/nof-1/team-time", {"arrival_s": 1.0}, "flight 'nof-1'"),
        ("DELETE", "/v1/flights/nof-1/threats/t", None, "flight 'nof-1'"),
        ("GET", "/v1/jobs/noj-2", None, "job 'noj-2'"),
        ("GET", "/v1/schedules/nos-3", None, "schedule 'nos-3'"),
        ("GET", "/v1/schedules/nos-3/missions/UAV1.plan", None, "schedule 'nos-3'"),
        ("POST", "/v1/flights", {"schedule_id": "nos-3"}, "schedule 'nos-3'"),
        ("GET", "/v1/scenarios/nosc-4", None, "scenario 'nosc-4'"),
        ("POST", "/v1/schedules", {"scenario_id": "nosc-4"}, "scenario 'nosc-4'"),
        ("GET", "/v1/vehicles/nov-5", None, "vehicle 'nov-5'"),
    ],
)
async def test_unknown_id_is_404_naming_it(
    client: httpx.AsyncClient,
    app: FastAPI,
    method: str,
    path: str,
    body: dict[str, Any] | None,
    named: str,
) -> None:
    before = _stored(app)
    r = await client.request(method, path, json=body, headers=auth("admin"))
    assert named in problem(r, 404)["detail"]
    assert _stored(app) == before


async def test_unknown_vehicle_of_a_schedule_is_404(client: httpx.AsyncClient) -> None:
    schedule = await _planned(client, await _keep_paper(client))
    r = await client.get(
        f"/v1/schedules/{schedule['id']}/missions/UAV9.plan", headers=auth("observe")
    )
    assert "UAV9" in problem(r, 404)["detail"]


# -- nothing stored on a refused request ------------------------------------------------------


async def test_refused_posts_store_nothing(client: httpx.AsyncClient, app: FastAPI) -> None:
    scenario_id = await _keep_paper(client)
    schedule = await _planned(client, scenario_id)
    counts, before = row_counts(app), _stored(app)
    assert counts["scenarios"] == 1
    admin = auth("admin")
    refused = [
        (await client.post("/v1/scenarios", content="name: a\n  b: c\n", headers=YAML), 422),
        (
            await client.post(
                "/v1/scenarios",
                content=json.dumps(_paper_with("vehicles.2.speed_min_m_s", [1])),
                headers=JSON,
            ),
            422,
        ),
        (await client.post("/v1/flights", json={"schedule_id": "nos"}, headers=admin), 404),
        (
            await client.post(
                "/v1/flights",
                json={"schedule_id": "nos", "rehearsal": {"speedup": 100}},
                headers=admin,
            ),
            404,
        ),
        (
            await client.post(
                "/v1/flights",
                json={"schedule_id": schedule["id"], "vehicles": {"UAV9": "v1"}},
                headers=admin,
            ),
            422,
        ),
        (
            await client.post(
                "/v1/flights",
                json={"schedule_id": schedule["id"], "vehicles": {"UAV1": "v1", "UAV2": "v2"}},
                headers=admin,
            ),
            422,
        ),
        (
            await client.post(
                "/v1/flights",
                json={
                    "schedule_id": schedule["id"],
                    "vehicles": {"UAV1": "v7", "UAV2": "v8", "UAV3": "v9"},
                },
                headers=admin,
            ),
            404,
        ),
        (
            await client.post("/v1/flights", json={"schedule_id": schedule["id"]}, headers=admin),
            422,
        ),
    ]
    for r, status in refused:
        problem(r, status)
    assert row_counts(app) == counts
    assert _stored(app) == before
    engine: Engine = app.state.engine
    assert not engine.flights


# -- Idempotency-Key --------------------------------------------------------------------------


async def test_retried_schedule_is_one_job(
    fresh: tuple[httpx.AsyncClient, FastAPI],
) -> None:
    client, app = fresh
    scenario_id = await _keep_paper(client)
    engine: Engine = app.state.engine
    body = {"scenario_id": scenario_id, "dry_run": True}
    headers = {**JSON, "Idempotency-Key": "schedule-once"}
    first = await client.post("/v1/schedules", json=body, headers=headers)
    assert first.status_code == 202, first.text
    await asyncio.sleep(0.1)  # the job moves on; the retry must still get the first answer
    again = await client.post("/v1/schedules", json=body, headers=headers)
    assert (again.status_code, again.content) == (first.status_code, first.content)
    assert again.headers["location"] == first.headers["location"]
    assert again.headers.get("idempotent-replayed") == "true"
    assert list(engine.planning.jobs) == [first.json()["id"]]
    # The same key for another request is refused, and does nothing either.
    other = await client.post("/v1/schedules", json={**body, "seed": 7}, headers=headers)
    assert "Idempotency-Key" in problem(other, 422)["detail"]
    assert list(engine.planning.jobs) == [first.json()["id"]]
    # Another key is another request.
    fresh = await client.post(
        "/v1/schedules", json=body, headers={**JSON, "Idempotency-Key": "schedule-twice"}
    )
    assert fresh.status_code == 202 and fresh.json()["id"] != first.json()["id"]
    assert len(engine.planning.jobs) == 2


async def test_retries_at_once_are_one_job(
    fresh: tuple[httpx.AsyncClient, FastAPI],
) -> None:
    client, app = fresh
    scenario_id = await _keep_paper(client)
    headers = {**JSON, "Idempotency-Key": "together"}
    body = {"scenario_id": scenario_id, "dry_run": True}
    answers = await asyncio.gather(
        *(client.post("/v1/schedules", json=body, headers=headers) for _ in range(5))
    )
    assert {(r.status_code, r.content) for r in answers} == {(202, answers[0].content)}
    assert len(app.state.engine.planning.jobs) == 1


async def test_retried_scenario_and_refusal_replayed(
    fresh: tuple[httpx.AsyncClient, FastAPI],
) -> None:
    client, app = fresh
    text = PAPER.read_bytes()
    headers = {**YAML, "Idempotency-Key": "scenario-1"}
    first = await client.post("/v1/scenarios", content=text, headers=headers)
    again = await client.post("/v1/scenarios", content=text, headers=headers)
    assert (
        (first.status_code, first.content)
        == (again.status_code, again.content)
        == (
            201,
            first.content,
        )
    )
    stored = _stored(app)
    assert len(stored["scenarios"]) == 1
    other = await client.post("/v1/scenarios", content=text + b"\n# v2\n", headers=headers)
    problem(other, 422)
    assert _stored(app) == stored
    # A refusal is kept for its key as well: the retry is refused the same way.
    bad = {**JSON, "Idempotency-Key": "refused"}
    r1 = await client.post("/v1/schedules", json={"scenario_id": "none"}, headers=bad)
    r2 = await client.post("/v1/schedules", json={"scenario_id": "none"}, headers=bad)
    assert (r1.status_code, r1.content) == (r2.status_code, r2.content)
    assert r1.status_code == 404


# -- a flight's team time ---------------------------------------------------------------------


async def _flight_row(client: httpx.AsyncClient, app: FastAPI, flight_id: str) -> tuple[Any, ...]:
    """The flight's row (state, team time, version) once the store has every event the flight
    has emitted (they are written behind the flight, and move its row)."""
    table = Base.metadata.tables["flights"]
    async with asyncio.timeout(30):
        while True:
            snap = (await client.get(f"/v1/flights/{flight_id}", headers=auth("observe"))).json()
            kept = app.state.store.events(flight_id)
            if len(kept) == snap["last_seq"]:
                break
            await asyncio.sleep(0.02)
    with app.state.store.engine.connect() as conn:
        row = conn.execute(
            select(table.c.state, table.c.team_time_s, table.c.version).where(
                table.c.id == flight_id
            )
        ).one()
    return tuple(row)


async def test_stale_if_match_is_412(
    fresh: tuple[httpx.AsyncClient, FastAPI],
) -> None:
    """A flight of the paper schedule on bundled simulator vehicles (planned, not launched):
    a move with the version read is taken, one with a stale version is refused."""
    client, app = fresh
    fid = await _rehearsal_of(client, await _keep_paper(client))
    path = f"/v1/flights/{fid}/team-time"
    read = await client.get(path, headers=auth("observe"))
    assert read.status_code == 200, read.text
    etag, now = read.headers["etag"], read.json()
    assert etag == f'"{now["version"]}"'

    moved = await client.put(
        path,
        json={"arrival_s": now["team_time_s"] + 60.0},
        headers={**auth("operate"), "If-Match": etag},
    )
    assert moved.status_code == 200, moved.text
    assert moved.json()["version"] == now["version"] + 1
    assert moved.headers["etag"] != etag
    after = (await client.get(path, headers=auth("observe"))).json()
    kept = await _flight_row(client, app, fid)
    assert kept[1] == after["team_time_s"], kept  # the move is kept

    for stale in (etag, f'"{now["version"] + 5}"', "not-a-version", '"-1"'):
        r = await client.put(
            path,
            json={"arrival_s": now["team_time_s"] + 120.0},
            headers={**auth("operate"), "If-Match": stale},
        )
        body = problem(r, 412)
        assert "stale" in body["detail"] or "not a version" in body["detail"], body
    assert (await client.get(path, headers=auth("observe"))).json() == after
    assert await _flight_row(client, app, fid) == kept
    # On the real flight, unknown parts of it are named too.
    r = await client.delete(f"/v1/flights/{fid}/threats/no-such", headers=auth("operate"))
    assert "no-such" in problem(r, 404)["detail"]
    r = await client.post(
        f"/v1/flights/{fid}/abort", json={"vehicle": "UAV9"}, headers=auth("operate")
    )
    assert "UAV9" in problem(r, 404)["detail"]


# -- bodies nested too deeply --------------------------------------------------------------------


@pytest.mark.parametrize(
    ("path", "headers", "said"),
    [
        ("/v1/scenarios", YAML, "scenario: nested too deeply to read"),
        ("/v1/scenarios", JSON, "scenario: nested too deeply to read"),
        ("/v1/schedules", JSON, "body: nested too deeply to read"),
        ("/v1/flights", {**auth("operate"), "Content-Type": "application/json"}, "body: nested"),
    ],
    ids=["scenario-yaml", "scenario-json", "schedule", "flight"],
)
async def test_a_body_nested_too_deeply_is_422(
    client: httpx.AsyncClient,
    caplog: pytest.LogCaptureFixture,
    path: str,
    headers: dict[str, str],
    said: str,
) -> None:
    """A list in a list ... 50,000 deep (a parser's recursion runs out): one 422, no 500, and
    nothing in the log."""
    deep = "[" * 50_000 + "]" * 50_000
    r = await client.post(path, content=deep, headers=headers)
    assert problem(r, 422)["detail"].startswith(said)
    assert not [rec for rec in caplog.records if rec.levelname in ("ERROR", "CRITICAL")]
    assert (await client.get("/v1/health")).status_code == 200


async def test_a_lockstep_file_is_joined_only_from_the_folder_the_service_names(
    tmp_path: Path,
) -> None:
    """``lockstep`` of ``POST /v1/flights`` (a flight on registered vehicles joining their
    simulator's lock step): a 422 naming the field and why without vehicles, when the service
    names no folder (``TCGCS_LOCKSTEP_DIR``), for a path outside it (``..`` included), and for
    a file that is not a simulator's lock-step file; no flight is made and the file is left
    as it was."""
    sim = tmp_path / "sim"
    sim.mkdir()
    pace, outside = sim / "pace", tmp_path / "pace"
    for path in (pace, outside):
        Lockstep(path, create=True, speedup=200.0).close()
    (sim / "notes.txt").write_text("not a pace file, but longer than one\n" * 2)
    (sim / "zeros").write_bytes(bytes(40))
    kept = pace.read_bytes()
    registered = {"vehicles": {"UAV1": "v1"}}
    cases = [
        (None, {**registered, "lockstep": str(pace)}, "no TCGCS_LOCKSTEP_DIR"),
        (sim, {"rehearsal": {}, "lockstep": str(pace)}, "only with vehicles"),
        (sim, {**registered, "lockstep": str(outside)}, "is not in TCGCS_LOCKSTEP_DIR"),
        (sim, {**registered, "lockstep": f"{sim}/../pace"}, "is not in TCGCS_LOCKSTEP_DIR"),
        (sim, {**registered, "lockstep": str(sim / "notes.txt")}, "not a lock-step file"),
        (sim, {**registered, "lockstep": str(sim / "zeros")}, "not a lock-step file"),
        (sim, {**registered, "lockstep": str(sim / "missing")}, "not a lock-step file"),
    ]
    for folder, body, why in cases:
        async for client in running(app_with(tmp_path / str(folder).replace("/", "_"),
                                             lockstep_dir=folder)):  # fmt: skip
            r = await client.post(
                "/v1/flights", json={"schedule_id": "s", **body}, headers=auth("operate")
            )
            detail = problem(r, 422)["detail"]
            assert "lockstep" in detail and why in detail, (body, detail)
            assert (await client.get("/v1/flights", headers=auth("observe"))).json() == []
    assert pace.read_bytes() == kept


# -- the team time of ordered slots and of windows ----------------------------------------------


async def _slots(client: httpx.AsyncClient, fid: str, version: int) -> dict[str, float]:
    """Each vehicle's slot in the flight's snapshot once it shows team time ``version`` (its
    worker tells it within a moment: waited for however long a busy machine takes)."""
    while True:
        view = (await client.get(f"/v1/flights/{fid}", headers=auth("observe"))).json()
        if view["team_time_version"] == version:
            return {v["id"]: v["slot_s"] for v in view["vehicles"]}
        await asyncio.sleep(0.05)


@pytest.mark.parametrize("kind", ["spaced", "windows"])
async def test_a_team_time_move_of_spaced_slots_or_windows_is_409_naming_why(
    client: httpx.AsyncClient, kind: str
) -> None:
    """The operator's move on the paper flight (bundled simulator vehicles, planned, not
    launched) with its arrivals 60 s apart, or in windows of their own. Spaced: a time
    before the earliest the team can make is 409 with the earliest feasible time and the
    vehicle that forces it, every slot kept; one it can make moves every slot alike, the
    spacing kept. Windows: every move is 409, as there is no team time to move."""
    vehicles = ("UAV1", "UAV2", "UAV3")
    arrival: dict[str, Any] = (
        {"kind": "spaced", "interval_s": 60.0}
        if kind == "spaced"
        else {
            "kind": "windows",
            "windows": [{"vehicle": v, "earliest_s": 0, "latest_s": 20_000} for v in vehicles],
        }
    )
    r = await client.post("/v1/scenarios", json=_paper_with("arrival", arrival), headers=JSON)
    assert r.status_code == 201, r.text
    fid = await _rehearsal_of(client, r.json()["id"])
    path = f"/v1/flights/{fid}/team-time"
    now = (await client.get(path, headers=auth("observe"))).json()
    slots = await _slots(client, fid, now["version"])
    if kind == "windows":
        assert now["team_time_s"] is None
        r = await client.put(path, json={"arrival_s": 6_000.0}, headers=auth("operate"))
        assert "per-vehicle windows: no team time to move" in problem(r, 409)["detail"]
        assert await _slots(client, fid, now["version"]) == slots
        return
    team_s = now["team_time_s"]
    assert sorted(slots.values()) == pytest.approx([team_s, team_s + 60.0, team_s + 120.0])
    r = await client.put(path, json={"arrival_s": team_s - 900.0}, headers=auth("operate"))
    body = problem(r, 409)
    assert body["vehicle"] in vehicles and body["vehicle"] in body["detail"], body
    assert team_s - 900.0 < body["earliest_feasible_s"] <= team_s + 1e-6, body
    assert f"earliest feasible {body['earliest_feasible_s']:.1f} s" in body["detail"]
    assert await _slots(client, fid, now["version"]) == slots
    moved = await client.put(path, json={"arrival_s": team_s + 60.0}, headers=auth("operate"))
    assert moved.status_code == 200, moved.text
    assert moved.json() == {"team_time_s": team_s + 60.0, "version": now["version"] + 1}
    after = await _slots(client, fid, now["version"] + 1)
    assert after == {v: pytest.approx(s + 60.0, abs=1e-3) for v, s in slots.items()}
