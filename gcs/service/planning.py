"""What the service keeps and plans before any flight: scenarios, planning jobs and the
schedules they plan, owned by :class:`Planning`.

A scenario is parsed in a job process (a large body never holds the event loop), checked
against the service's limits (:class:`Limits`) and kept in the store. A schedule is planned
as a :class:`Job` in a process of its own (queued past ``jobs_running``, limited per token,
cancelled by killing its process, stopped at its time limit); the planned schedule is kept
in the store, so a restarted service has every one it had.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
import uuid
from dataclasses import dataclass, field
from typing import Any, Literal

from gcs.service import planjobs
from gcs.service.mapview import terrain_png
from gcs.service.processjobs import (
    JOB_NICENESS,
    JobCancelled,
    JobFailed,
    JobTimedOut,
    ProcessJobs,
)
from gcs.service.scenariotext import (
    InvalidInput,
    NotFound,
    ScenarioLimits,
    TooBusy,
    check_limits,
    confine_terrain,
)
from gcs.store.repository import Store, StoreNotFound
from planner.missionfile import to_qgc_plan, to_wpl
from planner.plan import World
from planner.scenario import Scenario
from planner.schedule import Schedule
from planner.schedulefile import path_mission

__all__ = ["JOB_ENDED", "Job", "JobState", "Limits", "PlannedSchedule", "Planning", "kept_planned"]

log = logging.getLogger(__name__)

JobState = Literal["queued", "running", "succeeded", "failed", "cancelled"]
JOB_ENDED: frozenset[JobState] = frozenset({"succeeded", "failed", "cancelled"})


@dataclass(frozen=True)
class Limits:
    """What one client may ask of the service (settings ``TCGCS_*``)."""

    scenario: ScenarioLimits = field(default_factory=ScenarioLimits)
    jobs_running: int = 2
    """Planning jobs run at once (each in a process of its own); the others queue."""
    jobs_per_owner: int = 8
    """Jobs one token may have queued or running; past it, 429."""
    job_time_limit_s: float = 900.0
    """A job running longer (wall s) is stopped and failed."""
    retry_after_s: int = 10
    """What a 429 tells the client to wait, s."""
    parse_time_limit_s: float = 120.0
    """Reading one scenario's text (at most the body limit) takes no longer, wall s."""
    job_niceness: int = JOB_NICENESS
    """How much lower than this process's the jobs' scheduling priority is (``nice``)."""


@dataclass
class Job:
    """Long work (a schedule): polled until it has succeeded, failed or been cancelled."""

    id: str
    kind: str
    state: JobState = "queued"
    progress: float = 0.0
    stage: str = "queued"
    result: dict[str, Any] | None = None
    error: dict[str, Any] | None = None
    created_utc_s: float = field(default_factory=time.time)
    started_utc_s: float | None = None
    finished_utc_s: float | None = None
    owner: str | None = None
    """Who asked for it (a digest of the token: the quota's key), never shown."""
    task: asyncio.Task[None] | None = None

    def view(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "kind": self.kind,
            "state": self.state,
            "progress": self.progress,
            "stage": self.stage,
            "result": self.result,
            "error": self.error,
            "created_utc_s": self.created_utc_s,
            "started_utc_s": self.started_utc_s,
            "finished_utc_s": self.finished_utc_s,
        }


@dataclass
class PlannedSchedule:
    id: str
    scenario_id: str
    scenario: Scenario
    schedule: Schedule
    world: World
    seed: int
    plan_wall_s: float

    def view(self) -> dict[str, Any]:
        s = self.schedule
        return {
            "id": self.id,
            "scenario_id": self.scenario_id,
            "seed": self.seed,
            "required_arrival_s": s.required_arrival_s,
            "arrival_reason": s.arrival_reason,
            "plan_wall_s": round(self.plan_wall_s, 3),
            "vehicles": [
                {
                    "id": vs.vehicle_id,
                    "takeoff_s": round(vs.takeoff_s, 3),
                    "arrival_s": round(vs.arrival_s, 3),
                    "path_length_m": round(vs.path.length_m, 1),
                    "loiter_turns": sum(lo.turns for lo in vs.loiters),
                }
                for vs in s.vehicles
            ],
        }


class Planning:
    """The service's scenarios, planning jobs and planned schedules."""

    def __init__(self, store: Store, limits: Limits, method: str, ray: str | None = None) -> None:
        """``method``: the planner's route search for every schedule (``aco``, ...); ``ray``:
        where the jobs finish the routes (:func:`~gcs.service.planjobs.plan_schedule`)."""
        self.store = store
        self.limits = limits
        self.method = method
        self.ray = ray
        self.work = ProcessJobs(
            limits.jobs_running, preload=planjobs.PRELOAD, niceness=limits.job_niceness
        )
        self.jobs: dict[str, Job] = {}
        self.schedules: dict[str, PlannedSchedule] = {}
        self._scenarios: dict[str, Scenario] = {}
        """Scenarios parsed since the start, by id (a scenario is immutable)."""
        self._terrain: dict[str, bytes] = {}
        self._tasks: set[asyncio.Task[Any]] = set()

    async def close(self) -> None:
        """Stop: running and queued jobs are cancelled and their processes killed."""
        jobs = [j.task for j in self.jobs.values() if j.task is not None and not j.task.done()]
        for job_task in jobs:
            job_task.cancel()
        if jobs:
            await asyncio.wait(jobs)
        self.work.close()

    def _spawn(self, coro: Any) -> asyncio.Task[Any]:
        task = asyncio.get_running_loop().create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return task

    # -- scenarios ------------------------------------------------------------------------------

    async def add_scenario(self, body: str, media_type: str) -> dict[str, Any]:
        """Keep a scenario once it parses and is within the service's limits (parsed in a
        job process: a large body never holds the event loop)."""
        scenario = await self._parse(body, media_type)
        check_limits(scenario, self.limits.scenario)
        sid = self.store.save_scenario(body, name=scenario.name, media_type=media_type)
        self._scenarios[sid] = scenario
        return self._scenario_view(sid, scenario)

    async def _parse(self, body: str, media_type: str) -> Scenario:
        key = f"parse-{uuid.uuid4().hex}"
        try:
            parsed = await self.work.run(
                key,
                planjobs.parse,
                body,
                media_type,
                time_limit_s=self.limits.parse_time_limit_s,
            )
        except (JobFailed, JobTimedOut, JobCancelled) as err:
            raise InvalidInput(f"scenario: not read ({err})") from None
        if parsed[0] == "invalid":
            raise InvalidInput(parsed[1], parsed[2])
        scenario: Scenario = parsed[1]
        return confine_terrain(scenario, self.limits.scenario.srtm_dir)

    async def scenario(self, scenario_id: str) -> Scenario:
        """A kept scenario (parsed once per process, off the event loop)."""
        found = self._scenarios.get(scenario_id)
        if found is not None:
            return found
        try:
            row = self.store.scenario(scenario_id)
        except StoreNotFound:
            raise NotFound(f"no scenario {scenario_id!r}") from None
        scenario = await self._parse(row.body, row.media_type)
        self._scenarios[scenario_id] = scenario
        return scenario

    async def scenario_view(self, scenario_id: str) -> dict[str, Any]:
        return self._scenario_view(scenario_id, await self.scenario(scenario_id))

    @staticmethod
    def _scenario_view(scenario_id: str, s: Scenario) -> dict[str, Any]:
        return {
            "id": scenario_id,
            "name": s.name,
            "vehicles": [v.id for v in s.vehicles],
            "arrival": s.arrival.model_dump(mode="json"),
            "threats": [t.id for t in s.threats],
        }

    # -- schedules (jobs) -----------------------------------------------------------------------

    async def submit_schedule(
        self,
        scenario_id: str,
        *,
        required_arrival_s: float | None = None,
        seed: int = 0,
        dry_run: bool = False,
        owner: str | None = None,
    ) -> Job:
        """Queue a schedule job (planned in a process of its own).

        Raises
        ------
        TooBusy
            ``owner`` has as many jobs queued or running as its quota allows.
        """
        mine = [j for j in self.jobs.values() if j.owner == owner and j.state not in JOB_ENDED]
        if owner is not None and len(mine) >= self.limits.jobs_per_owner:
            raise TooBusy(
                f"this token has {len(mine)} jobs queued or running, its quota: wait for one "
                "to end, or cancel one (DELETE /v1/jobs/{id})",
                self.limits.retry_after_s,
            )
        scenario = await self.scenario(scenario_id)
        check_limits(scenario, self.limits.scenario)
        if required_arrival_s is not None:
            scenario = _with_arrival(scenario, required_arrival_s)
        job = Job(uuid.uuid4().hex, "dry_run" if dry_run else "schedule", owner=owner)
        self.jobs[job.id] = job
        job.task = self._spawn(self._run_schedule(job, scenario_id, scenario, seed, dry_run))
        return job

    async def _run_schedule(
        self, job: Job, scenario_id: str, scenario: Scenario, seed: int, dry_run: bool
    ) -> None:
        def started() -> None:
            job.state, job.stage = "running", "starting"
            job.started_utc_s = time.time()

        def progress(fraction: float, stage: str) -> None:
            job.progress, job.stage = round(fraction, 3), stage

        t0 = time.perf_counter()
        try:
            planned = await self.work.run(
                job.id,
                planjobs.plan_schedule,
                scenario,
                seed,
                self.method,
                self.ray,
                time_limit_s=self.limits.job_time_limit_s,
                on_start=started,
                on_progress=progress,
            )
        except (JobCancelled, asyncio.CancelledError):
            job.state, job.stage = "cancelled", "cancelled"
            job.error = {"status": 409, "detail": "cancelled"}
        except JobTimedOut as err:
            job.state, job.error = "failed", {"status": 422, "detail": f"stopped: {err}"}
        except JobFailed as err:
            log.error("schedule job %s failed: %s", job.id, err)
            job.state, job.error = "failed", {"status": 500, "detail": str(err)}
        else:
            if planned[0] == "infeasible":
                job.state = "failed"
                job.error = {
                    "status": 409,
                    "detail": planned[1],
                    "earliest_feasible_s": planned[2],
                    "vehicle": planned[3],
                }
            elif planned[0] == "invalid":
                job.state, job.error = "failed", {"status": 422, "detail": planned[1]}
            elif planned[0] == "unavailable":
                log.error("schedule job %s: %s", job.id, planned[1])
                job.state, job.error = "failed", {"status": 503, "detail": planned[1]}
            else:
                blob = planned[1]
                assert isinstance(blob, bytes)
                kept, schedule, world = await asyncio.to_thread(planjobs.kept_schedule, blob)
                entry = PlannedSchedule(
                    uuid.uuid4().hex,
                    scenario_id,
                    kept,
                    schedule,
                    world,
                    seed,
                    time.perf_counter() - t0,
                )
                if not dry_run:
                    await asyncio.to_thread(
                        self.store.save_schedule,
                        entry.id,
                        scenario_id,
                        seed=seed,
                        plan_wall_s=entry.plan_wall_s,
                        view=entry.view(),
                        blob=blob,
                    )
                    self.schedules[entry.id] = entry
                job.result = entry.view() if not dry_run else {**entry.view(), "id": None}
                job.progress, job.stage, job.state = 1.0, "done", "succeeded"
        finally:
            job.finished_utc_s = time.time()
            if job.state not in JOB_ENDED:  # the service stopping under it
                job.state, job.error = "cancelled", {"status": 409, "detail": "cancelled"}

    def job(self, job_id: str) -> Job:
        job = self.jobs.get(job_id)
        if job is None:
            raise NotFound(f"no job {job_id!r}")
        return job

    async def cancel_job(self, job_id: str) -> Job:
        """Cancel a queued or running job: its process is killed (its memory given back)
        before this returns. An ended job is left as it ended."""
        job = self.job(job_id)
        if job.state in JOB_ENDED:
            return job
        self.work.cancel(job.id)
        if job.task is not None:
            job.task.cancel()  # a queued one stops waiting for its turn
            await asyncio.wait([job.task])
        return job

    async def planned(self, schedule_id: str) -> PlannedSchedule:
        """A planned schedule: from the store once per process (kept when it was planned, so
        a restarted service has every one it had)."""
        entry = self.schedules.get(schedule_id)
        if entry is not None:
            return entry
        entry = await asyncio.to_thread(kept_planned, self.store, schedule_id)
        self.schedules[entry.id] = entry
        return entry

    async def mission_file(self, schedule_id: str, vehicle: str, fmt: str) -> str:
        entry = await self.planned(schedule_id)
        if vehicle not in {v.vehicle_id for v in entry.schedule.vehicles}:
            raise NotFound(f"no vehicle {vehicle!r} in schedule {schedule_id}")
        vs = entry.schedule.vehicle(vehicle)
        items = list(path_mission(entry.schedule, vs, entry.world.terrain).items)
        if fmt == "plan":
            return json.dumps(to_qgc_plan(items), indent=1) + "\n"
        return to_wpl(items)

    async def terrain_png(self, scenario_id: str) -> bytes:
        png = self._terrain.get(scenario_id)
        if png is None:
            scenario = await self.scenario(scenario_id)
            png = await asyncio.to_thread(terrain_png, scenario)
            self._terrain[scenario_id] = png
        return png


def _with_arrival(scenario: Scenario, required_arrival_s: float) -> Scenario:
    out = scenario.with_team_arrival_s(required_arrival_s)
    if out is None:
        raise InvalidInput(
            "required_arrival_s: needs a team arrival kind (simultaneous, spaced, waves)"
        )
    return out


def kept_planned(store: Store, schedule_id: str) -> PlannedSchedule:
    """A planned schedule as the store keeps it (read and unpickled: seconds for a large team).

    Raises
    ------
    NotFound
        No such schedule.
    """
    try:
        row, blob = store.schedule(schedule_id)
    except StoreNotFound:
        raise NotFound(f"no schedule {schedule_id!r}") from None
    scenario, schedule, world = planjobs.kept_schedule(blob)
    return PlannedSchedule(
        row.id, row.scenario_id, scenario, schedule, world, row.seed, row.plan_wall_s
    )
