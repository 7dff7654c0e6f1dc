"""What the service's job processes run (:mod:`gcs.service.processjobs`): parsing a scenario
and planning a schedule. Each returns its outcome as a tagged tuple rather than raising, so
that what the API tells apart (an infeasible time, a field that does not validate) crosses the
process boundary whole."""

from __future__ import annotations

import pickle
from collections.abc import Mapping
from typing import Any

import numpy as np

from gcs.service.processjobs import Progress
from gcs.service.scenariotext import InvalidInput, parse_scenario_text
from planner.backend import RayBackend
from planner.errors import InfeasibleError, PlannerError
from planner.plan import Method, World, build_world, plan
from planner.retime import build_schedule, check_feasible
from planner.scenario import Scenario
from planner.schedule import Schedule

__all__ = [
    "PRELOAD",
    "Parsed",
    "Planned",
    "keep_schedule",
    "kept_schedule",
    "parse",
    "plan_schedule",
]

PRELOAD = ("gcs.service.planjobs", "scipy.sparse.csgraph")
"""Imported once by the job processes' fork server (every job starts with them loaded)."""

Planned = tuple[str, bytes] | tuple[str, str, float | None, str | None] | tuple[str, str]
"""``("ok", kept)`` (:func:`keep_schedule`'s bytes), ``("infeasible", message, earliest_s,
vehicle)``, ``("invalid", message)`` or ``("unavailable", message)`` (the Ray it was to plan
on could not be reached)."""
SCHEDULE_FORMAT = "tcgcs-schedule/1"
Parsed = tuple[str, Scenario] | tuple[str, str, list[Mapping[str, Any]]]
"""``("ok", scenario)`` or ``("invalid", message, errors)``."""


def parse(progress: Progress, body: str, media_type: str) -> Parsed:
    """A scenario from its text (:func:`~gcs.service.scenariotext.parse_scenario_text`)."""
    progress(0.0, "parsing")
    try:
        return "ok", parse_scenario_text(body, media_type)
    except InvalidInput as err:
        return "invalid", str(err), err.errors
    except RecursionError:
        return "invalid", "scenario: nested too deeply to read", []


def plan_schedule(
    progress: Progress, scenario: Scenario, seed: int, method: Method, ray: str | None = None
) -> Planned:
    """Plan and schedule; an infeasible request names the earliest time and the vehicle.

    ``ray``: where the vehicles' routes are finished (:mod:`planner.backend`): None, here (and
    in forked processes for a large team); ``"local"``, a Ray started here for the job (its
    processes are the job's, killed with it); else the address of a Ray cluster to join."""
    progress(0.05, "building the world")
    world = build_world(scenario)
    backend: RayBackend | None = None
    if ray is not None:
        progress(0.1, "starting Ray" if ray == "local" else f"joining Ray at {ray}")
        try:
            backend = RayBackend(None if ray == "local" else ray)
        except Exception as err:
            return "unavailable", f"planning on Ray ({ray}): not reached ({err})"
    try:
        progress(0.2, "planning routes" if backend is None else "planning routes on Ray")
        p = plan(
            scenario,
            method=method,
            rng=np.random.default_rng(seed),
            world=world,
            backend=backend,
        )
        progress(0.8, "timing")
        schedule = build_schedule(scenario, p, world=world)
        progress(0.95, "checking feasibility")
        check_feasible(schedule)
    except InfeasibleError as err:
        return "infeasible", f"infeasible: {err}", err.earliest_s, err.vehicle
    except (PlannerError, ValueError) as err:
        return "invalid", str(err)
    finally:
        if backend is not None:
            backend.close()
    progress(0.99, "keeping")
    return "ok", keep_schedule(scenario, schedule, world)


def keep_schedule(scenario: Scenario, schedule: Schedule, world: World) -> bytes:
    """A planned schedule as the store keeps it (pickled, as a flight's checkpoint is): the
    scenario it was planned for (with its team time), the schedule and the world."""
    doc = {"format": SCHEDULE_FORMAT, "scenario": scenario, "schedule": schedule, "world": world}
    return pickle.dumps(doc, protocol=pickle.HIGHEST_PROTOCOL)


def kept_schedule(blob: bytes) -> tuple[Scenario, Schedule, World]:
    """:func:`keep_schedule` read back."""
    doc = pickle.loads(blob)
    if doc.get("format") != SCHEDULE_FORMAT:
        raise ValueError(f"a kept schedule of format {doc.get('format')!r}")
    return doc["scenario"], doc["schedule"], doc["world"]
