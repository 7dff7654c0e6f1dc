"""The flight's checkpoint (what a restart resumes from) is written at once when a mission
is sent, whether or not an event goes with it: a restart finds the vehicle flying a mission
the checkpoint knows was sent, instead of one it takes for a stranger and replaces."""

from __future__ import annotations

import pickle
from collections.abc import Coroutine
from typing import Any

import pytest

from gcs.coordination import actions as act
from gcs.coordination.missionclock import MissionClock
from gcs.coordination.runner import CHECKPOINT_WALL_S, FlightRunner
from planner.scenario import load_scenario
from tests.gcs.conftest import PAPER


def test_an_upload_sent_with_no_event_beside_it_is_checkpointed_at_once(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Loiter turns worked out for an early vehicle go up with no event of their own (it is
    said once they are on board): the upload alone writes the checkpoint, even within
    :data:`CHECKPOINT_WALL_S` of the last one, which routine changes wait out."""
    runner = FlightRunner(load_scenario(PAPER), MissionClock())
    runner.team = {"stands for": "the team"}  # type: ignore[assignment]
    kept: list[bytes] = []
    runner.on_checkpoint = kept.append
    sent: list[str] = []

    def spawn(coro: Coroutine[Any, Any, object]) -> None:
        sent.append(coro.__qualname__)
        coro.close()

    monkeypatch.setattr(runner, "_spawn", spawn)
    runner._checkpoint(at_once=True)  # just written
    assert len(kept) == 1
    runner._dispatch([act.CommandSpeed("UAV1", 20.0, "routine", 0.0)])
    assert sent == ["FlightRunner._command_speed"] and len(kept) == 1  # routine: not yet
    upload = act.Upload("UAV1", None, None, 12, "loiter inserted", True)  # type: ignore[arg-type]
    runner._dispatch([upload])
    assert sent[-1] == "FlightRunner._install"
    assert len(kept) == 2, f"no checkpoint within {CHECKPOINT_WALL_S} s of the last"
    assert pickle.loads(kept[-1])["team"] == {"stands for": "the team"}
