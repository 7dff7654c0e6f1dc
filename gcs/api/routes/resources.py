"""Vehicles, scenarios, schedules (planning jobs) and jobs."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter, Depends, Request, Response

from gcs.api.auth import require
from gcs.api.routes.common import ERRORS, engine_of
from gcs.api.schemas import ScheduleIn, VehicleIn
from gcs.service.engine import InvalidInput
from planner.scenario import json_schema

router = APIRouter(responses=ERRORS)
observe = [Depends(require("observe"))]

_SCENARIO_BODY = {
    "requestBody": {
        "required": True,
        "description": "a scenario (docs/scenario.md) as YAML or JSON",
        "content": {
            "application/json": {"schema": {"type": "object"}},
            "application/yaml": {"schema": {"type": "string"}},
        },
    }
}
_JSON_SCHEMA = json_schema()


@router.post(
    "/vehicles", status_code=201, dependencies=[Depends(require("operate"))], tags=["vehicles"]
)
async def add_vehicle(body: VehicleIn, request: Request) -> dict[str, Any]:
    """Register a live vehicle by connection string (its link is opened and its HEARTBEAT
    awaited), kept across restarts under its id; the signing key is kept for the link only
    (a vehicle registered with one is registered again with it after a restart:
    ``signing_key_needed``). A connection registered already answers with its id."""
    return await engine_of(request).add_vehicle(
        body.connection, system_id=body.system_id, signing_key=body.signing_key
    )


@router.get("/vehicles", dependencies=observe, tags=["vehicles"])
async def vehicles(request: Request) -> list[dict[str, Any]]:
    """Every vehicle registered (and a rehearsal's simulator vehicles while it runs), with its
    live status from telemetry; one whose link is not open shows ``link.open`` false."""
    return engine_of(request).vehicle_views()


@router.get("/vehicles/{vehicle_id}", dependencies=observe, tags=["vehicles"])
async def vehicle(vehicle_id: str, request: Request) -> dict[str, Any]:
    return engine_of(request).vehicle_view(vehicle_id)


@router.post(
    "/scenarios",
    status_code=201,
    dependencies=[Depends(require("plan"))],
    openapi_extra=_SCENARIO_BODY,
    tags=["scenarios"],
)
async def add_scenario(request: Request) -> dict[str, Any]:
    """Keep a scenario (immutable, named by the SHA-256 of its text); 422 names the field."""
    raw = await request.body()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise InvalidInput("scenario: not UTF-8 text") from None
    media = request.headers.get("content-type", "application/yaml").split(";")[0].strip()
    kind = "application/json" if "json" in media else "application/yaml"
    return await engine_of(request).planning.add_scenario(text, kind)


@router.get("/scenarios/schema", dependencies=observe, tags=["scenarios"])
async def scenario_schema() -> dict[str, Any]:
    """The JSON Schema of scenarios."""
    return _JSON_SCHEMA


@router.get("/scenarios/{scenario_id}", dependencies=observe, tags=["scenarios"])
async def scenario(scenario_id: str, request: Request) -> dict[str, Any]:
    return await engine_of(request).planning.scenario_view(scenario_id)


@router.get(
    "/scenarios/{scenario_id}/terrain.png",
    dependencies=observe,
    tags=["scenarios"],
    response_class=Response,
    responses={200: {"content": {"image/png": {}}}},
)
async def terrain(scenario_id: str, request: Request) -> Response:
    """A hillshade of the scenario's terrain over its area, north up (the map's base layer)."""
    png = await engine_of(request).planning.terrain_png(scenario_id)
    return Response(png, media_type="image/png", headers={"Cache-Control": "max-age=3600"})


@router.post(
    "/schedules", status_code=202, dependencies=[Depends(require("plan"))], tags=["schedules"]
)
async def schedule(body: ScheduleIn, request: Request, response: Response) -> dict[str, Any]:
    """Plan and schedule as a job (poll ``/v1/jobs/{id}``); an infeasible time fails the job
    with status 409, the earliest feasible time and the vehicle that forces it."""
    job = await engine_of(request).planning.submit_schedule(
        body.scenario_id,
        required_arrival_s=body.required_arrival_s,
        seed=body.seed,
        dry_run=body.dry_run,
        owner=getattr(request.state, "token_id", None),
    )
    response.headers["Location"] = f"/v1/jobs/{job.id}"
    return job.view()


@router.get("/jobs/{job_id}", dependencies=observe, tags=["schedules"])
async def job(job_id: str, request: Request) -> dict[str, Any]:
    """A job's state, progress (0 to 1, with the stage it is at) and, once it has ended, its
    result or error."""
    return engine_of(request).planning.job(job_id).view()


@router.delete("/jobs/{job_id}", dependencies=[Depends(require("plan"))], tags=["schedules"])
async def cancel_job(job_id: str, request: Request) -> dict[str, Any]:
    """Cancel a queued or running job: its process is killed, and its memory given back,
    before the answer (state ``cancelled``). An ended job is answered as it ended."""
    return (await engine_of(request).planning.cancel_job(job_id)).view()


@router.get("/schedules/{schedule_id}", dependencies=observe, tags=["schedules"])
async def schedule_view(schedule_id: str, request: Request) -> dict[str, Any]:
    return (await engine_of(request).planning.planned(schedule_id)).view()


@router.get(
    "/schedules/{schedule_id}/missions/{vehicle}.{fmt}",
    dependencies=observe,
    tags=["schedules"],
    response_class=Response,
    responses={
        200: {
            "description": "the .plan (JSON) or the .waypoints (text) file",
            "content": {
                "application/json": {"schema": {"type": "object"}},
                "text/plain": {"schema": {"type": "string"}},
            },
        }
    },
)
async def mission_file(
    schedule_id: str, vehicle: str, fmt: Literal["plan", "waypoints"], request: Request
) -> Response:
    """A vehicle's mission as a QGroundControl ``.plan`` or a ``.waypoints`` (WPL 110) file."""
    text = await engine_of(request).planning.mission_file(schedule_id, vehicle, fmt)
    media = "application/json" if fmt == "plan" else "text/plain"
    return Response(text, media_type=media)
