"""The service end to end over HTTP only: ``python -m gcs serve`` in its own process on
loopback, this test its client (httpx, server-sent events). The verdicts are the oracle's
(:mod:`tests.oracle` through :func:`tests.verdict.assert_flown`): the truth log the service's
simulator wrote for the flight (``flights/<id>/truth.jsonl`` in its data directory) against
the slots the schedule set before launch, 3-D separation over the whole flight and the
forbidden zones (the operator's included); nothing is taken from the coordinator's own
figures but which simulated vehicle each id is and how far the team time moved, which each
test bounds."""

from __future__ import annotations

import asyncio
import math
from collections import Counter
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
import yaml

from gcs.api.demo import sse_messages
from gcs.rehearsal.figures import FIGURES
from tests import oracle
from tests.flightstory import story
from tests.gcs.conftest import PAPER
from tests.paperbounds import paper_schedule, team_time_move_max_s
from tests.service.conftest import Service
from tests.teams import compact_paper
from tests.verdict import assert_flown

pytestmark = pytest.mark.slow  # 10-20 s of wall time each

ARRIVAL_TOLERANCE_S = 1.0
"""A goal passage (the truth's) this close to its slot is on time: the coordinator aims within
0.5 s (``FlightConfig.tolerance_s``); the rest is what its last speed step cannot trim in the
final seconds."""
COMPACT_TOGETHER_MIN_S = 600.0
"""Every pair is airborne together at least this long in the compact paper flight
(:func:`tests.teams.compact_paper`): UAV1, the last up, takes off at some 258 s and the three
arrive together at 1,260 s or later, so every pair flies together some 1,000 s; the
separation is judged over it."""


def truth_log(service: Service, fid: str) -> Path:
    """The truth log the service's bundled simulator wrote for flight ``fid`` (its data
    directory's ``flights/<id>/truth.jsonl``, docs/service.md); whole once the record is
    there (the service stops the simulator before it writes the record)."""
    path = service.data_dir / "flights" / fid / "truth.jsonl"
    assert path.exists(), f"no truth log at {path}"
    return path


def _ok(r: httpx.Response, status: int = 200) -> Any:
    assert r.status_code == status, (r.request.method, r.request.url, r.status_code, r.text)
    return r.json() if r.content else None


async def _flight(
    client: httpx.AsyncClient,
    rehearsal: dict[str, Any],
    seed: int = 1,
    scenario_name: str = "paper",
) -> tuple[str, dict[str, Any]]:
    """Scenario (the paper's, or ``scenario_name`` "compact": :func:`tests.teams.compact_paper`),
    schedule (a job), flight on simulator vehicles, upload: ready to launch."""
    if scenario_name == "compact":
        body = yaml.safe_dump(compact_paper(), sort_keys=False)
    else:
        body = PAPER.read_text(encoding="utf-8")
    job = await _scheduled(client, body, seed)
    flight = _ok(
        await client.post(
            "/v1/flights", json={"schedule_id": job["result"]["id"], "rehearsal": rehearsal}
        ),
        201,
    )
    fid = flight["flight_id"]
    _ok(await client.post(f"/v1/flights/{fid}/upload"), 202)
    snap = flight
    while snap["state"] in ("planned", "uploading"):
        await asyncio.sleep(0.1)
        snap = _ok(await client.get(f"/v1/flights/{fid}"))
    assert snap["state"] == "ready", snap
    assert {v: u["state"] for v, u in snap["uploads"].items()} == dict.fromkeys(
        ("UAV1", "UAV2", "UAV3"), "ok"
    )
    return fid, job["result"]


async def _scheduled(client: httpx.AsyncClient, text: str, seed: int = 1) -> dict[str, Any]:
    """A scenario (YAML text) kept and scheduled: the job, succeeded."""
    sc = _ok(
        await client.post(
            "/v1/scenarios", content=text, headers={"Content-Type": "application/yaml"}
        ),
        201,
    )
    job = _ok(await client.post("/v1/schedules", json={"scenario_id": sc["id"], "seed": seed}), 202)
    while job["state"] in ("queued", "running"):
        await asyncio.sleep(0.1)
        job = _ok(await client.get(f"/v1/jobs/{job['id']}"))
    assert job["state"] == "succeeded", job
    return dict(job)


async def _until(client: httpx.AsyncClient, fid: str, t_s: float) -> dict[str, Any]:
    """Poll the snapshot until mission time ``t_s``."""
    while True:
        snap = _ok(await client.get(f"/v1/flights/{fid}"))
        if snap["t_s"] >= t_s or snap["state"] in ("completed", "failed", "aborted"):
            return snap
        await asyncio.sleep(0.05)


async def _paused(client: httpx.AsyncClient, fid: str, at_s: float) -> dict[str, Any]:
    """Poll the snapshot until the rehearsal waits at its pause at mission time ``at_s``
    (there or within a few seconds of flight past it: its simulator's lead)."""
    while not (snap := _ok(await client.get(f"/v1/flights/{fid}")))["pause"]["paused"]:
        assert snap["state"] not in ("completed", "failed", "aborted"), snap["state"]
        await asyncio.sleep(0.05)
    assert at_s <= snap["t_s"] <= at_s + 3.0, (at_s, snap["t_s"])
    return snap


async def _follow(client: httpx.AsyncClient, fid: str, after_seq: int = 0) -> list[int]:
    """Every event's seq from the stream until it ends."""
    seqs: list[int] = []
    async for kind, data in sse_messages(
        client, f"/v1/flights/{fid}/stream", {"after_seq": after_seq}
    ):
        if kind == "event":
            seqs.append(data["seq"])
        elif kind == "end":
            return seqs
        elif kind == "behind":
            raise AssertionError("stream fell behind")
    raise AssertionError("stream closed before the end")


async def _interrupted(client: httpx.AsyncClient, fid: str) -> list[int]:
    """Read 20 events, go away for 10 s, come back with ``after_seq``."""
    seqs: list[int] = []
    async for kind, data in sse_messages(client, f"/v1/flights/{fid}/stream"):
        if kind == "event":
            seqs.append(data["seq"])
            if len(seqs) >= 20:
                break
    await asyncio.sleep(10.0)
    return seqs + await _follow(client, fid, seqs[-1])


async def _all_events(client: httpx.AsyncClient, fid: str) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    after = 0
    while True:
        page = _ok(await client.get(f"/v1/flights/{fid}/events", params={"after_seq": after}))
        out += page["events"]
        if not page["events"]:
            return out
        after = page["next_after_seq"]


async def _taken_on(client: httpx.AsyncClient, fid: str, pid: int) -> dict[str, Any]:
    """The flight's snapshot once a worker other than ``pid`` has it; a flight that ended
    instead (no worker could take it on) fails the test at once, with its events."""
    while (snap := _ok(await client.get(f"/v1/flights/{fid}")))["worker"]["pid"] == pid:
        if snap["state"] in ("completed", "failed", "aborted"):
            raise AssertionError(
                f"no worker took the flight on after pid {pid}: {snap['state']}\n"
                + story(await _all_events(client, fid))
            )
        await asyncio.sleep(0.05)
    return snap


UAV3_BOXES = {"paper": (0.75, 1_500.0, 8_000.0), "compact": (0.8, 375.0, 2_000.0)}
"""Per scenario: how far along UAV3's planned route the no-fly square lies (fraction), its
half side (m) and how close (m) the other routes may come to its centre. Full size: 3 km
across, 75 % along (just past B3, 5.5 km from its centre) and 8 km from the others. Compact
(0.25 scale): a quarter of each distance, 750 m across and 2 km from the others, but 80 %
along: 75 % lies in B3 (600 m from its centre, radius 1.25 km), where UAV3 is to hold, while
80 % is just past it (1.5 km from the centre) as 75 % is at full size."""


def _uav3_box(scenario_name: str = "paper") -> list[tuple[float, float]]:
    """A no-fly square on UAV3's planned route (:data:`UAV3_BOXES`: 3 km across 75 % along
    it at full size, at least 8 km from the other two routes), from the test's own plan of
    the scenario (``scenario_name`` "paper" or "compact") and seed."""
    along, h, clear_m = UAV3_BOXES[scenario_name]
    _, schedule = paper_schedule(1, scenario_name)
    vs = schedule.vehicle("UAV3")
    assert vs is not None
    p = vs.path.pose_at(along * vs.path.length_m)
    for other in ("UAV1", "UAV2"):
        o = schedule.vehicle(other)
        assert o is not None
        d = min(
            math.hypot(q.east_m - p.east_m, q.north_m - p.north_m)
            for q in (o.path.pose_at(float(s)) for s in np.linspace(0, o.path.length_m, 400))
        )
        assert d > clear_m, (other, d)
    e, n = p.east_m, p.north_m
    return [(e - h, n - h), (e + h, n - h), (e + h, n + h), (e - h, n + h)]


def _inside(e: float, n: float, box: list[tuple[float, float]]) -> bool:
    return box[0][0] <= e <= box[1][0] and box[0][1] <= n <= box[2][1]


OP1_AT_S = 700.0
"""When (mission s) OP1 appears across UAV3's route in the compact paper flight: after the
scenario's pop-up (300 s after UAV1's takeoff, some 560-620 s), with UAV3 some 6 km short of
the square."""
OP1_DRAWN_S = 300.0
"""When (mission s) the operator draws OP1, to appear at :data:`OP1_AT_S`: the rehearsal
pauses there (at 200x a wall second is 200 s of flight, and a busy machine takes that long to
answer a request: what the flight does then must not depend on it)."""
TEAM_TIME_AT_S = 800.0
"""When (mission s, paused there) the operator moves the team time 120 s later: once OP1's
re-plan is on board, some 500 s before the team time."""


async def test_paper_flight_over_http_with_a_no_fly_zone_a_later_team_time_and_fifty_streams(
    service: Service,
) -> None:
    """The compact paper flight (:func:`tests.teams.compact_paper`) in a 5 m/s wind with 10 %
    loss, followed by fifty event streams and one that goes away for 10 s: the operator draws a
    no-fly square across UAV3's route, then moves the team time 120 s later, with the
    version it read (a stale one is refused)."""
    box = _uav3_box("compact")
    async with service.client() as client:
        fid, _ = await _flight(
            client,
            {"speedup": 200.0, "wind_m_s": 5.0, "wind_from_deg": 270.0, "loss": 0.1, "seed": 1},
            scenario_name="compact",
        )
        streams = [asyncio.create_task(_follow(client, fid)) for _ in range(50)]
        resumed = asyncio.create_task(_interrupted(client, fid))
        for at_s in (TEAM_TIME_AT_S, OP1_DRAWN_S):
            _ok(await client.post(f"/v1/flights/{fid}/pause", json={"at_s": at_s}))
        _ok(await client.post(f"/v1/flights/{fid}/launch", json={}), 202)
        await _paused(client, fid, OP1_DRAWN_S)
        threat = {
            "kind": "no_fly",
            "id": "OP1",
            "polygon": [{"east_m": e, "north_m": n} for e, n in box],
        }
        drawn = {"threat": threat, "at_s": OP1_AT_S}
        _ok(await client.post(f"/v1/flights/{fid}/threats", json=drawn), 201)
        resumed_at = _ok(await client.post(f"/v1/flights/{fid}/resume"))
        assert resumed_at == {"pausable": True, "paused": False, "at_s": [TEAM_TIME_AT_S]}
        await _paused(client, fid, TEAM_TIME_AT_S)
        tt = await client.get(f"/v1/flights/{fid}/team-time")
        version = tt.headers["ETag"]
        ref = _ok(tt)["team_time_s"]
        stale = await client.put(
            f"/v1/flights/{fid}/team-time",
            json={"arrival_s": ref + 120.0},
            headers={"If-Match": '"0"'},
        )
        assert stale.status_code == 412, stale.text
        asked = await client.put(
            f"/v1/flights/{fid}/team-time",
            json={"arrival_s": ref + 120.0},
            headers={"If-Match": version},
        )
        wanted_s = ref + 120.0
        if asked.status_code == 409:
            # A vehicle cannot wait that long (where the flight is at 800 s moves within the
            # lock step's lead with the machine's load; from some places no loiter turns fit
            # clear of the others): the refusal names it and the latest time it can make,
            # and the operator takes that instead.
            refused = asked.json()
            assert refused["vehicle"] and ref < refused["latest_feasible_s"] < wanted_s, refused
            wanted_s = refused["latest_feasible_s"]
            asked = await client.put(
                f"/v1/flights/{fid}/team-time",
                json={"arrival_s": wanted_s},
                headers={"If-Match": version},
            )
        moved = _ok(asked)
        assert moved["team_time_s"] == pytest.approx(wanted_s)
        _ok(await client.post(f"/v1/flights/{fid}/resume"))
        got = await asyncio.gather(*streams)
        interrupted = await resumed
        record = _ok(await client.get(f"/v1/flights/{fid}/record"))
        events = await _all_events(client, fid)
        assert service.spare_workers() == []  # TCGCS_SPARE_WORKER=false: none kept loaded

    # The team time: the wind and the pop-up moved it later by no more than they can
    # (tests.paperbounds), the operator by 120 s (or as late as it could), and nothing after
    # that (the vehicles met the operator's time).
    move_max_s = team_time_move_max_s(5.0, 270.0, "compact")
    planned_s = record["planned_arrival_s"]
    assert -1e-3 <= ref - planned_s <= move_max_s, (planned_s, ref, move_max_s, story(events))
    assert record["required_arrival_s"] == pytest.approx(wanted_s, abs=1e-3), (
        ref, wanted_s, record["required_arrival_s"], story(events),
    )  # fmt: skip
    # Arrivals, separation and zones from the truth log; OP1 forbidden from when it appeared.
    # (It appears at the flight's first tick from then: within a few seconds of flight.)
    appeared = {t["id"]: t["utc_s"] for t in record["threats_appeared"]}
    assert OP1_AT_S <= appeared["OP1"] - record["start_utc_s"] <= OP1_AT_S + 10.0, appeared
    op1 = oracle.Zone.of(threat, record["start_utc_s"] + OP1_AT_S)
    assert_flown(
        record,
        truth_log(service, fid),
        tolerance_s=ARRIVAL_TOLERANCE_S,
        team_shift_max_s=move_max_s + 120.0,
        together_min_s=COMPACT_TOGETHER_MIN_S,
        extra_zones=[op1],
    )
    assert {a["strategy"] for a in record["adjustments"]} >= {"takeoff_delay", "speed", "loiter"}
    # The no-fly zone: only UAV3's route was planned again.
    replanned = {
        v["id"]
        for v in record["vehicles"]
        if any(p["label"] == "after OP1" for p in v["planned_paths"])
    }
    assert replanned == {"UAV3"}
    # Every stream client, and the one that went away for 10 s, got every event once, in order.
    seqs = [e["seq"] for e in events]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
    for s in got:
        assert s == seqs
    assert interrupted == seqs
    assert Counter(e["kind"] for e in events)["arrived"] == 3


ABORT_S = 450.0
"""When (mission s) the operator aborts UAV1 in the compact paper flight: some 190 s after its
takeoff, 4 km from home."""
ABORT_SAID_WITHIN_S = 5.0
"""Flight seconds from the flight taking an abort to its saying the vehicle took RTL."""


async def test_an_aborted_vehicle_goes_home_over_http_and_the_others_arrive_on_time(
    service: Service,
) -> None:
    async with service.client() as client:
        fid, _ = await _flight(client, {"speedup": 200.0, "seed": 2}, scenario_name="compact")
        _ok(await client.post(f"/v1/flights/{fid}/launch", json={}), 202)
        await _until(client, fid, ABORT_S)
        out = _ok(
            await client.post(f"/v1/flights/{fid}/abort", json={"vehicle": "UAV1", "mode": "rtl"})
        )
        assert out["vehicles"] == {"UAV1": None}
        snap = _ok(await client.get(f"/v1/flights/{fid}"))
        uav1 = next(v for v in snap["vehicles"] if v["id"] == "UAV1")
        assert uav1["state"] == "aborted"
        # The mode shown is the vehicle's heartbeat's (1 Hz of flight): RTL within a few
        # seconds of flight of the accepted command, however busy the machine.
        asked_s = snap["t_s"]
        while uav1["link"]["mode"] != "RTL":
            assert snap["t_s"] <= asked_s + 5.0, (snap["t_s"], uav1["link"])
            await asyncio.sleep(0.02)
            snap = _ok(await client.get(f"/v1/flights/{fid}"))
            uav1 = next(v for v in snap["vehicles"] if v["id"] == "UAV1")
        again = await client.post(f"/v1/flights/{fid}/abort", json={"vehicle": "UAV9"})
        assert again.status_code == 404 and "UAV9" in again.json()["detail"]
        while _ok(await client.get(f"/v1/flights/{fid}"))["state"] not in ("completed", "failed"):
            await asyncio.sleep(0.2)
        while (r := await client.get(f"/v1/flights/{fid}/record")).status_code == 404:
            await asyncio.sleep(0.2)
        record = _ok(r)
        events = await _all_events(client, fid)
        # The report: its pages left by the worker, each figure drawn when first asked for.
        folder = service.data_dir / "flights" / fid / "report"
        assert sorted(p.name for p in folder.iterdir()) == ["arrivals.md", "index.html"]
        index = (await client.get(f"/v1/flights/{fid}/report/index.html")).text
        drawn = await asyncio.gather(
            *(client.get(f"/v1/flights/{fid}/report/{n}") for n in FIGURES for _ in range(2))
        )
        for n, got in zip([n for n in FIGURES for _ in range(2)], drawn, strict=True):
            assert f'src="{n}"' in index
            assert got.status_code == 200 and got.content.startswith(b"\x89PNG"), (n, got)
            assert got.content == (folder / n).read_bytes()
        assert sorted(p.name for p in folder.iterdir()) == sorted(
            ["arrivals.md", "index.html", *FIGURES]
        )
        for bad in ("nope.png", ".part.paths.png", "..%2Fflight.json"):
            assert (await client.get(f"/v1/flights/{fid}/report/{bad}")).status_code == 404
    by_id = {v["id"]: v for v in record["vehicles"]}
    assert by_id["UAV1"]["state"] == "aborted"
    # The others on their slots, judged from the truth log: the abort leaves the team time
    # alone ("the rest keep their arrival time"), the pop-up may move it later as bounded
    # (tests.paperbounds: still air).
    move_max_s = team_time_move_max_s(scenario_name="compact")
    moved_s = record["required_arrival_s"] - record["planned_arrival_s"]
    assert 0.0 <= moved_s <= move_max_s, (moved_s, move_max_s, story(events))
    verdict = assert_flown(
        record,
        truth_log(service, fid),
        tolerance_s=ARRIVAL_TOLERANCE_S,
        team_shift_max_s=move_max_s,
        together_min_s=120.0,  # UAV1 flies with the others from some 260 s to past its abort
        arriving=("UAV2", "UAV3"),
    )
    # Said once, when RTL was taken: a few command round trips (flight seconds) after the
    # flight took the request (its vehicle's state said aborted), itself after ABORT_S by
    # the request's way through the service in wall time (at 200x a busy machine's 0.4 s of
    # wall time are 80 s of flight).
    aborts = [e for e in events if e["kind"] == "abort"]
    assert [e["vehicle"] for e in aborts] == ["UAV1"], aborts
    (taken,) = [
        e
        for e in events
        if e["kind"] == "state" and e["vehicle"] == "UAV1" and e["payload"]["state"] == "aborted"
    ]
    assert ABORT_S <= taken["t_s"] <= aborts[0]["t_s"] <= taken["t_s"] + ABORT_SAID_WITHIN_S, story(
        events
    )
    assert "RTL" in aborts[0]["reason"], aborts
    # UAV1 (by the truth) never passed its goal, and flew home: from where it was aborted,
    # over its launch point (its first true sample) before the others arrived.
    assert verdict.passages_s["UAV1"] is None, verdict
    uav1 = verdict.tracks["UAV1"]
    east, north = verdict.ground.local(uav1)
    t_abort = record["start_utc_s"] + aborts[0]["t_s"]
    after = uav1.utc_s >= t_abort
    first_arrival = record["start_utc_s"] + min(
        t for v, t in verdict.passages_s.items() if t is not None
    )
    home = (east[0], north[0])
    away = np.hypot(east - home[0], north - home[1])
    assert away[after][0] > 2_500.0, away[after][0]
    back = after & (uav1.utc_s <= first_arrival)
    assert back.any() and away[back].min() < 1_000.0, away[back].min() if back.any() else None
