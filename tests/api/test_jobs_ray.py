"""Planning jobs on Ray (``TCGCS_PLAN_RAY``): with ``local`` each schedule job starts a Ray on
this machine, and with a cluster's address it joins that cluster (started here as an operator
starts one, ``ray start --head``, with token authentication on); either way it finishes its
vehicles' routes there, giving the schedule the job gives without Ray for the same seed. A
cancelled job takes the Ray it started with it."""

from __future__ import annotations

import asyncio
import contextlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from gcs.service import planjobs
from planner.backend import AUTH_MODE_ENV, AUTH_TOKEN_ENV, AUTH_TOKEN_PATH_ENV, LOOPBACK_ONLY_ENV
from planner.scenario import load_scenario
from tests.api.conftest import PAPER, app_with, auth, running
from tests.procs import goes
from tests.service.conftest import nice_of
from tests.teams import ring_team

# One Ray at a time on the machine: with the planner's Ray tests, on one worker under -n.
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("ray")]

RAY_JOB_NICENESS = 2
"""The jobs' niceness here (``TCGCS_JOB_NICENESS``, 10 unless set): Ray waits a fixed 30 s for
the node a job starts to register, which a Ray at 10 below a busy machine's other processes
does not make."""


def _ray_processes() -> set[int]:
    """Live processes of a Ray (its workers name themselves ``ray::...``; its services run
    from Ray's package)."""
    found = set()
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            state = (d / "stat").read_text().rsplit(")", 1)[1].split()[0]
            cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ")
        except OSError:
            continue
        if state != "Z" and (cmd.startswith(b"ray::") or b"/site-packages/ray/" in cmd):
            found.add(int(d.name))
    return found


CLUSTER_READY_WALL_S = 120.0
"""How long ``ray start --head`` may take to say its cluster is up (a bound on a hang, no
verdict: it takes 5-20 s here)."""


def _gcs_port() -> int:
    """A free port for the head's GCS, in the ephemeral range: outside the range Ray gives its
    workers (10002-19999) and none of its other fixed ports."""
    while True:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port: int = s.getsockname()[1]
        if not 10002 <= port <= 19999 and port not in (6379, 8265, 10001, 52365):
            return port


@pytest.fixture
def ray_cluster() -> Iterator[str]:
    """A Ray cluster on this machine, started as an operator starts one (``ray start --head``)
    on the loopback address, with token authentication on: its address. The token is Ray's
    default one (``~/.ray/auth_token``: made as Ray's docs say, by ``ray get-auth-token
    --generate``, unless a Ray started here already made it), and the jobs are told nothing of
    it: ``RAY_AUTH_MODE`` is left as the service has it (the jobs' fork server keeps the
    environment it started with)."""
    temp = Path(tempfile.mkdtemp(prefix="ray", dir="/tmp"))  # short: Ray's sockets are in it
    port = _gcs_port()
    ray_cli = str(Path(sys.executable).with_name("ray"))
    env = os.environ | {AUTH_MODE_ENV: "token", LOOPBACK_ONLY_ENV: "0"}
    env.pop(AUTH_TOKEN_PATH_ENV, None)
    env.pop(AUTH_TOKEN_ENV, None)
    subprocess.run(
        [ray_cli, "get-auth-token", "--generate"], env=env, check=True, capture_output=True
    )
    log = temp / "head.log"
    with log.open("wb") as out:
        head = subprocess.Popen(
            [
                ray_cli, "start", "--head", "--block",
                f"--port={port}", "--num-cpus=1", "--include-dashboard=false",
                f"--temp-dir={temp}", "--disable-usage-stats",
            ],
            env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True,
        )  # fmt: skip
    try:
        deadline = time.monotonic() + CLUSTER_READY_WALL_S
        while b"Ray runtime started" not in log.read_bytes():
            assert head.poll() is None, log.read_text()
            assert time.monotonic() < deadline, log.read_text()
            time.sleep(0.1)
        yield f"127.0.0.1:{port}"
    finally:
        # Its whole process group: the head's services and the workers they started.
        for sig, wait_s in ((signal.SIGTERM, 10.0), (signal.SIGKILL, 10.0)):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(head.pid, sig)
            with contextlib.suppress(subprocess.TimeoutExpired):
                head.wait(wait_s)
        shutil.rmtree(temp, ignore_errors=True)


@pytest.mark.parametrize("where", ["local", "cluster"])
async def test_a_schedule_planned_on_ray_is_the_one_planned_without_it(
    tmp_path: Path, where: str, request: pytest.FixtureRequest
) -> None:
    # Without Ray, in this process: the job's own function, for the same seed.
    planned = planjobs.plan_schedule(lambda *_: None, load_scenario(PAPER), 1, "aco")
    assert planned[0] == "ok"
    blob = planned[1]
    assert isinstance(blob, bytes)
    _, here, _ = planjobs.kept_schedule(blob)
    ray = "local" if where == "local" else request.getfixturevalue("ray_cluster")
    app = app_with(tmp_path, plan_ray=ray, job_niceness=RAY_JOB_NICENESS)
    async for client in running(app):
        r = await client.post(
            "/v1/scenarios",
            content=PAPER.read_bytes(),
            headers=auth("plan") | {"content-type": "application/yaml"},
        )
        assert r.status_code == 201, r.text
        body = {"scenario_id": r.json()["id"], "seed": 1}
        r = await client.post("/v1/schedules", json=body, headers=auth("plan"))
        assert r.status_code == 202, r.text
        stages: set[str] = set()
        while (job := await _job(client, r.json()["id"]))["state"] in ("queued", "running"):
            stages.add(job["stage"])
            await asyncio.sleep(0.02)
        assert job["state"] == "succeeded", job
        # It went through Ray (the stages it said as it went, as many as were polled).
        said = "starting Ray" if where == "local" else f"joining Ray at {ray}"
        assert stages & {said, "planning routes on Ray"}, stages
        on_ray = app.state.engine.planning.schedules[job["result"]["id"]].schedule
    assert on_ray.required_arrival_s == here.required_arrival_s
    for a, b in zip(on_ray.vehicles, here.vehicles, strict=True):
        assert (a.vehicle_id, a.takeoff_s, a.arrival_s) == (b.vehicle_id, b.takeoff_s, b.arrival_s)
        np.testing.assert_array_equal(a.path.cumulative_m(), b.path.cumulative_m())


async def test_a_cancelled_job_planning_on_ray_takes_its_ray_with_it(tmp_path: Path) -> None:
    before = _ray_processes()
    app = app_with(tmp_path, plan_ray="local", job_niceness=RAY_JOB_NICENESS)
    async for client in running(app):
        r = await client.post(
            "/v1/scenarios",
            json=ring_team(1000),
            headers=auth("plan"),
        )
        assert r.status_code == 201, r.text
        r = await client.post(
            "/v1/schedules", json={"scenario_id": r.json()["id"]}, headers=auth("plan")
        )
        # Once its Ray runs: its stage says so, and its processes are up.
        while (job := await _job(client, r.json()["id"]))["stage"] != "planning routes on Ray":
            assert job["state"] in ("queued", "running"), job
            await asyncio.sleep(0.02)
        rays = _ray_processes() - before
        assert rays
        pid = app.state.engine.planning.work.running_pid(job["id"])
        assert pid is not None and pid != os.getpid()
        # The job behind this process by TCGCS_JOB_NICENESS, and the Ray it started no
        # further ahead (Ray puts its own workers further behind).
        nice = os.getpriority(os.PRIO_PROCESS, 0) + RAY_JOB_NICENESS
        assert nice_of(pid) == nice
        ray_nice = {}
        for p in rays:
            with contextlib.suppress(OSError):  # gone meanwhile
                ray_nice[p] = nice_of(p)
        assert ray_nice and min(ray_nice.values()) >= nice, ray_nice
        r = await client.delete(f"/v1/jobs/{job['id']}", headers=auth("plan"))
        assert r.status_code == 200 and r.json()["state"] == "cancelled", r.text
        assert goes(pid)
        assert goes_all(before)


async def _job(client: httpx.AsyncClient, job_id: str) -> dict[str, Any]:
    r = await client.get(f"/v1/jobs/{job_id}", headers=auth())
    assert r.status_code == 200, r.text
    job: dict[str, Any] = r.json()
    return job


def goes_all(before: set[int], within_s: float = 10.0) -> bool:
    """Whether every Ray process not running ``before`` has exited within ``within_s``."""
    deadline = time.monotonic() + within_s
    while _ray_processes() - before:
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True
