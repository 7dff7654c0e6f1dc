"""Processes as ``/proc`` shows them (Linux), for the tests and benchmarks that kill some."""

from __future__ import annotations

from pathlib import Path

__all__ = ["gone"]


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
