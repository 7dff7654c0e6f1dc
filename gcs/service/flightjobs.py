"""A flight's planning jobs (a re-plan round a zone, loiter turns) in OS processes of their own.

In a thread of the flight's worker a job held the worker's interpreter lock while it computed:
the event loop that reads the vehicles' reports and sends their commands then woke tens of
milliseconds late, more on a busy machine. In a process of its own (forked from a server that
has the planner loaded: :class:`~gcs.service.processjobs.ProcessJobs`) it holds nothing of the
worker's; it runs at the worker's own priority (a re-plan is as urgent as the flight). What it
raises is raised here again, as it was raised.
"""

from __future__ import annotations

import os
import pickle
from typing import Any

from gcs.coordination.actions import LoiterJob, PopupJob
from gcs.errors import GcsError
from gcs.service.processjobs import ProcessJobs, Progress

__all__ = ["FlightJobs", "start_server"]

PRELOAD = ("gcs.service.flightjobs", "scipy.sparse.csgraph")
"""Imported once by the jobs' fork server (the planner with it)."""
RUNNING = 2
"""Jobs of one flight that run at once (a loiter job beside a re-plan)."""
TIME_LIMIT_S = 600.0
"""A job running longer (wall s) is stopped: the runner's own budget ends a re-plan's search
long before."""


def start_server() -> None:
    """Start the jobs' fork server now (its imports take a second or two), not with a flight's
    first job: a worker does this as it starts, a standby one before its flight is given."""
    import multiprocessing
    from multiprocessing import forkserver

    multiprocessing.get_context("forkserver").set_forkserver_preload(list(PRELOAD))
    # Started with /dev/null as its stdout: the worker's stdout is a pipe the service reads,
    # and a server holding it would keep it open after the worker has gone.
    saved, devnull = os.dup(1), os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    try:
        forkserver.ensure_running()
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


class FlightJobs:
    """Runs one flight's planning jobs, each in a process of its own
    (:attr:`gcs.coordination.runner.FlightRunner.run_job`)."""

    def __init__(self) -> None:
        self._jobs = ProcessJobs(RUNNING, preload=PRELOAD)
        self._count = 0

    async def run(self, job: LoiterJob | PopupJob) -> Any:
        """``job.run()`` in a process of its own: its result, or what it raised."""
        self._count += 1
        kind, value = await self._jobs.run(str(self._count), _run, job, time_limit_s=TIME_LIMIT_S)
        if kind == "raised":
            raise value
        return value

    def close(self) -> None:
        """Kill any job still running."""
        self._jobs.close()


def _run(progress: Progress, job: LoiterJob | PopupJob) -> tuple[str, Any]:
    try:
        return "ok", job.run()
    except Exception as err:
        try:
            pickle.loads(pickle.dumps(err))  # it crosses back whole, or said as a GcsError
        except Exception:
            err = GcsError(f"{type(err).__name__}: {err}")
        return "raised", err
