"""Processes as ``/proc`` shows them (Linux), for the tests and benchmarks that kill some."""

from __future__ import annotations

import time
from pathlib import Path

__all__ = ["goes", "gone"]


def gone(pid: int) -> bool:
    """No live process (a zombie waiting for init to reap it has no memory and runs nothing)
    with that id, nor in the process group it led."""
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            state, _, pgid = (d / "stat").read_text().rsplit(")", 1)[1].split()[:3]
        except OSError:
            continue
        if (int(d.name) == pid or int(pgid) == pid) and state != "Z":
            return False
    return True


def goes(pid: int, within_s: float = 10.0) -> bool:
    """Whether ``pid`` and its group are :func:`gone` within ``within_s`` (wall): a process
    sent SIGKILL takes a moment to exit (its memory given back first), the more so on a busy
    machine; the bound only tells that from one that lives on."""
    deadline = time.monotonic() + within_s
    while not gone(pid):
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True
