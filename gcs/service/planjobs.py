"""What the service's job processes run (:mod:`gcs.service.processjobs`): parsing a scenario
and planning a schedule. Each returns its outcome as a tagged tuple rather than raising, so
that what the API tells apart (an infeasible time, a field that does not validate) crosses the
process boundary whole."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from gcs.service.processjobs import Progress
from gcs.service.scenariotext import InvalidInput, parse_scenario_text
from planner.errors import InfeasibleError, PlannerError
from planner.plan import Method, World, build_world, plan
from planner.retime import build_schedule, check_feasible
from planner.scenario import Scenario
from planner.schedule import Schedule

__all__ = ["PRELOAD", "Parsed", "Planned", "parse", "plan_schedule"]

PRELOAD = ("gcs.service.planjobs",)
"""Imported once by the job processes' fork server (every job starts with them loaded)."""

Planned = tuple[str, Schedule, World] | tuple[str, str, float | None, str | None] | tuple[str, str]
"""``("ok", schedule, world)``, ``("infeasible", message, earliest_s, vehicle)`` or
``("invalid", message)``."""
Parsed = tuple[str, Scenario] | tuple[str, str, list[Mapping[str, Any]]]
"""``("ok", scenario)`` or ``("invalid", message, errors)``."""


def parse(progress: Progress, body: str, media_type: str) -> Parsed:
    """A scenario from its text (:func:`~gcs.service.scenariotext.parse_scenario_text`)."""
    progress(0.0, "parsing")
    try:
        return "ok", parse_scenario_text(body, media_type)
    except InvalidInput as err:
        return "invalid", str(err), err.errors


def plan_schedule(progress: Progress, scenario: Scenario, seed: int, method: Method) -> Planned:
    """Plan and schedule; an infeasible request names the earliest time and the vehicle."""
    progress(0.05, "building the world")
    world = build_world(scenario)
    try:
        progress(0.2, "planning routes")
        p = plan(scenario, method=method, rng=np.random.default_rng(seed), world=world)
        progress(0.8, "timing")
        schedule = build_schedule(scenario, p, world=world)
        progress(0.95, "checking feasibility")
        check_feasible(schedule)
    except InfeasibleError as err:
        return "infeasible", f"infeasible: {err}", err.earliest_s, err.vehicle
    except (PlannerError, ValueError) as err:
        return "invalid", str(err)
    return "ok", schedule, world
