"""``docker-compose.yml`` and the ``Dockerfile``: read as files (the services, their order of
start, the published port, one project image whose default command is the api's), then each
service's command run here as its container would run it (the image's and the service's
environment, a working directory like the image's ``/app``, SIGTERM to stop), on loopback:
the migration against the local PostgreSQL and SQLite, the stub vehicles until they are ready
and send HEARTBEATs, the service until ``/v1/health`` and ``/v1/ready`` answer and it reaches
the stub vehicles as the compose file wires them. No container engine is needed."""

from __future__ import annotations

import asyncio
import contextlib
import fnmatch
import json
import os
import shlex
import signal
import sys
from collections.abc import AsyncIterator, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import httpx
import pytest
import yaml
from alembic.script import ScriptDirectory
from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from sqlalchemy import create_engine, inspect, text
from sqlalchemy.engine import make_url

import gcs.store.migrations
from gcs.__main__ import parser as gcs_parser
from sitl_stub.__main__ import parse_args as sitl_parse_args
from tests.gcs.conftest import postgres_schema
from tests.sitl_stub.conftest import free_port_base

REPO = Path(__file__).resolve().parents[2]
COMPOSE_FILE = REPO / "docker-compose.yml"
DOCKERFILE = REPO / "Dockerfile"
SERVICES = {"db", "migrate", "api", "sitl"}
PROJECT = ("migrate", "api", "sitl")
"""The services that run the project image."""
SERVE_EXITS = (0, -signal.SIGTERM)
"""uvicorn shuts the service down on SIGTERM, then raises the signal again with its default
action: here the process ends by it (-15, 143 in a shell); as a container's PID 1 the kernel
ignores a signal without a handler, and the command returns 0."""
HEAD = ScriptDirectory(str(Path(gcs.store.migrations.__file__).parent)).get_current_head()


@pytest.fixture(scope="module")
def compose() -> dict[str, Any]:
    data: dict[str, Any] = yaml.safe_load(COMPOSE_FILE.read_text(encoding="utf-8"))
    return data


def services(compose: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    svc: dict[str, dict[str, Any]] = compose["services"]
    return svc


def dockerfile() -> list[tuple[str, str]]:
    """The Dockerfile's instructions, ``(NAME, arguments)``, continuation lines joined."""
    out: list[tuple[str, str]] = []
    pending = ""
    for raw in DOCKERFILE.read_text(encoding="utf-8").splitlines():
        line = raw.strip()
        if not pending and (not line or line.startswith("#")):
            continue
        if line.endswith("\\"):
            pending += line[:-1] + " "
            continue
        name, _, args = (pending + line).partition(" ")
        out.append((name.upper(), args.strip()))
        pending = ""
    return out


def final_stage() -> list[tuple[str, str]]:
    steps = dockerfile()
    last_from = max(i for i, (name, _) in enumerate(steps) if name == "FROM")
    return steps[last_from:]


def image_env() -> dict[str, str]:
    """The final stage's ``ENV`` (``KEY=VALUE`` pairs)."""
    env: dict[str, str] = {}
    for name, args in final_stage():
        if name == "ENV":
            for pair in shlex.split(args):
                key, _, value = pair.partition("=")
                env[key] = value
    return env


def service_env(svc: Mapping[str, Any], **overrides: str) -> dict[str, str]:
    """A container's environment: the image's, then the service's, then ``overrides`` (the
    host's paths and loopback addresses); of the host's only what finds programs."""
    base = {k: os.environ[k] for k in ("PATH", "LANG", "HOME", "TMPDIR") if k in os.environ}
    env = svc.get("environment") or {}
    assert isinstance(env, dict), "environment as a mapping"
    return {**base, **image_env(), **{k: str(v) for k, v in env.items()}, **overrides}


def local_argv(command: Sequence[str], **values: str) -> list[str]:
    """The service's command with this interpreter for ``python`` and the options named
    (``tcp_base`` for ``--tcp-base``) given other values; each must be in the command."""
    argv = [sys.executable if i == 0 and arg == "python" else arg for i, arg in enumerate(command)]
    for key, value in values.items():
        option = "--" + key.replace("_", "-")
        assert option in argv, f"{option} not in {command}"
        argv[argv.index(option) + 1] = value
    return argv


@pytest.fixture
def app_dir(tmp_path: Path) -> Path:
    """The image's working directory: ``/app`` holds the scenarios and nothing else."""
    app = tmp_path / "app"
    app.mkdir()
    (app / "scenarios").symlink_to(REPO / "scenarios")
    return app


@pytest.fixture
def pg_url() -> Iterator[str]:
    yield from postgres_schema()


async def run(argv: Sequence[str], env: Mapping[str, str], cwd: Path) -> tuple[int, str]:
    proc = await asyncio.create_subprocess_exec(
        *argv, env=dict(env), cwd=cwd,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT,
    )  # fmt: skip
    async with asyncio.timeout(60):
        out, _ = await proc.communicate()
    assert proc.returncode is not None
    return proc.returncode, out.decode()


async def _ended_within(proc: asyncio.subprocess.Process, timeout_s: float) -> bool:
    """Whether the process ended within ``timeout_s``; if not, it is killed."""
    with contextlib.suppress(TimeoutError):
        await asyncio.wait_for(proc.wait(), timeout_s)
        return True
    proc.kill()
    await proc.wait()
    return False


@contextlib.asynccontextmanager
async def running(
    argv: Sequence[str],
    env: Mapping[str, str],
    cwd: Path,
    ready: str,
    exits: tuple[int, ...] = (0,),
) -> AsyncIterator[str]:
    """The command until it prints a line with ``ready`` (yielded); then SIGTERM, as
    ``docker stop`` sends, and it must exit with one of ``exits`` within 20 s."""
    log = cwd / f"stderr-{Path(argv[2]).name}-{os.urandom(3).hex()}.txt"
    with log.open("wb") as err:
        proc = await asyncio.create_subprocess_exec(
            *argv, env=dict(env), cwd=cwd, stdout=asyncio.subprocess.PIPE, stderr=err
        )
    assert proc.stdout is not None
    try:
        async with asyncio.timeout(30):
            while True:
                line = (await proc.stdout.readline()).decode()
                assert line, f"{argv[2]} exited before ready: {log.read_text()[-3000:]}"
                if ready in line:
                    break
        yield line
    finally:
        if proc.returncode is None:
            proc.send_signal(signal.SIGTERM)
        stopped = await _ended_within(proc, 20.0)
    assert stopped, f"{argv[2]} did not stop within 20 s of SIGTERM (killed)"
    assert proc.returncode in exits, f"{argv[2]} exit {proc.returncode}: {log.read_text()[-3000:]}"


# -- the files ------------------------------------------------------------------------------------


def test_compose_names_the_four_services(compose: dict[str, Any]) -> None:
    assert set(services(compose)) == SERVICES


def test_db_is_postgres_16_healthy_by_pg_isready_for_its_own_user_and_database(
    compose: dict[str, Any],
) -> None:
    db = services(compose)["db"]
    assert db["image"] == "postgres:16"
    assert "build" not in db
    check = db["healthcheck"]
    test = check["test"]
    assert test[0] in ("CMD", "CMD-SHELL")
    words = shlex.split(test[1]) if test[0] == "CMD-SHELL" else list(test[1:])
    assert words[0] == "pg_isready"
    env = db["environment"]
    assert words[words.index("-U") + 1] == env["POSTGRES_USER"]
    assert words[words.index("-d") + 1] == env["POSTGRES_DB"]
    assert check["retries"] >= 1 and check["interval"]


def test_services_start_in_order(compose: dict[str, Any]) -> None:
    """db healthy -> migrate completed -> api; the one-shot migration is never restarted."""
    svc = services(compose)
    assert svc["migrate"]["depends_on"] == {"db": {"condition": "service_healthy"}}
    assert svc["api"]["depends_on"]["migrate"] == {"condition": "service_completed_successfully"}
    assert svc["migrate"].get("restart", "no") == "no"
    assert "db" not in svc["sitl"].get("depends_on", {})


def test_migrate_and_api_use_the_db_service_as_its_own_settings_say(
    compose: dict[str, Any],
) -> None:
    svc = services(compose)
    db_env = svc["db"]["environment"]
    urls = {svc[name]["environment"]["TCGCS_DATABASE_URL"] for name in ("migrate", "api")}
    assert len(urls) == 1
    url = make_url(urls.pop())
    assert url.drivername == "postgresql+psycopg"
    assert url.host == "db" and url.port in (None, 5432)
    assert url.username == db_env["POSTGRES_USER"]
    assert url.password == db_env["POSTGRES_PASSWORD"]
    assert url.database == db_env["POSTGRES_DB"]


def test_the_api_listens_on_all_interfaces_on_the_published_port(
    compose: dict[str, Any],
) -> None:
    api = services(compose)["api"]
    args = gcs_parser().parse_args(api["command"][3:])
    assert api["command"][:3] == ["python", "-m", "gcs"] and args.cmd == "serve"
    assert args.host == "0.0.0.0" and args.port == 8600
    assert "8600:8600" in [str(p) for p in api["ports"]]
    exposed = next(args for name, args in final_stage() if name == "EXPOSE").split()
    assert "8600" in exposed
    probe = " ".join(api["healthcheck"]["test"])
    assert "127.0.0.1:8600/v1/ready" in probe
    # The data directory is a volume, and the image's user owns it.
    data = api["environment"]["TCGCS_DATA_DIR"]
    assert any(str(v).endswith(f":{data}") for v in api["volumes"])
    assert image_env()["TCGCS_DATA_DIR"] == data


def test_migrate_runs_the_upgrade_with_its_url_from_the_environment(
    compose: dict[str, Any],
) -> None:
    cmd = services(compose)["migrate"]["command"]
    assert cmd[:3] == ["python", "-m", "gcs"]
    args = gcs_parser().parse_args(cmd[3:])
    assert (args.cmd, args.op, args.url) == ("db", "upgrade", None)


def test_sitl_serves_three_vehicles_on_all_interfaces_in_the_sitl_port_layout(
    compose: dict[str, Any],
) -> None:
    sitl = services(compose)["sitl"]
    cmd = sitl["command"]
    assert cmd[:3] == ["python", "-m", "sitl_stub"]
    args = sitl_parse_args(cmd[3:])
    assert args.vehicles == 3 and args.tcp_base == 5760 and args.host == "0.0.0.0"
    assert args.speedup == 10
    # The api reaches vehicle i as tcp:sitl:(5760 + 10 i).
    assert {str(p) for p in sitl["expose"]} == {"5760", "5770", "5780"}
    if args.scenario:
        assert (REPO / args.scenario).is_file()
        copied = [a.split() for name, a in final_stage() if name == "COPY"]
        assert any(Path(args.scenario).parts[0] in words for words in copied)


def test_every_project_service_runs_the_one_project_image(compose: dict[str, Any]) -> None:
    svc = services(compose)
    images = {svc[name]["image"] for name in PROJECT}
    builds = [svc[name]["build"] for name in PROJECT]
    assert len(images) == 1 and images != {"postgres:16"}
    assert all(b == builds[0] for b in builds)
    build = builds[0]
    context = REPO / (build["context"] if isinstance(build, dict) else build)
    name = build.get("dockerfile", "Dockerfile") if isinstance(build, dict) else "Dockerfile"
    assert (context / name).resolve() == DOCKERFILE
    assert [n for n, s in svc.items() if "build" in s] == list(PROJECT)


def test_the_dockerfile_installs_the_package_and_runs_the_api_as_a_user(
    compose: dict[str, Any],
) -> None:
    stage = final_stage()
    assert stage[0] == ("FROM", "python:3.11-slim")
    runs = " ".join(args for name, args in stage if name == "RUN")
    assert "pip install" in runs
    users = [args for name, args in stage if name == "USER"]
    assert users and users[-1] not in ("root", "0")
    assert not [name for name, _ in dockerfile() if name == "ENTRYPOINT"]
    (cmd,) = [json.loads(args) for name, args in stage if name == "CMD"]
    assert cmd == services(compose)["api"]["command"]
    assert image_env().get("PYTHONUNBUFFERED") == "1"  # log lines as they come


def test_dockerignore_keeps_what_the_image_copies() -> None:
    ignored = [
        line.strip()
        for line in (REPO / ".dockerignore").read_text(encoding="utf-8").splitlines()
        if line.strip() and not line.startswith("#")
    ]
    for name, args in dockerfile():
        if name != "COPY" or "--from=" in args:
            continue
        sources = [w for w in args.split() if not w.startswith("--")][:-1]
        for src in sources:
            assert (REPO / src).exists(), src
            assert not any(fnmatch.fnmatch(src, pattern) for pattern in ignored), src
    for secret in (".env", ".git", ".venv", "tcgcs-data"):
        assert secret in ignored


# -- the commands, run as the containers would -----------------------------------------------------


def _head_of(url: str, schema: str | None = None) -> str:
    engine = create_engine(url)
    try:
        with engine.connect() as conn:
            assert "flights" in inspect(conn).get_table_names(schema=schema)
            version = conn.execute(text("select version_num from alembic_version")).scalar_one()
    finally:
        engine.dispose()
    return str(version)


@pytest.mark.slow  # several seconds: left out of make test-quick
async def test_migrate_brings_postgresql_to_the_head_twice_over(
    compose: dict[str, Any], pg_url: str, app_dir: Path
) -> None:
    svc = services(compose)["migrate"]
    env = service_env(svc, TCGCS_DATABASE_URL=pg_url, TCGCS_DATA_DIR=str(app_dir / "data"))
    for _ in range(2):  # a migrate container started again finds the schema at the head
        code, out = await run(local_argv(svc["command"]), env, app_dir)
        assert code == 0, out
        assert "is at the latest revision" in out
    assert _head_of(pg_url) == HEAD
    code, out = await run([*local_argv(svc["command"]), "--url", pg_url], env, app_dir)
    assert code == 0, out


async def test_migrate_with_a_sqlite_url_makes_the_file_and_its_folder(
    compose: dict[str, Any], app_dir: Path
) -> None:
    svc = services(compose)["migrate"]
    url = f"sqlite:///{app_dir / 'data' / 'sub' / 'tcgcs.db'}"
    env = service_env(svc, TCGCS_DATA_DIR=str(app_dir / "data"))
    code, out = await run([*local_argv(svc["command"]), "--url", url], env, app_dir)
    assert code == 0, out
    assert _head_of(url) == HEAD


def _sitl_here(compose: Mapping[str, Any], base: int) -> list[str]:
    return local_argv(services(compose)["sitl"]["command"], host="127.0.0.1", tcp_base=str(base))


async def _heartbeat(port: int) -> Any:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    parser = mavlink2.MAVLink(None)
    parser.robust_parsing = True
    try:
        async with asyncio.timeout(10):
            while True:
                for m in parser.parse_buffer(await reader.read(4096)) or []:
                    if m.get_type() == "HEARTBEAT":
                        return m
    finally:
        writer.close()


async def test_sitl_runs_three_vehicles_until_stopped(
    compose: dict[str, Any], app_dir: Path
) -> None:
    base = free_port_base(3)
    svc = services(compose)["sitl"]
    env = service_env(svc, TCGCS_DATA_DIR=str(app_dir / "data"))
    async with running(_sitl_here(compose, base), env, app_dir, "ready") as line:
        assert "3 vehicle(s) ready" in line
        assert f"[{base}, {base + 10}, {base + 20}]" in line
        for i in range(3):
            beat = await _heartbeat(base + 10 * i)
            assert beat.get_srcSystem() == i + 1
            assert beat.type == mavlink2.MAV_TYPE_FIXED_WING


async def _flight_on(c: httpx.AsyncClient, ids: list[str], scenario: Path) -> None:
    """A flight of the sitl service's scenario on its vehicles, scenario vehicle i on vehicle
    i (sitl's vehicle i starts at scenario vehicle i's start), as the README says."""
    text = scenario.read_text(encoding="utf-8")
    r = await c.post("/v1/scenarios", content=text, headers={"Content-Type": "application/yaml"})
    assert r.status_code == 201, r.text
    job = (await c.post("/v1/schedules", json={"scenario_id": r.json()["id"], "seed": 1})).json()
    while job["state"] in ("queued", "running"):  # however long a busy machine takes
        await asyncio.sleep(0.2)
        job = (await c.get(f"/v1/jobs/{job['id']}")).json()
    assert job["state"] == "succeeded", job["error"]
    vehicles = [v["id"] for v in job["result"]["vehicles"]]
    body = {"schedule_id": job["result"]["id"], "vehicles": dict(zip(vehicles, ids, strict=True))}
    r = await c.post("/v1/flights", json=body)
    assert r.status_code == 201, r.text
    snap = r.json()
    assert snap["state"] == "planned"
    assert [v["link"]["system_id"] for v in snap["vehicles"]] == [1, 2, 3]


@pytest.mark.slow  # several seconds: left out of make test-quick
async def test_api_answers_health_and_ready_and_reaches_the_sitl_vehicles(
    compose: dict[str, Any], pg_url: str, app_dir: Path
) -> None:
    svc = services(compose)
    data = app_dir / "data"
    paths = {"TCGCS_DATABASE_URL": pg_url, "TCGCS_DATA_DIR": str(data)}
    code, out = await run(
        local_argv(svc["migrate"]["command"]), service_env(svc["migrate"], **paths), app_dir
    )
    assert code == 0, out
    port = free_port_base(1)
    api = local_argv(svc["api"]["command"], host="127.0.0.1", port=str(port))
    base = free_port_base(3)
    async with (
        running(_sitl_here(compose, base), service_env(svc["sitl"], **paths), app_dir, "ready"),
        running(api, service_env(svc["api"], **paths), app_dir, "serving on", SERVE_EXITS) as line,
    ):
        assert f"http://127.0.0.1:{port}/v1" in line
        async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}", timeout=10) as c:
            for _ in range(100):
                with contextlib.suppress(httpx.TransportError):
                    if (await c.get("/v1/health")).status_code == 200:
                        break
                await asyncio.sleep(0.1)
            health = await c.get("/v1/health")
            assert health.status_code == 200 and health.json() == {"status": "ok"}
            ready = await c.get("/v1/ready")
            assert ready.status_code == 200, ready.text
            assert ready.json()["status"] == "ready"
            # No TCGCS_TOKENS in the compose file: the admin token is in the data volume.
            token = (data / "admin.token").read_text().strip()
            c.headers["Authorization"] = f"Bearer {token}"
            ids = []
            for i in range(3):  # tcp:sitl:5760, tcp:sitl:5770, tcp:sitl:5780 in the compose
                r = await c.post(
                    "/v1/vehicles", json={"connection": f"tcp:127.0.0.1:{base + 10 * i}"}
                )
                assert r.status_code == 201, r.text
                ids.append(r.json()["id"])
            assert len((await c.get("/v1/vehicles")).json()) == 3
            await _flight_on(c, ids, REPO / sitl_parse_args(svc["sitl"]["command"][3:]).scenario)
        # The compose healthcheck, run as Docker runs it in the container (here on its port).
        probe = svc["api"]["healthcheck"]["test"]
        assert probe[0] == "CMD"
        here = [arg.replace(":8600/", f":{port}/") for arg in local_argv(probe[1:])]
        code, out = await run(here, service_env(svc["api"], **paths), app_dir)
        assert code == 0, out
