"""What an operator's map draws, in the scenario's local metres: the area, a hillshade of its
terrain, the threats (with when pop-ups appear and whether they are in force), the loiter
buffers, each vehicle's start, goal, planned route and loiter circles."""

from __future__ import annotations

import io
from typing import Any

import numpy as np

from gcs.coordination.member import path_en
from gcs.coordination.team import TeamController
from planner.scenario import NoFly, Radar, Scenario
from planner.terrain import build_terrain

__all__ = ["flight_map", "terrain_png"]

TERRAIN_PX = 768
"""The hillshade's longer side, pixels."""


def terrain_png(scenario: Scenario) -> bytes:
    """A hillshade coloured by height over the scenario's area (north up), as PNG."""
    import matplotlib  # when a map is first drawn, not when the service starts

    matplotlib.use("Agg")
    import matplotlib.colors as mcolors
    import matplotlib.pyplot as plt

    area = scenario.area
    terrain = build_terrain(scenario)
    scale = TERRAIN_PX / max(area.width_m, area.height_m)
    nx = max(2, int(area.width_m * scale))
    ny = max(2, int(area.height_m * scale))
    east = area.min_east_m + (np.arange(nx) + 0.5) * area.width_m / nx
    north = area.min_north_m + (np.arange(ny) + 0.5) * area.height_m / ny
    ee, nn = np.meshgrid(east, north[::-1])  # row 0 is the north edge
    z = np.asarray(terrain.elevation_m(ee.ravel(), nn.ravel()), dtype=float).reshape(ny, nx)
    light = mcolors.LightSource(azdeg=315, altdeg=45)
    vmin, vmax = float(np.min(z)), float(np.max(z))
    norm = mcolors.Normalize(vmin, vmax if vmax > vmin else vmin + 1.0)
    # The land part of matplotlib's "terrain" (no sea blue: the lowest ground is green),
    # washed towards white so the routes and threats drawn over it stand out.
    land = mcolors.LinearSegmentedColormap.from_list(
        "land",
        [
            (1.0 - 0.35) * np.array(plt.get_cmap("terrain")(x)) + 0.35
            for x in np.linspace(0.25, 1.0, 64)
        ],
    )
    rgb = light.shade(
        z, cmap=land, norm=norm, blend_mode="soft",
        vert_exag=3.0, dx=area.width_m / nx, dy=area.height_m / ny,
    )  # fmt: skip
    out = io.BytesIO()
    plt.imsave(out, rgb, format="png")
    return out.getvalue()


def _threat(
    t: Radar | NoFly, in_force: set[str], appears: dict[str, float | None]
) -> dict[str, Any]:
    doc: dict[str, Any] = {
        "id": t.id,
        "kind": t.kind,
        "in_force": t.id in in_force,
        "appears_at_s": appears.get(t.id),
    }
    if isinstance(t, Radar):
        doc |= {
            "center": [t.center.east_m, t.center.north_m],
            "radius_m": t.radius_m,
            "forbidden": bool(t.forbidden),
        }
    else:
        doc |= {"polygon": [[p.east_m, p.north_m] for p in t.polygon], "forbidden": True}
    return doc


def flight_map(team: TeamController, now_s: float) -> dict[str, Any]:
    """The flight's map as data (see the module)."""
    s = team.scenario
    a = s.area
    in_force = {z.id for z in team.in_force(now_s)}
    appears = {z.id: z.appears_at_s for z in team.zones()}
    threats = [
        _threat(t, in_force, appears)
        for t in (*s.threats, *team.operator_threats)
        if t.id not in team.removed_threats
    ]
    vehicles = []
    for v in s.vehicles:
        m = team.members[v.id]
        vehicles.append(
            {
                "id": v.id,
                "start": [v.start.east_m, v.start.north_m],
                "goal": [v.goal.east_m, v.goal.north_m],
                "route_en_m": path_en(m.schedule),
                "loiters": [
                    {
                        "centre": [lo.centre_east_m, lo.centre_north_m],
                        "radius_m": lo.radius_m,
                        "turns": lo.turns,
                    }
                    for lo in m.schedule.loiters
                ],
                "planned": [p["label"] for p in m.planned_paths],
            }
        )
    return {
        "area": {
            "min_east_m": a.min_east_m,
            "min_north_m": a.min_north_m,
            "width_m": a.width_m,
            "height_m": a.height_m,
        },
        "origin": {"lat_deg": a.origin.lat_deg, "lon_deg": a.origin.lon_deg},
        "threats": threats,
        "buffers": [
            {"id": b.id, "center": [b.center.east_m, b.center.north_m], "radius_m": b.radius_m}
            for b in s.buffers
        ],
        "vehicles": vehicles,
        "separation_m": s.separation_m,
    }
