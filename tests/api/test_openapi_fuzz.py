"""Every operation of the OpenAPI the app serves (``/v1/openapi.json``), fuzzed with schemathesis
as the admin: no 5xx, and every response is documented (status code, content type, headers,
body schema). Deterministic (a fixed seed, derandomised) and bounded (a few examples each).

No operation is left out: the stream's GET can be fuzzed, since no flight exists in a fuzzed
app (without ``Accept: text/event-stream`` it is a 422, with it every id a 404): it never
streams.
The WebSocket stream is not in the OpenAPI (tests/api/test_auth.py covers it).

Each operation's test gets a fresh app (schemathesis ends the app's lifespan after each test);
requests run on schemathesis' own event loop, where the lifespan runs too, so the engine's tasks
(schedule jobs, links) live on one loop.

Each operation's test counts the requests it made by schemathesis phase and fails unless the
fuzzing phase made ``MAX_EXAMPLES`` of them (one for an operation with nothing to vary): a
fuzz that Hypothesis cut short (a health check, an exhausted or filtered strategy) says so
instead of passing on a handful of requests.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any, cast

import pytest
import schemathesis
from fastapi import FastAPI
from hypothesis import HealthCheck, settings
from schemathesis.checks import not_a_server_error
from schemathesis.python import asgi
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    response_headers_conformance,
    response_schema_conformance,
    status_code_conformance,
)

from gcs.api.app import create_app
from tests.api.conftest import PAPER, auth, settings_for

CHECKS = [
    not_a_server_error,
    status_code_conformance,
    content_type_conformance,
    response_headers_conformance,
    response_schema_conformance,
]
MAX_EXAMPLES = 25
SEED = 20240501
REQUEST_TIMEOUT_S = 60
"""Per request (schemathesis' default, 10 s, is short for a terrain image on a loaded machine)."""
LINK_WAIT_S = 0.5
"""How long a fuzzed vehicle's connection string is waited on for a HEARTBEAT (the service
waits 15 s; the examples name tcp:127.0.0.1:5760, where nothing answers)."""


def _client(app: FastAPI) -> asgi.ASGIClient:
    """schemathesis' in-process client of ``app``: entered, it starts the app's lifespan."""
    return asgi.get_client(cast(Any, app))


def _served_openapi() -> dict[str, Any]:
    """The document the app serves (read without the lifespan: it needs no engine)."""
    app = create_app(settings_for(Path("unused"), "sqlite://"))
    r = _client(app).get("/v1/openapi.json")
    assert r.status_code == 200, r.text
    doc: dict[str, Any] = r.json()
    return doc


pytestmark = pytest.mark.slow  # every operation fuzzed: about 25 s, left out of make test-quick

SERVED = _served_openapi()
schema = schemathesis.openapi.from_dict(
    SERVED,
    config=schemathesis.Config.from_dict({"seed": SEED, "request-timeout": REQUEST_TIMEOUT_S}),
)


@pytest.fixture
def served(tmp_path: Path) -> Iterator[FastAPI]:
    """The app on SQLite, its lifespan started (on schemathesis' event loop), ended after the
    test."""
    app = create_app(settings_for(tmp_path / "data", f"sqlite:///{tmp_path / 'tcgcs.db'}"))
    with _client(app):
        pass
    app.state.engine.fleet.wait_s = LINK_WAIT_S
    try:
        yield app
    finally:
        asgi.shutdown_lifespans()


def _fixed_requests(doc: dict[str, Any]) -> set[str]:
    """The operations of ``doc`` with nothing to vary (no parameter, no body, no security
    scheme whose header could be fuzzed): one request is all Hypothesis can make of each."""
    return {
        f"{method.upper()} {path}"
        for path, ops in doc["paths"].items()
        for method, op in ops.items()
        if not (op.get("parameters") or op.get("requestBody") or op.get("security"))
    }


FIXED = _fixed_requests(SERVED)


@pytest.fixture
def requests_made(request: pytest.FixtureRequest) -> Iterator[Counter[str]]:
    """Counts the requests of one operation's test by schemathesis phase (``examples``,
    ``coverage``, ``fuzzing``); after every example has run (this fixture lives as long as the
    whole Hypothesis run), the fuzzing phase must have made ``MAX_EXAMPLES`` requests, or
    exactly one for an operation in :data:`FIXED`."""
    made: Counter[str] = Counter()
    yield made
    label = request.node.name.partition("[")[2].removesuffix("]")
    floor = 1 if label in FIXED else MAX_EXAMPLES
    assert made["fuzzing"] >= floor, (
        f"{label}: {made['fuzzing']} fuzzed requests, not {floor} ({dict(made)})"
    )


@schema.parametrize()
@settings(
    max_examples=MAX_EXAMPLES,
    derandomize=True,
    database=None,
    deadline=None,
    # The one health check suppressed: ``served`` and ``requests_made`` are function-scoped
    # on purpose (one app, and one count, for all of an operation's examples). Every other
    # check stays on; the count above catches a run cut short however it happens.
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
def test_operation(
    case: schemathesis.Case[Any], served: FastAPI, requests_made: Counter[str]
) -> None:
    requests_made[str(case.meta.phase.name) if case.meta is not None else "unknown"] += 1
    case.call_and_validate(app=served, headers=auth("admin"), checks=CHECKS)


def _planned(app: FastAPI) -> tuple[str, str]:
    """The paper scenario kept and a schedule of it planned: (scenario id, schedule id)."""
    client = _client(app)
    headers = {**auth("admin"), "Content-Type": "application/yaml"}
    r = client.post("/v1/scenarios", data=PAPER.read_bytes(), headers=headers)
    assert r.status_code == 201, r.text
    scenario_id = r.json()["id"]
    r = client.post("/v1/schedules", json={"scenario_id": scenario_id}, headers=auth("admin"))
    assert r.status_code == 202, r.text
    job = r.json()
    while job["state"] in ("queued", "running"):  # however long a busy machine takes
        time.sleep(0.05)
        job = client.get(f"/v1/jobs/{job['id']}", headers=auth("admin")).json()
    assert job["state"] == "succeeded", job
    return scenario_id, job["result"]["id"]


def test_known_resources_conform(served: FastAPI) -> None:
    """The operations that read a resource, on resources that exist (fuzzing only reaches their
    404s): each answer is documented too."""
    scenario_id, schedule_id = _planned(served)
    job_id = next(iter(served.state.engine.planning.jobs))
    cases: list[tuple[str, dict[str, str]]] = [
        ("GET /v1/scenarios/{scenario_id}", {"scenario_id": scenario_id}),
        ("GET /v1/scenarios/{scenario_id}/terrain.png", {"scenario_id": scenario_id}),
        ("GET /v1/scenarios/schema", {}),
        ("GET /v1/jobs/{job_id}", {"job_id": job_id}),
        ("GET /v1/schedules/{schedule_id}", {"schedule_id": schedule_id}),
        ("GET /v1/vehicles", {}),
        ("GET /v1/flights", {}),
        ("GET /v1/ready", {}),
        ("GET /metrics", {}),
    ]
    mission = "GET /v1/schedules/{schedule_id}/missions/{vehicle}.{fmt}"
    for vehicle in ("UAV1", "UAV3"):
        for fmt in ("plan", "waypoints"):
            cases.append((mission, {"schedule_id": schedule_id, "vehicle": vehicle, "fmt": fmt}))
    for label, params in cases:
        operation = schema.find_operation_by_label(label)
        assert operation is not None, label
        case = operation.Case(path_parameters=params)
        r = case.call_and_validate(app=served, headers=auth("admin"), checks=CHECKS)
        assert r.status_code == 200, (label, params, r.status_code, r.text)
