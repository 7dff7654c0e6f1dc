"""A flight worker's scheduling priority (``--nice``, from ``TCGCS_WORKER_NICE``): set where the
process may, said (not raised) where it may not. The flight test that asks for it is
``tests/service/test_restart_http.py::test_a_killed_or_hung_flight_worker_is_flown_on_from_its_checkpoint``."""

from __future__ import annotations

import errno
import os

import pytest

from gcs.service.worker import prioritize
from gcs.service.workers import WORKERS_AHEAD, ahead_of_service


def test_a_priority_the_process_may_not_take_is_said_and_it_runs_on_at_its_own(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    now = os.getpriority(os.PRIO_PROCESS, 0)
    asked: list[int] = []

    def refuse(which: int, who: int, value: int) -> None:
        asked.append(value)
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES))

    monkeypatch.setattr(os, "setpriority", refuse)
    said = prioritize(now - 5)
    assert asked == [now - 5]
    assert said == f"priority {now - 5} refused ({os.strerror(errno.EACCES)}): it runs at {now}"
    assert prioritize(now) is None and asked == [now - 5]  # already there: nothing asked


def test_unless_told_the_workers_run_ahead_of_the_service_where_it_may_raise_a_priority(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Tried on the service's own process, then put back; refused, the service's."""
    now = os.getpriority(os.PRIO_PROCESS, 0)
    asked: list[int] = []
    real = os.setpriority

    def record(which: int, who: int, value: int) -> None:
        asked.append(value)
        real(which, who, value)

    monkeypatch.setattr(os, "setpriority", record)
    may = ahead_of_service()
    assert os.getpriority(os.PRIO_PROCESS, 0) == now  # put back
    if may is None:  # this user may not raise a priority: the one try, refused
        assert asked == [max(-20, now - WORKERS_AHEAD)]
    else:
        assert may == max(-20, now - WORKERS_AHEAD) and asked == [may, now]

    def refuse(which: int, who: int, value: int) -> None:
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES))

    monkeypatch.setattr(os, "setpriority", refuse)
    assert ahead_of_service() is None
    assert os.getpriority(os.PRIO_PROCESS, 0) == now
