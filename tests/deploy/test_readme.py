"""The README's walk-through as a new user runs it: the paper flight by hand with ``curl`` and
``jq`` against ``python -m gcs serve`` started as ``make serve`` starts it (its defaults: the
data folder ``tcgcs-data`` where it runs, the admin token it writes there). The commands are
read from the README itself, so that the README and the service cannot drift apart; only the
port is the test's own (another test may hold 8600).

The flight is judged from the truth log the service's simulator wrote (:mod:`tests.oracle`
through :func:`tests.verdict.assert_flown`), not from the figures the walk-through prints."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import sys
from pathlib import Path

import httpx
import pytest

from gcs.api.process import ServiceProcess, free_port, wait_ready
from tests.paperbounds import team_time_move_max_s
from tests.verdict import assert_flown

pytestmark = pytest.mark.slow  # a whole flight at 200x

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
INTRO = "The paper flight by hand against `make serve`"
README_API = "http://127.0.0.1:8600/v1"
READY_WALL_S = 120.0
"""A bound on a service that never comes up (no verdict: it answers within seconds)."""
TOGETHER_MIN_S = 1_000.0
"""The three fly together for over an hour once the last is up: at least this long."""


def walk_through() -> str:
    """The README's shell block after :data:`INTRO`."""
    text = README.read_text()
    start = text.index("```sh\n", text.index(INTRO)) + len("```sh\n")
    return text[start : text.index("```", start)]


async def test_the_readmes_walk_through_flies_the_paper_flight_on_its_slots(
    tmp_path: Path,
) -> None:
    script = walk_through()
    assert README_API in script
    port = free_port()
    script = script.replace(README_API, f"http://127.0.0.1:{port}/v1")
    (tmp_path / "scenarios").symlink_to(ROOT / "scenarios")
    # As from a shell with nothing set: the service's own defaults.
    env = {k: v for k, v in os.environ.items() if not k.startswith("TCGCS_")}
    serve = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "gcs", "serve", "--port", str(port), cwd=tmp_path, env=env,
        stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    try:
        await wait_ready(ServiceProcess(f"http://127.0.0.1:{port}", serve), READY_WALL_S)
        run = await asyncio.create_subprocess_exec(
            "bash", "-e", "-o", "pipefail", "-c", script, cwd=tmp_path, env=env,
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
        )  # fmt: skip
        out, err = await run.communicate()
        assert run.returncode == 0, err.decode()[-3000:]
        # What the README says the steps print: the job's outcome, and the record's arrivals last.
        printed = out.decode()
        job, _ = json.JSONDecoder().raw_decode(printed, printed.index("{"))
        assert job["state"] == "succeeded" and job["error"] is None, job
        arrivals = json.loads(printed.splitlines()[-1])
        assert [v["id"] for v in arrivals] == ["UAV1", "UAV2", "UAV3"], arrivals
        data = tmp_path / "tcgcs-data"
        token = (data / "admin.token").read_text().strip()
        async with httpx.AsyncClient(
            base_url=f"http://127.0.0.1:{port}", headers={"Authorization": f"Bearer {token}"}
        ) as client:
            (flight,) = (await client.get("/v1/flights")).json()
            record = (await client.get(f"/v1/flights/{flight['id']}/record")).json()
    finally:
        if serve.returncode is None:
            serve.send_signal(signal.SIGINT)
        _, stderr = await serve.communicate()
    assert serve.returncode == 0 and b"Traceback" not in stderr, stderr.decode()[-3000:]
    assert record["state"] == "completed", record["state_reason"]
    assert_flown(
        record,
        data / "flights" / flight["id"] / "truth.jsonl",
        tolerance_s=1.0,
        team_shift_max_s=team_time_move_max_s(5.0, 270.0),
        together_min_s=TOGETHER_MIN_S,
    )
