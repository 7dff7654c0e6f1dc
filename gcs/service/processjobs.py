"""Work that would hold the service's event loop or its GIL, done in OS processes of its own.

:class:`ProcessJobs` runs each call in a process forked from a server that has the planner
imported already (``multiprocessing``'s forkserver: a process with no threads and no event
loop to fork from, so a job starts in milliseconds). A job:

- never holds the service's event loop or its GIL: a flight's control loop and every reader
  go on while it works;
- is cancelled, or stopped at its time limit, by killing its process group (the planner's own
  worker processes with it);
- gives all its memory back when it ends (a 1,000-vehicle schedule peaks past 2 GB, and a
  process that lives on keeps most of that);
- waits its turn: at most ``max_running`` run at once, the others queue in order.

The function is called in the child as ``fn(progress, *args)``, where ``progress(fraction,
stage)`` reports how far it has got; what it returns comes back pickled. An exception in the
child comes back as :class:`JobFailed` with its type name and message (the function returns,
rather than raises, the outcomes its caller must tell apart).
"""

from __future__ import annotations

import asyncio
import contextlib
import multiprocessing
import os
import signal
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from multiprocessing.connection import Connection
from typing import Any

__all__ = ["JobCancelled", "JobFailed", "JobTimedOut", "ProcessJobs", "Progress"]

Progress = Callable[[float, str], None]
"""``progress(fraction, stage)``: how far a job has got (0 to 1) and what it is doing."""


class JobCancelled(Exception):
    """The job was cancelled (its process killed)."""


class JobTimedOut(Exception):
    """The job overran its time limit (its process killed)."""


class JobFailed(Exception):
    """The job's function raised, or its process died: what and why."""


class ProcessJobs:
    """Calls run one per OS process, at most ``max_running`` at once."""

    def __init__(self, max_running: int, *, preload: Sequence[str] = (), niceness: int = 0) -> None:
        self.niceness = niceness
        """How much lower a job's scheduling priority is than this process's (``nice``)."""
        self._ctx = multiprocessing.get_context("forkserver")
        self._ctx.set_forkserver_preload(list(preload))
        self._slots = asyncio.Semaphore(max(1, max_running))
        # Per running job, a thread waits on its pipe (a result is read, and unpickled, off
        # the loop), and one starts or reaps its process.
        self._readers = ThreadPoolExecutor(
            2 * max(1, max_running) + 1, thread_name_prefix="tcgcs-job"
        )
        self._running: dict[str, multiprocessing.process.BaseProcess] = {}
        self._cancelled: set[str] = set()

    def running_pid(self, key: str) -> int | None:
        """The process id of a running job, else None."""
        proc = self._running.get(key)
        return None if proc is None else proc.pid

    async def run(
        self,
        key: str,
        fn: Callable[..., Any],
        *args: Any,
        time_limit_s: float,
        on_start: Callable[[], None] | None = None,
        on_progress: Progress | None = None,
    ) -> Any:
        """``fn(progress, *args)`` in a process of its own once a slot is free; its result.

        Raises
        ------
        JobCancelled
            :meth:`cancel` was called for ``key`` (before or while it ran).
        JobTimedOut
            It ran longer than ``time_limit_s`` (wall seconds from its start).
        JobFailed
            ``fn`` raised, or its process died.
        """
        async with self._slots:
            if key in self._cancelled:
                self._cancelled.discard(key)
                raise JobCancelled(key)
            loop = asyncio.get_running_loop()
            parent, child = self._ctx.Pipe(duplex=False)
            proc = self._ctx.Process(
                target=_child, args=(child, self.niceness, fn, args), name=f"tcgcs-job-{key}"
            )
            self._running[key] = proc
            started = loop.run_in_executor(self._readers, proc.start)
            try:
                await asyncio.shield(started)
                child.close()
                if key in self._cancelled:  # cancelled while it started
                    raise JobCancelled(key)
                if on_start is not None:
                    on_start()
                return await asyncio.wait_for(
                    self._receive(parent, proc, key, on_progress), time_limit_s
                )
            except TimeoutError:
                raise JobTimedOut(f"ran longer than its {time_limit_s:g} s limit") from None
            finally:
                self._running.pop(key, None)
                with contextlib.suppress(BaseException):
                    await started  # so that a process being started is killed, not missed
                child.close()
                _kill(proc)
                if proc.pid is not None:
                    await loop.run_in_executor(self._readers, proc.join)
                    # Again, once it is gone: a worker it was forking as the first kill came
                    # was not yet in its group then, and would live on.
                    _kill_group(proc.pid)
                parent.close()
                self._cancelled.discard(key)

    async def _receive(
        self,
        conn: Connection,
        proc: multiprocessing.process.BaseProcess,
        key: str,
        on_progress: Progress | None,
    ) -> Any:
        loop = asyncio.get_running_loop()
        while True:
            try:
                tag, *value = await loop.run_in_executor(self._readers, conn.recv)
            except (EOFError, OSError):
                if key in self._cancelled:
                    raise JobCancelled(key) from None
                await loop.run_in_executor(self._readers, proc.join)
                raise JobFailed(f"its process ended with exit code {proc.exitcode}") from None
            if tag == "progress":
                if on_progress is not None:
                    on_progress(float(value[0]), str(value[1]))
            elif tag == "done":
                return value[0]
            else:
                raise JobFailed(f"{value[0]}: {value[1]}")

    def cancel(self, key: str) -> None:
        """Cancel a job: a running one's process (and any it started) is killed now; a queued
        one never starts."""
        self._cancelled.add(key)
        proc = self._running.get(key)
        if proc is not None:
            _kill(proc)

    def close(self) -> None:
        """Kill every running job."""
        for key in list(self._running):
            self.cancel(key)
        self._readers.shutdown(wait=False, cancel_futures=True)


JOB_NICENESS = 10
"""How much lower a job's scheduling priority is than the service's (``nice``): planning is
batch work, flights are not."""


def _kill(proc: multiprocessing.process.BaseProcess) -> None:
    """Kill a job's process group (the job leads its own: see :func:`_child`)."""
    if proc.pid is None:
        return
    _kill_group(proc.pid)
    with contextlib.suppress(ProcessLookupError):
        proc.kill()


def _kill_group(pgid: int) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pgid, signal.SIGKILL)


def _child(conn: Connection, niceness: int, fn: Callable[..., Any], args: tuple[Any, ...]) -> None:
    """The job's process: a group of its own (so that a kill takes any worker processes it
    starts too), at ``niceness`` (the service's jobs at :data:`JOB_NICENESS`: a flight's
    control loop is served first when the cores are busy), the function, its result sent
    back."""
    os.setpgid(0, 0)
    if niceness:
        with contextlib.suppress(OSError):
            os.nice(niceness)

    def progress(fraction: float, stage: str) -> None:
        conn.send(("progress", fraction, stage))

    try:
        result = fn(progress, *args)
    except Exception as err:  # the job's failure, said to the service
        conn.send(("error", type(err).__name__, str(err)))
    else:
        conn.send(("done", result))
    finally:
        conn.close()
