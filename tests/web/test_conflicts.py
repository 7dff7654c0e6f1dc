"""Conflicts in the console: thirty aircraft of :func:`tests.teams.ring_team` flown through the
service at 100x, with the pop-up zone of :mod:`tests.gcs.test_swarm_popup_replanned`: the
re-plan round it separates the pairs it brings under the separation before the missions are
sent (timed apart, or lifted onto a layer), or alarms those it cannot; in flight the speed
resolution keeps the rest apart, judged by that module. The page
draws a line between each pair in conflict, joining the two aircraft where it draws them,
and lists them in its Separation panel. The operator then sends them all home; once the
flight is over, what the page read of the stream is what the flight record's
``separation_events`` says (kind, pair and event), read by the service on its own."""

from __future__ import annotations

import asyncio
import math
from typing import Any

import pytest
import yaml

from tests.service.test_flights_http import _ok
from tests.teams import ring_team
from tests.web.conftest import Console

pytestmark = pytest.mark.slow  # thirty aircraft up to the re-plan: about 15 s of wall time

ZONE = {
    "kind": "radar", "id": "POP30", "forbidden": True,
    "center": {"east_m": 30_000.0, "north_m": 39_000.0}, "radius_m": 2_500.0,
    "appears": {"at_s": 95.0},
}  # fmt: skip


async def _ring_flight(c: Console) -> str:
    """The ring's flight on simulator vehicles at 100x, its missions on board."""
    data = ring_team(30)
    data["threats"].append(ZONE)
    async with c.service.client() as client:
        body = yaml.safe_dump(data, sort_keys=False)
        sc = _ok(
            await client.post(
                "/v1/scenarios", content=body, headers={"Content-Type": "application/yaml"}
            ),
            201,
        )
        job = _ok(await client.post("/v1/schedules", json={"scenario_id": sc["id"]}), 202)
        while job["state"] in ("queued", "running"):
            await asyncio.sleep(0.1)
            job = _ok(await client.get(f"/v1/jobs/{job['id']}"))
        assert job["state"] == "succeeded", job
        rehearsal = {"speedup": 100.0, "seed": 1}
        body2 = {"schedule_id": job["result"]["id"], "rehearsal": rehearsal}
        fid = str(_ok(await client.post("/v1/flights", json=body2), 201)["flight_id"])
        _ok(await client.post(f"/v1/flights/{fid}/upload"), 202)
        snap: dict[str, Any] = {"state": "planned"}
        while snap["state"] in ("planned", "uploading"):
            await asyncio.sleep(0.1)
            snap = _ok(await client.get(f"/v1/flights/{fid}"))
        assert snap["state"] == "ready", snap
    return fid


async def test_the_console_draws_each_conflict_between_the_pair_and_lists_it(
    console: Console,
) -> None:
    c, page = console, console.page
    fid = await _ring_flight(c)
    await c.open(f"/ui/?flight={fid}")
    await c.login()
    await c.until("() => !document.getElementById('launch').disabled", timeout_s=60.0)
    await page.click("#launch")
    await c.confirm()
    # Launched (the page says so), or the service's refusal, in words.
    said = await c.until(
        "() => document.getElementById('flight-error').textContent"
        " || (document.getElementById('flight-note').textContent.startsWith('launched')"
        " && 'launched')",
        timeout_s=60.0,
    )
    assert said == "launched", said

    # The pairs in conflict (the re-plan's, separated or not): drawn between the two
    # aircraft as drawn.
    drawn = await c.until(
        """() => {
             const lines = tcgcs.geometry().conflicts;
             if (!lines.length) return null;
             const at = Object.fromEntries(
               tcgcs.map.vehicles.map(v => [v.id, [v.east_m, v.north_m]]));
             const listed = [...document.querySelectorAll("#conflicts li.now")]
               .map(li => li.dataset.pair);
             return {lines, at, listed};
           }""",
        timeout_s=90.0,
    )
    await c.screenshot("console-conflicts.png")
    for line in drawn["lines"]:
        assert math.dist(line["from"], drawn["at"][line["a"]]) < 1e-6, line
        assert math.dist(line["to"], drawn["at"][line["b"]]) < 1e-6, line
        assert "|".join(sorted((line["a"], line["b"]))) in drawn["listed"], (line, drawn["listed"])

    # Sent home (the flight ends with its record), as the operator would once seen.
    await page.click("#abort-all")
    await c.confirm()
    await c.until("() => tcgcs.stream.state === 'ended'", timeout_s=120.0)
    async with c.service.client() as client:
        record = _ok(await client.get(f"/v1/flights/{fid}/record"))
    said = [[e["seq"], e["kind"], *e["pair"]] for e in record["separation_events"]]
    seen = await c.js("tcgcs.conflicts.seen.map(s => [s.seq, s.kind, s.a, s.b])")
    assert said and seen == said
    replanned = [
        e
        for e in record["separation_events"]
        if e["kind"] == "unresolved" or e["action"].startswith(("timing", "offset", "altitude +"))
    ]
    assert replanned, record["separation_events"]
    assert not c.external(), c.external()
