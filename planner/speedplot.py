"""Speed profiles per stage of the schedule (the paper's Figs. 6b, 7, 9 and 10c), from
schedule.json."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from planner.errors import PlannerError


def plot_speeds(doc: Mapping[str, Any], out: Path) -> None:
    """One panel per stage: speed (m/s) vs time (s) for each vehicle, its range dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    stages = doc.get("stages") or []
    if not stages:
        raise PlannerError("schedule has no stages to plot")
    vehicles = {v["id"]: v for v in doc["vehicles"]}
    fig, axes = plt.subplots(len(stages), 1, figsize=(9, 2.6 * len(stages)), sharex=True)
    axes_list = list(axes) if len(stages) > 1 else [axes]
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, stage in zip(axes_list, stages, strict=True):
        for k, (vid, spans) in enumerate(stage["vehicles"].items()):
            c = colours[k % len(colours)]
            first = True
            for t0, t1, v, kind in spans:
                style = {"leg": "-", "loiter": "-", "required": "--"}[kind]
                ax.plot(
                    [t0, t1],
                    [v, v],
                    style,
                    color=c,
                    lw=2.5 if kind == "loiter" else 1.6,
                    label=vid if first else None,
                )
                if kind == "loiter":
                    ax.axvspan(t0, t1, color=c, alpha=0.15)
                first = False
            lim = vehicles.get(vid, {})
            for key in ("speed_min_m_s", "speed_max_m_s"):
                if key in lim:
                    ax.axhline(lim[key], color=c, lw=0.6, ls=":")
        ax.set_title(stage["name"], fontsize=9)
        ax.set_ylabel("speed (m/s)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower left")
    axes_list[-1].set_xlabel("mission time (s)")
    fig.tight_layout()
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=110)
    except OSError as err:
        raise PlannerError(f"{out}: cannot write plot ({err.strerror})") from None
    finally:
        plt.close(fig)
