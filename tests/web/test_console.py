"""The operator console end to end: Chromium on ``/ui/`` against ``python -m gcs serve`` with
simulator vehicles at 200x, flying the compact paper team (:func:`tests.teams.compact_paper`:
the paper's three vehicles, threats, pop-up and holding areas at a quarter of the size, some
1,300 s of flight). The page is driven as an operator drives it (the file picker, the
buttons and their confirmations, the mouse on the map) and read through what it draws
(``window.tcgcs``) and what it says (the DOM); the service is checked over HTTP, and the flight
the operator flew is judged by the oracle from the simulator's truth log (arrivals against the
slots set before launch, 3-D separation, the scenario's zones and the one drawn on the map:
:func:`tests.verdict.assert_flown`).

Each of the operator's steps is taken with the rehearsal paused at a set mission time
(``POST /v1/flights/{id}/pause``): at 200x a second of wall time is 200 s of flight, and how
long the page and a busy machine take over a step must not move where the flight is when it
lands."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import pytest
import yaml
from playwright.async_api import WebSocketRoute

from tests import oracle
from tests.paperbounds import team_time_move_max_s
from tests.service.test_flights_http import (
    ARRIVAL_TOLERANCE_S,
    COMPACT_TOGETHER_MIN_S,
    _all_events,
    _flight,
    _ok,
    _paused,
    _uav3_box,
    truth_log,
)
from tests.teams import compact_paper
from tests.verdict import assert_flown
from tests.web.conftest import Console

pytestmark = pytest.mark.slow  # each flies one compact flight: about 13 s and 10 s of wall
# time (35 s and 13 s at full size)

UAVS = ("UAV1", "UAV2", "UAV3")

# The compact flights' mission times (s). The schedule (plan seed 1) has UAV2 take off at 0 s,
# UAV3 at 75 s and UAV1 at 258 s (its window opens at 75 s: it waits to arrive with the
# others); POPUP1 appears 300 s after UAV1's takeoff (1,200 s at full size), at some 558 s;
# the team arrives at 1,260 s as planned, later by what the pop-up, the wind and the
# operator's move cost. At 200x a second of wall time is some 200 s of flight, and the page
# hears the mission time every 0.5 s of wall time (``TELEMETRY_WALL_S``): a wait for a mission
# time ends up to 100 s past it, so the operator's steps are taken at pauses.
FLYING_S = 260.0
"""The map is read twice, 150 s of flight apart, from here: UAV1, the last up, has just taken
off (258 s). The second read and the rows' states come at 410 s, before UAV3 turns into its
holding circle in B3 (some 680 s)."""
READ_APART_S = 150.0
STEER_S = 620.0
"""The operator draws a no-fly zone on UAV3's route here: after the scenario's pop-up (some
558 s) and UAV2's route round it, while UAV3 flies to B3 (13.7 km along its 19 km route, some
680-1,040 s) short of the box (15.3 km along it, _uav3_box). The zone is in force at once; the
flight re-plans round it once resumed."""
TEAM_S = 680.0
"""The operator moves the team time here, UAV3's route round the zone on board, before UAV1
turns its loiter circle (some 720-835 s: a zone re-planned round while it turns there moved
the team time up to 59 s later)."""
TEAM_MOVE_S = 30.0
"""How far the operator moves the team time (120 s at full size, scaled as the flight): every
vehicle has 580 s or more of flight left to lose 30 s in. (Later it may not: the service takes
a move while a vehicle has a waypoint a minute ahead, but one already at its minimum speed
with no room left for whole loiter turns then arrives early; UAV1 passed its goal 3-13 s
early with the move at some 1,020 s.)"""
MID_FLIGHT_S = 1_100.0
"""The mid-flight screenshot: the three on their last legs or loiter turns, POPUP1 and the
zone drawn on the map."""
DROP_S = 20.0
"""The stream is dropped: UAV2 is climbing out (0 s), UAV3's and UAV1's takeoffs (75 s,
258 s) come while it is down (the network is down 2 s of wall time, the page tries again after
0.25, 0.5, 1 and 2 s: some 830 s at 200x, or the pause at :data:`ABORT_S`)."""
ABORT_S = 600.0
"""UAV1 (up since 258 s) is aborted here, the rehearsal paused until the stream is back."""
ABORT_ALL_S = 900.0
"""The rest are aborted here (UAV1 flying home), paused, before the team time (1,260 s or
later)."""


async def _pause_at(c: Console, fid: str, *at_s: float) -> None:
    """The rehearsal is to wait at mission seconds ``at_s``: the steps an operator takes there
    take no flight time, however long the page (or a busy machine) takes over them."""
    async with c.service.client() as client:
        for t_s in at_s:
            _ok(await client.post(f"/v1/flights/{fid}/pause", json={"at_s": t_s}))


async def _paused_at(c: Console, fid: str, at_s: float) -> None:
    """Wait until the rehearsal waits at its pause at ``at_s`` and the page has heard so."""
    async with c.service.client() as client:
        await _paused(client, fid, at_s)
    await c.until_mission(at_s)


async def _resume(c: Console, fid: str) -> None:
    async with c.service.client() as client:
        _ok(await client.post(f"/v1/flights/{fid}/resume"))


def _inside(e: float, n: float, polygon: list[list[float]]) -> bool:
    """Ray casting: is (e, n) inside the polygon?"""
    inside = False
    for (e1, n1), (e2, n2) in zip(polygon, polygon[1:] + polygon[:1], strict=True):
        if (n1 > n) != (n2 > n) and e < e1 + (n - n1) * (e2 - e1) / (n2 - n1):
            inside = not inside
    return inside


async def _positions(c: Console) -> dict[str, tuple[float, float]]:
    """Each vehicle's position the map draws."""
    got = await c.js("tcgcs.map.vehicles.map(v => [v.id, v.east_m, v.north_m])")
    return {vid: (e, n) for vid, e, n in got}


async def _three_moving(c: Console, fid: str) -> None:
    """The map read at two pauses 150 s of flight apart (the flight flies on after)."""
    await _paused_at(c, fid, FLYING_S)
    first = await _positions(c)
    await _resume(c, fid)
    await _paused_at(c, fid, FLYING_S + READ_APART_S)
    second = await _positions(c)
    assert set(first) == set(second) == set(UAVS)
    for vid in UAVS:
        assert math.dist(first[vid], second[vid]) > 500.0, (vid, first[vid], second[vid])
    rows = await c.js("tcgcs.table.text()")
    assert all(rows[v]["state"] in ("on route", "climbing", "link silent") for v in UAVS), rows
    await _resume(c, fid)


async def _draw_no_fly(c: Console, box: list[tuple[float, float]]) -> list[list[float]]:
    """Zoom in on the box with the wheel, click its corners, double-click the last; the
    polygon the page holds for sending."""
    page = c.page
    await page.click('#map-tools [data-tool="no_fly"]')
    ce = sum(p[0] for p in box) / len(box)
    cn = sum(p[1] for p in box) / len(box)
    at = await c.js("([e, n]) => tcgcs.toClient(e, n)", [ce, cn])
    await page.mouse.move(at["x"], at["y"])
    scale0 = await c.js("tcgcs.map.view.scale")
    for _ in range(3):
        await page.mouse.wheel(0, -500)
    await c.until("s => tcgcs.map.view.scale > 8 * s", scale0)
    corners = [await c.js("([e, n]) => tcgcs.toClient(e, n)", list(p)) for p in box]
    for p in corners[:-1]:
        await page.mouse.click(p["x"], p["y"])
    await page.mouse.dblclick(corners[-1]["x"], corners[-1]["y"])
    await page.wait_for_selector("#draw-confirm:not([hidden])")
    pending = await c.js("tcgcs.geometry().pending")
    assert pending["kind"] == "no_fly" and len(pending["polygon"]) == 4, pending
    px_m = 1.5 / await c.js("tcgcs.map.view.scale")
    for (e, n), want in zip(pending["polygon"], box, strict=True):
        assert math.dist((e, n), want) <= px_m, ((e, n), want)
    return [list(p) for p in pending["polygon"]]


async def _move_team_time(c: Console, value: float) -> str:
    """Type a team time, press Move and confirm; the words shown: the note or the error."""
    await c.page.fill("#team-time", f"{value:.3f}")
    await c.page.click("#team-time-move")
    await c.confirm()
    return str(
        await c.until(
            "() => document.getElementById('team-time-error').textContent"
            " || document.getElementById('team-time-note').textContent"
        )
    )


async def test_an_operator_flies_the_paper_scenario_from_the_console(
    console: Console, tmp_path: Path
) -> None:
    c, page = console, console.page
    box = _uav3_box("compact")
    scenario = tmp_path / "compact.yaml"
    scenario.write_text(yaml.safe_dump(compact_paper(), sort_keys=False), encoding="utf-8")
    await c.open("/")  # redirected to /ui/
    await c.login()
    # A flight from the scenario file: the file picker, the rehearsal form, a confirmation.
    await page.click("#new-flight summary")
    await page.set_input_files("#scenario-file", str(scenario))
    for field, value in {
        "#plan-seed": "1",
        "#rh-speedup": "200",
        "#rh-wind": "5",
        "#rh-wind-from": "270",
        "#rh-loss": "0.1",
        "#rh-seed": "1",
    }.items():
        await page.fill(field, value)
    await page.click("#create-flight")
    await c.confirm()
    fid = await c.until("() => tcgcs.state.flightState === 'planned' && tcgcs.state.flightId")
    assert f"flight={fid}" in page.url
    await page.click("#upload")
    await c.confirm()
    # The state comes with the telemetry; the uploads' note with the snapshot it calls for.
    await c.until(
        "() => tcgcs.state.flightState === 'ready' && document.querySelector('#flight-note')"
        ".textContent.includes('UAV1 ok, UAV2 ok, UAV3 ok')"
    )
    # The operator's steps wait for the flight where they are taken (each at a pause).
    await _pause_at(c, fid, FLYING_S, FLYING_S + READ_APART_S, STEER_S, TEAM_S)
    await page.click("#launch")
    await c.confirm()

    # Three vehicles fly: what the map draws moves between two reads.
    await _three_moving(c, fid)

    # A no-fly zone drawn by mouse on UAV3's route at STEER_S, once the page has UAV2's route
    # round the scenario's pop-up on board.
    await _paused_at(c, fid, STEER_S)
    await c.until(
        """() => tcgcs.events.some(e => e.kind === "upload" && e.vehicle === "UAV2"
                                      && e.payload.what === "after POPUP1")"""
    )
    before = await c.js("tcgcs.geometry().routes")
    polygon = await _draw_no_fly(c, box)
    sent_s = await c.mission_s()  # the zone is forbidden from here on (at the latest)
    await page.click("#draw-send")
    await page.wait_for_selector("#draw-confirm", state="hidden")
    assert not await c.text("#draw-error")
    async with c.service.client() as client:
        doc = _ok(await client.get(f"/v1/flights/{fid}/map"))
    op1 = next(t for t in doc["threats"] if t["id"] == "OP1")
    assert op1["kind"] == "no_fly" and op1["in_force"], op1
    assert op1["polygon"] == [[round(e), round(n)] for e, n in polygon]
    await _resume(c, fid)
    route = await c.until(
        """old => {
          const v = tcgcs.state.mapDoc.vehicles.find(v => v.id === "UAV3");
          const r = JSON.stringify(v.route_en_m);
          return v.planned.includes("after OP1") && r !== JSON.stringify(old) && v.route_en_m;
        }""",
        before["UAV3"],
    )
    assert route == (await c.js("tcgcs.geometry().routes"))["UAV3"]
    inside = [p for p in route if _inside(p[0], p[1], op1["polygon"])]
    assert not inside, inside[:3]
    planned = {v["id"]: v["planned"] for v in await c.js("tcgcs.state.mapDoc.vehicles")}
    assert [v for v, labels in planned.items() if "after OP1" in labels] == ["UAV3"]

    # The team time at TEAM_S: +30 s moves every slot (from the time and slots the page has
    # once it has the team-time version the zone's re-plan left); one no vehicle can make is
    # refused in words.
    await _paused_at(c, fid, TEAM_S)
    async with c.service.client() as client:
        version = int(_ok(await client.get(f"/v1/flights/{fid}/team-time"))["version"])
    await c.until("v => tcgcs.state.teamTimeVersion === v", version)
    state: dict[str, Any] = await c.js(
        "({ref: tcgcs.state.teamTimeS, slots: Object.fromEntries("
        "[...tcgcs.state.vehicles.values()].map(v => [v.id, v.slot_s]))})"
    )
    moved = await _move_team_time(c, state["ref"] + TEAM_MOVE_S)
    assert moved.startswith("team arrival moved to"), moved
    want = {v: s + TEAM_MOVE_S for v, s in state["slots"].items()}
    shown = await c.until(
        """want => {
          const rows = tcgcs.table.text();
          return Object.entries(want).every(([v, s]) => rows[v].slot === s.toFixed(1)) && rows;
        }""",
        want,
    )
    assert {v: r["slot"] for v, r in shown.items()} == {v: f"{s:.1f}" for v, s in want.items()}
    async with c.service.client() as client:
        snap = _ok(await client.get(f"/v1/flights/{fid}"))
    assert {v["id"]: v["slot_s"] for v in snap["vehicles"]} == pytest.approx(want, abs=2e-3)
    await page.fill("#team-time", "")
    now = await c.mission_s()
    refused = await _move_team_time(c, now + 100.0)
    assert re.search(
        r"earliest time every vehicle can make is \d+\.\d s \(UAV\d forces it\)\..*HTTP 409",
        refused,
        re.S,
    ), refused
    await _resume(c, fid)

    # Mid-flight, then the arrival.
    await c.until_mission(MID_FLIGHT_S)
    await page.click("#map-fit")
    await c.screenshot("console-mid-flight.png")
    await c.until("() => tcgcs.stream.state === 'ended'", timeout_s=90.0)
    await c.until("() => document.getElementById('countdown').textContent === 'arrived'")
    await c.screenshot("console-arrival.png")
    rows = await c.js("tcgcs.table.text()")
    assert all(rows[v]["state"] == "arrived" for v in UAVS), rows
    for v in UAVS:
        float(rows[v]["error"])  # each row shows its arrival error (judged below, by the truth)

    async with c.service.client() as client:
        events = await _all_events(client, fid)
        while (r := await client.get(f"/v1/flights/{fid}/record")).status_code == 404:
            await page.wait_for_timeout(200)
        record = _ok(r)
    # The team time: the wind and the pop-up moved it later by no more than they can
    # (tests.paperbounds), the operator by 30 s from the console, and nothing after that.
    # (The page holds the team time to the millisecond; at this size the wind, behind the
    # vehicles, and the pop-up, across UAV2's route only, may leave it where it was.)
    move_max_s = team_time_move_max_s(5.0, 270.0, scenario_name="compact")
    moved_s = state["ref"] - record["planned_arrival_s"]
    assert -1e-3 <= moved_s <= move_max_s, (moved_s, move_max_s)
    assert record["required_arrival_s"] == pytest.approx(state["ref"] + TEAM_MOVE_S, abs=1e-3)
    # The flown tracks (the truth's): on the slots, apart, and out of the zones, the one
    # drawn included (forbidden from the mission time read before it was sent).
    drawn = {"kind": "no_fly", "id": "OP1",
             "polygon": [{"east_m": e, "north_m": n} for e, n in polygon]}  # fmt: skip
    assert_flown(
        record,
        truth_log(c.service, fid),
        tolerance_s=ARRIVAL_TOLERANCE_S,
        team_shift_max_s=move_max_s + TEAM_MOVE_S,
        together_min_s=COMPACT_TOGETHER_MIN_S,
        extra_zones=[oracle.Zone.of(drawn, record["start_utc_s"] + sent_s)],
    )
    assert [e["seq"] for e in await c.js("tcgcs.events")] == [e["seq"] for e in events]
    assert await c.js("tcgcs.stream.duplicates") == 0
    assert not c.external(), c.external()


async def test_the_console_resumes_a_dropped_stream_and_sends_vehicles_home(
    console: Console,
) -> None:
    c, page = console, console.page
    async with c.service.client() as client:
        fid, _ = await _flight(client, {"speedup": 200.0, "seed": 2}, scenario_name="compact")
    await _pause_at(c, fid, ABORT_S, ABORT_ALL_S)

    # The stream passes through the test, which can drop it and refuse reconnects.
    gate: dict[str, Any] = {"blocked": False, "live": []}

    async def stream_route(ws: WebSocketRoute) -> None:
        if gate["blocked"]:
            await ws.close(code=4000, reason="the network is down")
            return
        gate["live"].append((ws, ws.connect_to_server()))

    await page.route_web_socket(re.compile(r"/v1/flights/[^/]+/stream"), stream_route)

    await c.open(f"/ui/?flight={fid}")
    await c.login("not-the-token")
    refused = await c.until("() => document.getElementById('login-error').textContent")
    assert "refused the token" in refused, refused
    await c.login()
    await c.until(
        "id => tcgcs.state.flightId === id && tcgcs.stream && tcgcs.stream.state === 'open'", fid
    )
    await c.until("() => !document.getElementById('launch').disabled")
    await page.click("#launch")
    await c.confirm()
    await c.until_mission(DROP_S)

    # Drop the connection and keep the network down for 2 s: the page says so, then resumes.
    gate["blocked"] = True
    page_side, server_side = gate["live"].pop()
    await page_side.close(code=4000, reason="the network is down")
    await server_side.close()
    lost = await c.until("() => tcgcs.stream.state === 'lost' && tcgcs.stream.lastSeq")
    assert "reconnecting" in await c.text("#stream-status")
    await page.wait_for_timeout(2000)
    await c.screenshot("console-stream-lost.png")
    gate["blocked"] = False
    await c.until("() => tcgcs.stream.state === 'back'", timeout_s=15.0)
    status = await c.text("#stream-status")
    assert status.startswith("stream back after") and f"after event {lost}" in status, status
    assert await c.js("tcgcs.stream.reconnects") >= 2

    # Abort UAV1 from its row: it flies home; then all of them.
    await _paused_at(c, fid, ABORT_S)
    await page.click('#vehicles tr[data-vehicle="UAV1"] button.abort')
    await c.confirm()
    # The page's request is on its way once confirmed: its row says when the flight has it
    # (paused: the vehicle's new mode comes with its telemetry once the simulator flies on).
    await c.until("() => tcgcs.table.text().UAV1.state === 'aborted'")
    await _resume(c, fid)
    row = await c.until(
        """() => { const r = tcgcs.table.text().UAV1;
                   return r.state === "aborted" && r.mode === "RTL" && r; }"""
    )
    async with c.service.client() as client:
        snap = _ok(await client.get(f"/v1/flights/{fid}"))
    uav1 = next(v for v in snap["vehicles"] if v["id"] == "UAV1")
    assert uav1["state"] == "aborted" and uav1["link"]["mode"] == "RTL", uav1
    assert await page.is_disabled('#vehicles tr[data-vehicle="UAV1"] button.abort'), row
    await _paused_at(c, fid, ABORT_ALL_S)
    await c.screenshot("console-abort.png")
    await page.click("#abort-all")
    await c.confirm()
    await c.until("() => Object.values(tcgcs.table.text()).every(r => r.state === 'aborted')")
    await _resume(c, fid)
    await c.until("() => tcgcs.stream.state === 'ended'", timeout_s=60.0)

    async with c.service.client() as client:
        events = await _all_events(client, fid)
    seen = [e["seq"] for e in await c.js("tcgcs.events")]
    assert seen == [e["seq"] for e in events]
    assert len(set(seen)) == len(seen) and await c.js("tcgcs.stream.duplicates") == 0
    assert not c.external(), c.external()
