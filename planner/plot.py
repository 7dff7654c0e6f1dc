"""Plot a plan: terrain, threats, buffers and the smoothed paths (paper Fig. 5/6a style)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from planner.errors import PlannerError
from planner.plan import World, build_world
from planner.scenario import load_scenario
from planner.threats import NoFlyZone, RadarSite

KM = 1000.0


def _load(path: Path) -> dict[str, Any]:
    try:
        doc: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    except OSError as err:
        raise PlannerError(f"{path}: cannot read plan ({err.strerror})") from None
    except json.JSONDecodeError as err:
        raise PlannerError(f"{path}: not valid JSON ({err.msg} at line {err.lineno})") from None
    for key in ("scenario_file", "vehicles"):
        if key not in doc:
            raise PlannerError(f"{path}: plan has no field {key!r}")
    return doc


def draw_world(
    fig: Any, ax: Any, world: World, appeared_s: Mapping[str, float] | None = None
) -> tuple[float, float, float, float]:
    """Terrain (with a colour bar), threats and buffer areas on ``ax``, in km.

    Pop-up threats are dashed and unfilled; ``appeared_s`` (threat id -> mission s) adds the
    time a threat appeared to its label and marks it as a pop-up. Returns the map extent
    (west, east, south, north) in km.
    """
    from matplotlib.patches import Circle, Polygon  # matplotlib when a figure is drawn

    appeared = appeared_s or {}
    g = world.grid
    extent = (
        g.min_east_m / KM,
        (g.min_east_m + (g.n_east - 1) * g.resolution_m) / KM,
        g.min_north_m / KM,
        (g.min_north_m + (g.n_north - 1) * g.resolution_m) / KM,
    )
    terrain = world.terrain_grid_m.reshape(g.n_north, g.n_east)
    im = ax.imshow(terrain, origin="lower", extent=extent, cmap="terrain", alpha=0.85)
    fig.colorbar(im, ax=ax, label="terrain (m AMSL)", shrink=0.8)
    for t in world.threats:
        popup = t.appears_at_s is not None or t.id in appeared
        colour = "red" if t.forbidden else "darkorange"
        style = "--" if popup else "-"
        label = t.id
        if popup:
            label += f"\n(pop-up {appeared[t.id]:.0f} s)" if t.id in appeared else "\n(pop-up)"
        if isinstance(t, RadarSite):
            ax.add_patch(
                Circle(
                    (t.east_m / KM, t.north_m / KM),
                    t.radius_m / KM,
                    fill=t.forbidden and not popup,
                    alpha=0.35 if t.forbidden and not popup else 1.0,
                    color=colour,
                    ls=style,
                    lw=1.5,
                )
            )
            ax.text(t.east_m / KM, t.north_m / KM, label, ha="center", va="center", fontsize=7)
        elif isinstance(t, NoFlyZone):
            verts = np.asarray(t.vertices_m) / KM
            ax.add_patch(Polygon(verts, closed=True, color=colour, alpha=0.35, ls=style))
            c = verts.mean(axis=0)
            ax.text(c[0], c[1], label, ha="center", va="center", fontsize=7)
    for b in world.scenario.buffers:
        e, n = b.center.local(world.frame)
        ax.add_patch(Circle((e / KM, n / KM), b.radius_m / KM, fill=False, color="green", ls=":"))
        ax.text(e / KM, n / KM, b.id, color="green", fontsize=7, ha="center")
    return extent


def plot_plan(plan_path: Path, out_path: Path) -> None:
    """Write a PNG of the plan over its scenario's terrain and threats."""
    doc = _load(plan_path)
    scenario_file = Path(doc["scenario_file"])
    if not scenario_file.is_absolute() and not scenario_file.exists():
        scenario_file = plan_path.parent / scenario_file
    scenario = load_scenario(scenario_file)
    world = build_world(scenario)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 8), dpi=110)
    extent = draw_world(fig, ax, world)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, v in enumerate(doc["vehicles"]):
        pts = np.array([[w["east_m"], w["north_m"]] for w in v["waypoints"]]) / KM
        c = colours[k % len(colours)]
        ax.plot(
            pts[:, 0],
            pts[:, 1],
            "-",
            color=c,
            lw=1.8,
            label=f"{v['id']} {v['length_m'] / KM:.0f} km",
        )
        ax.plot(pts[0, 0], pts[0, 1], "^", color=c, ms=9, mec="black")
        ax.plot(pts[-1, 0], pts[-1, 1], "*", color=c, ms=12, mec="black")
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    ax.set_xlabel("east (km)")
    ax.set_ylabel("north (km)")
    ax.set_title(
        f"{doc.get('scenario', '')}: {doc.get('method', '')} plan, {doc.get('status', '')}"
    )
    ax.legend(loc="lower right", fontsize=8)
    ax.set_aspect("equal")
    fig.tight_layout()
    try:
        out_path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out_path)
    except OSError as err:
        raise PlannerError(f"{out_path}: cannot write plot ({err.strerror})") from None
    finally:
        plt.close(fig)
