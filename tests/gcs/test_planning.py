"""gcs.coordination.planning: planning jobs run in worker processes, off the event loop."""

from __future__ import annotations

import functools
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from gcs.coordination.planning import run_planning
from planner.errors import InfeasibleError

ROOT = Path(__file__).resolve().parents[2]


def _refuse(vehicle: str) -> None:
    raise InfeasibleError(f"vehicle {vehicle}: no route", vehicle=vehicle)


async def test_a_job_runs_in_another_process_and_its_error_comes_back_typed() -> None:
    pid = await run_planning(functools.partial(os.getpid))
    assert pid != os.getpid()
    with pytest.raises(InfeasibleError, match="vehicle UAV3: no route") as err:
        await run_planning(functools.partial(_refuse, "UAV3"))
    assert err.value.vehicle == "UAV3"


def test_a_script_without_a_main_guard_is_not_run_again_in_the_workers(tmp_path: Path) -> None:
    """multiprocessing imports the caller's main module again in each worker; a script that
    flies its flight at the top level would fly it again there."""
    script = tmp_path / "unguarded.py"
    script.write_text(
        textwrap.dedent(
            """
            import asyncio, functools, os
            from gcs.coordination.planning import run_planning
            print("ran", flush=True)
            pid = asyncio.run(run_planning(functools.partial(os.getpid)))
            print("worker", pid != os.getpid(), flush=True)
            """
        )
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=60, env=env
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines() == ["ran", "worker True"], (out.stdout, out.stderr)
