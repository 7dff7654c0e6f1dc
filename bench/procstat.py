"""CPU time and resident memory of processes, read from ``/proc`` (Linux), for the benchmarks."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from pathlib import Path

TICKS_PER_S = os.sysconf("SC_CLK_TCK")
PAGE_BYTES = os.sysconf("SC_PAGE_SIZE")


def cpu_s(pid: int) -> float | None:
    """User + system CPU seconds of a process (None once it has gone)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / TICKS_PER_S


def rss_mib(pid: int) -> float | None:
    """Resident memory of a process, MiB (None once it has gone)."""
    try:
        pages = int(Path(f"/proc/{pid}/statm").read_text().split()[1])
    except OSError:
        return None
    return pages * PAGE_BYTES / 2**20


def children(pid: int) -> list[int]:
    try:
        text = Path(f"/proc/{pid}/task/{pid}/children").read_text()
    except OSError:
        return []
    return [int(x) for x in text.split()]


def tree(pid: int) -> list[int]:
    """A process and all its descendants."""
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        todo.extend(children(p))
    return out


class TreeMemory:
    """The peak of the summed resident memory of a process tree, sampled by a separate
    process (a sampling thread here would keep the planner from forking its workers: it
    forks only while it runs alone)."""

    def __init__(self, pid: int | None = None, period_s: float = 0.25) -> None:
        self.pid = os.getpid() if pid is None else pid
        self.period_s = period_s
        self.peak_mib = 0.0
        self._sampler: subprocess.Popen[str] | None = None

    def __enter__(self) -> TreeMemory:
        self._sampler = subprocess.Popen(
            [sys.executable, __file__, str(self.pid), str(self.period_s)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        return self

    def __exit__(self, *exc: object) -> None:
        assert self._sampler is not None
        out, _ = self._sampler.communicate("")  # closing its input stops it
        self.peak_mib = float(out)


def _sample(pid: int, period_s: float) -> None:
    """Sample the tree of ``pid`` (less this process) until standard input closes; print
    the peak (MiB)."""
    peak = 0.0
    done = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
    me = os.getpid()
    while not done.wait(period_s):
        peak = max(peak, sum(rss_mib(p) or 0.0 for p in tree(pid) if p != me))
    peak = max(peak, sum(rss_mib(p) or 0.0 for p in tree(pid) if p != me))
    print(peak)


if __name__ == "__main__":
    _sample(int(sys.argv[1]), float(sys.argv[2]))
