"""Jobs in processes of their own (:class:`gcs.service.processjobs.ProcessJobs`): a job that
succeeds gives back all its memory (its process is gone once its answer is in), and its progress
comes back as it goes, in order; a planning job's stages go forward."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from gcs.service import planjobs
from gcs.service.processjobs import ProcessJobs, Progress
from planner.scenario import load_scenario
from tests.procs import goes

PAPER = Path(__file__).resolve().parents[2] / "scenarios" / "paper_three_uav.yaml"
BIG_MB = 200


def _rss_mb(pid: int | str = "self") -> float:
    """Resident memory of a process (``/proc/PID/status``, VmRSS)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise AssertionError(f"no VmRSS for {pid}")


def _big(progress: Progress, mb: int) -> tuple[int, float]:
    """Holds ``mb`` of memory, saying so in three steps: its pid and its resident memory."""
    progress(0.1, "allocating")
    block = np.ones(mb * 1024 * 1024 // 8)
    progress(0.5, "holding")
    rss = _rss_mb()
    progress(0.9, "answering")
    return os.getpid(), rss + 0.0 * float(block[0])


async def test_a_job_that_succeeds_gives_back_its_memory_and_its_progress_in_order() -> None:
    jobs = ProcessJobs(1)
    said: list[tuple[float, str]] = []
    try:
        before_mb = _rss_mb()
        pid, job_rss_mb = await jobs.run(
            "big", _big, BIG_MB, time_limit_s=600.0, on_progress=lambda f, s: said.append((f, s))
        )
    finally:
        jobs.close()
    assert pid != os.getpid()
    assert job_rss_mb > BIG_MB  # it held the memory, in its own process
    # Its answer in, its process (and group) is gone: nothing of its memory is kept anywhere.
    assert goes(pid)
    assert jobs.running_pid("big") is None
    assert _rss_mb() - before_mb < BIG_MB / 4
    assert said == [(0.1, "allocating"), (0.5, "holding"), (0.9, "answering")]


def test_a_planning_job_says_its_stages_in_order_and_only_forward() -> None:
    said: list[tuple[float, str]] = []
    got = planjobs.plan_schedule(lambda f, s: said.append((f, s)), load_scenario(PAPER), 1, "aco")
    assert got[0] == "ok"
    fractions = [f for f, _ in said]
    assert fractions == sorted(fractions) and fractions[0] > 0.0 and fractions[-1] < 1.0
    assert [s for _, s in said] == [
        "building the world",
        "planning routes",
        "timing",
        "checking feasibility",
        "keeping",
    ]
