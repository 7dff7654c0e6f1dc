"""A flight worker's scheduling priority (``--nice``, from ``TCGCS_WORKER_NICE``): set where the
process may, said (not raised) where it may not. The flight test that asks for it is
``tests/service/test_restart_http.py::test_a_killed_or_hung_flight_worker_is_flown_on_from_its_checkpoint``."""

from __future__ import annotations

import errno
import os

import pytest

from gcs.service.worker import prioritize


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
