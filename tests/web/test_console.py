"""The operator console end to end: Chromium on ``/ui/`` against ``python -m gcs serve`` with
simulator vehicles at 200x. The page is driven as an operator drives it (the file picker, the
buttons and their confirmations, the mouse on the map) and read through what it draws
(``window.tcgcs``) and what it says (the DOM); the service is checked over HTTP, and the flight
the operator flew is judged by the oracle from the simulator's truth log (arrivals against the
slots set before launch, 3-D separation, the scenario's zones and the one drawn on the map:
:func:`tests.verdict.assert_flown`)."""

from __future__ import annotations

import math
import re
from typing import Any

import pytest
from playwright.async_api import WebSocketRoute

from tests import oracle
from tests.gcs.conftest import PAPER
from tests.paperbounds import team_time_move_max_s
from tests.service.test_flights_http import (
    ARRIVAL_TOLERANCE_S,
    TOGETHER_MIN_S,
    _all_events,
    _flight,
    _ok,
    _uav3_box,
    truth_log,
)
from tests.verdict import assert_flown
from tests.web.conftest import Console

pytestmark = pytest.mark.slow  # each flies one flight: about 40 s and 20 s of wall time

UAVS = ("UAV1", "UAV2", "UAV3")


def _inside(e: float, n: float, polygon: list[list[float]]) -> bool:
    """Ray casting: is (e, n) inside the polygon?"""
    inside = False
    for (e1, n1), (e2, n2) in zip(polygon, polygon[1:] + polygon[:1], strict=True):
        if (n1 > n) != (n2 > n) and e < e1 + (n - n1) * (e2 - e1) / (n2 - n1):
            inside = not inside
    return inside


async def _positions(c: Console) -> tuple[float, dict[str, tuple[float, float]]]:
    """The mission time and each vehicle's position the map draws."""
    got = await c.js(
        "({t: tcgcs.telemetry.t_s, v: tcgcs.map.vehicles.map(v => [v.id, v.east_m, v.north_m])})"
    )
    return got["t"], {vid: (e, n) for vid, e, n in got["v"]}


async def _three_moving(c: Console) -> None:
    t1, first = await _positions(c)
    await c.until_mission(t1 + 150.0)
    _, second = await _positions(c)
    assert set(first) == set(second) == set(UAVS)
    for vid in UAVS:
        assert math.dist(first[vid], second[vid]) > 500.0, (vid, first[vid], second[vid])
    rows = await c.js("tcgcs.table.text()")
    assert all(rows[v]["state"] in ("on route", "climbing", "link silent") for v in UAVS), rows


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


async def test_an_operator_flies_the_paper_scenario_from_the_console(console: Console) -> None:
    c, page = console, console.page
    box = _uav3_box()
    await c.open("/")  # redirected to /ui/
    await c.login()
    # A flight from the scenario file: the file picker, the rehearsal form, a confirmation.
    await page.click("#new-flight summary")
    await page.set_input_files("#scenario-file", str(PAPER))
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
    await page.click("#launch")
    await c.confirm()

    # Three vehicles fly: what the map draws moves between two reads.
    await c.until_mission(600.0)
    await _three_moving(c)

    # A no-fly zone drawn by mouse on UAV3's route, after the scenario's pop-up (1500 s).
    await c.until_mission(1900.0)
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

    # The team time: one no vehicle can make is refused in words; +120 s moves every slot.
    await c.until_mission(2300.0)
    now = await c.mission_s()
    refused = await _move_team_time(c, now + 100.0)
    assert re.search(
        r"earliest time every vehicle can make is \d+\.\d s \(UAV\d forces it\)\..*HTTP 409",
        refused,
        re.S,
    ), refused
    state: dict[str, Any] = await c.js(
        "({ref: tcgcs.state.teamTimeS, slots: Object.fromEntries("
        "[...tcgcs.state.vehicles.values()].map(v => [v.id, v.slot_s]))})"
    )
    await page.fill("#team-time", "")
    moved = await _move_team_time(c, state["ref"] + 120.0)
    assert moved.startswith("team arrival moved to"), moved
    want = {v: s + 120.0 for v, s in state["slots"].items()}
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

    # Mid-flight (UAV3 holding in B3), then the arrival.
    await c.until_mission(3500.0)
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
    # (tests.paperbounds), the operator by 120 s from the console, and nothing after that.
    move_max_s = team_time_move_max_s(5.0, 270.0)
    moved_s = state["ref"] - record["planned_arrival_s"]
    assert 0.0 <= moved_s <= move_max_s, (moved_s, move_max_s)
    assert record["required_arrival_s"] == pytest.approx(state["ref"] + 120.0, abs=1e-3)
    # The flown tracks (the truth's): on the slots, apart, and out of the zones, the one
    # drawn included (forbidden from the mission time read before it was sent).
    drawn = {"kind": "no_fly", "id": "OP1",
             "polygon": [{"east_m": e, "north_m": n} for e, n in polygon]}  # fmt: skip
    assert_flown(
        record,
        truth_log(c.service, fid),
        tolerance_s=ARRIVAL_TOLERANCE_S,
        team_shift_max_s=move_max_s + 120.0,
        together_min_s=TOGETHER_MIN_S,
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
        fid, _ = await _flight(client, {"speedup": 200.0, "seed": 2})

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
    await c.until_mission(500.0)

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
    await c.until_mission(1200.0)
    await page.click('#vehicles tr[data-vehicle="UAV1"] button.abort')
    await c.confirm()
    # The page's request is on its way once confirmed: its row says when the flight has it.
    row = await c.until(
        """() => { const r = tcgcs.table.text().UAV1;
                   return r.state === "aborted" && r.mode === "RTL" && r; }"""
    )
    async with c.service.client() as client:
        snap = _ok(await client.get(f"/v1/flights/{fid}"))
    uav1 = next(v for v in snap["vehicles"] if v["id"] == "UAV1")
    assert uav1["state"] == "aborted" and uav1["link"]["mode"] == "RTL", uav1
    assert await page.is_disabled('#vehicles tr[data-vehicle="UAV1"] button.abort'), row
    await c.until_mission(1500.0)
    await c.screenshot("console-abort.png")
    await page.click("#abort-all")
    await c.confirm()
    await c.until("() => tcgcs.stream.state === 'ended'", timeout_s=60.0)

    async with c.service.client() as client:
        events = await _all_events(client, fid)
    seen = [e["seq"] for e in await c.js("tcgcs.events")]
    assert seen == [e["seq"] for e in events]
    assert len(set(seen)) == len(seen) and await c.js("tcgcs.stream.duplicates") == 0
    assert not c.external(), c.external()
