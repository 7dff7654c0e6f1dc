"""The flight's buttons in Chromium act only on a flight the page has open and has read: from
the page's load until the open flight's snapshot arrives, Upload, Launch, Abort all and Move
are disabled, whatever the flight's state. (They were enabled in that gap, and a Launch
pressed in it went to ``/v1/flights/null/launch``.) The snapshot is held back at the page's
network layer, so the gap lasts as long as the test wants on any machine."""

from __future__ import annotations

import asyncio

import pytest
from playwright.async_api import Route

from tests.service.test_flights_http import _flight
from tests.web.conftest import Console

pytestmark = pytest.mark.slow  # one flight planned and uploaded: a few seconds of wall time

BUTTONS = "['upload', 'launch', 'abort-all', 'team-time-move', 'pause']"
DISABLED = f"{BUTTONS}.map(id => document.getElementById(id).disabled)"


async def test_the_flight_buttons_wait_for_the_open_flights_snapshot(console: Console) -> None:
    c, page = console, console.page
    async with c.service.client() as client:
        fid, _ = await _flight(client, {"speedup": 100.0, "seed": 1}, scenario_name="compact")
    asked = asyncio.Event()
    release = asyncio.Event()

    async def hold(route: Route) -> None:
        asked.set()
        await release.wait()
        await route.continue_()

    await page.route(f"**/v1/flights/{fid}", hold)
    await c.open(f"/ui/?flight={fid}")
    assert await c.js(DISABLED) == [True] * 5  # before signing in
    await c.login()
    await asyncio.wait_for(asked.wait(), timeout=30.0)
    await c.until("() => !document.getElementById('console').hidden")
    assert await c.js(DISABLED) == [True] * 5  # signed in, the flight's snapshot not yet read
    await page.click("#launch", force=True)  # a press on the disabled button sends nothing
    assert not await c.js("document.getElementById('confirm').open")

    release.set()
    await c.until("() => !document.getElementById('launch').disabled")
    # Ready: launch, move the time, or pause (a rehearsal in lock step).
    assert await c.js(DISABLED) == [True, False, True, False, False]
    assert await c.text("#flight-title") == f"flight {fid}"

    # Pause before the launch: the rehearsal waits at its start, the button says Resume, and
    # a press on it flies the flight on.
    await page.click("#pause")
    await c.until("() => tcgcs.state.pause && tcgcs.state.pause.at_s.length === 1")
    assert await c.text("#flight-note") == "paused: the simulator waits here until resumed"
    await page.click("#launch")
    await c.confirm()
    await c.until("() => document.getElementById('pause').textContent === 'Resume'")
    async with c.service.client() as client:
        snap = (await client.get(f"/v1/flights/{fid}")).json()
    assert snap["pause"]["paused"] and 0.0 <= snap["t_s"] <= 3.0, snap["pause"]
    await page.click("#pause")
    await c.until("() => document.getElementById('pause').textContent === 'Pause'")
    assert await c.text("#flight-note") == "resumed: the flight flies on"
    await c.until("() => tcgcs.state.telemetry && tcgcs.state.telemetry.t_s > 20")
