"""The rehearsal report's figures, recreating the reference paper's from what was flown.

* ``paths.png``: terrain, threats (pop-ups dashed, with their appearance time), buffers, the
  planned paths (initial dashed, replans solid), the flown tracks, loiter circles, starts, goals
  and goal crossings (Fig. 10a);
* ``speeds.png``: per vehicle, commanded airspeed, flown air- and groundspeed, the planned spans
  and the speed limits, with launch, pop-up and arrival markers (Figs. 7, 9 and 10c);
* ``timeline.png``: the events per vehicle on a time axis, with the required arrival.

Times are mission seconds, ``utc_s - start_utc_s``; maps are in km of the scenario's local
frame. matplotlib is imported when a figure is drawn.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from gcs.errors import GcsError
from gcs.rehearsal.flightrecord import Flight, RecordedVehicle
from planner.plan import World
from planner.plot import draw_world

__all__ = ["FIGURES", "plot_paths", "plot_speeds", "plot_timeline"]

FIGURES = ("paths.png", "speeds.png", "timeline.png")
KM = 1000.0


def _colours() -> list[str]:
    import matplotlib.pyplot as plt

    colours: list[str] = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    return colours


def _save(fig: Any, out: Path) -> None:
    import matplotlib.pyplot as plt

    try:
        fig.savefig(out, dpi=110)
    except OSError as err:
        raise GcsError(f"{out}: cannot write figure ({err.strerror})") from None
    finally:
        plt.close(fig)


def _crossing(v: RecordedVehicle) -> tuple[float, float] | None:
    """Where the flown track was at the arrival time (the goal crossing)."""
    if v.arrival_utc_s is None or len(v.track) == 0:
        return None
    t = v.track[:, 0]
    return (
        float(np.interp(v.arrival_utc_s, t, v.track[:, 1])),
        float(np.interp(v.arrival_utc_s, t, v.track[:, 2])),
    )


def plot_paths(flight: Flight, world: World, title: str, out: Path) -> None:
    """``paths.png``: the world, the planned and flown paths, loiters, starts, goals."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle

    scenario = world.scenario
    fig, ax = plt.subplots(figsize=(9, 8))
    appeared = {tid: flight.t(utc) for tid, utc in flight.threats_appeared}
    extent = draw_world(fig, ax, world, appeared)
    known = {v.id: v for v in scenario.vehicles}
    colours = _colours()
    for k, v in enumerate(flight.vehicles):
        c = colours[k % len(colours)]
        for i, p in enumerate(v.planned_paths):
            if len(p.en_m):
                xy = p.en_m / KM
                initial = i == 0
                ax.plot(xy[:, 0], xy[:, 1], "--" if initial else "-", color=c, lw=0.9, alpha=0.8)
        err = "not arrived" if v.error_s is None else f"{v.error_s:+.2f} s"
        if len(v.track):
            ax.plot(
                v.track[:, 1] / KM,
                v.track[:, 2] / KM,
                "-",
                color=c,
                lw=2.0,
                label=f"{v.id} ({err})",
            )
        else:
            ax.plot([], [], "-", color=c, lw=2.0, label=f"{v.id} ({err}, no track)")
        for lo in v.loiters:
            ax.plot(lo.east_m / KM, lo.north_m / KM, "o", color=c, ms=7, mfc="none", mew=1.5)
            ax.add_patch(
                Circle(
                    (lo.east_m / KM, lo.north_m / KM),
                    lo.radius_m / KM,
                    fill=False,
                    color=c,
                    lw=1.4,
                )
            )
            ax.text(
                (lo.east_m + lo.radius_m) / KM,
                lo.north_m / KM,
                f" {lo.turns:g} turn(s)",
                color=c,
                fontsize=7,
                va="center",
            )
        if v.id in known:
            se, sn = known[v.id].start.local(world.frame)
            ge, gn = known[v.id].goal.local(world.frame)
            ax.plot(se / KM, sn / KM, "^", color=c, ms=9, mec="black")
            ax.plot(ge / KM, gn / KM, "*", color=c, ms=12, mec="black")
        crossing = _crossing(v)
        if crossing is not None:
            ax.plot(crossing[0] / KM, crossing[1] / KM, "X", color=c, ms=8, mec="black")
    handles, _ = ax.get_legend_handles_labels()
    grey = "dimgray"
    handles += [
        Line2D([], [], color=grey, ls="--", lw=0.9, label="initial plan"),
        Line2D([], [], color=grey, ls="-", lw=0.9, label="replanned"),
        Line2D([], [], color=grey, ls="", marker="^", mec="black", label="start"),
        Line2D([], [], color=grey, ls="", marker="*", ms=10, mec="black", label="goal"),
        Line2D([], [], color=grey, ls="", marker="X", mec="black", label="goal crossing"),
        Line2D([], [], color=grey, ls="", marker="o", mfc="none", label="loiter"),
    ]
    ax.legend(handles=handles, loc="lower right", fontsize=7)
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    ax.set_xlabel("east (km)")
    ax.set_ylabel("north (km)")
    ax.set_title(f"{title}: planned and flown paths")
    ax.set_aspect("equal")
    fig.tight_layout()
    _save(fig, out)


def _time_end(flight: Flight) -> float:
    """The last mission time anything in the record refers to."""
    ends = [] if flight.required_utc_s is None else [flight.required_utc_s]
    for v in flight.vehicles:
        ends.append(v.target_utc_s)
        if v.arrival_utc_s is not None:
            ends.append(v.arrival_utc_s)
        if len(v.track):
            ends.append(float(v.track[-1, 0]))
        ends += [s[1] for s in v.planned_speeds]
        ends += [c[0] for c in v.commanded]
    return flight.t(max(ends))


def plot_speeds(flight: Flight, title: str, out: Path) -> None:
    """``speeds.png``: per vehicle, planned, commanded and flown speeds over mission time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(flight.vehicles)
    fig, axes = plt.subplots(n, 1, figsize=(10.5, 2.6 * n + 0.6), sharex=True, squeeze=False)
    colours = _colours()
    end = _time_end(flight)
    popups = [(tid, flight.t(utc)) for tid, utc in flight.threats_appeared]
    for k, (ax, v) in enumerate(zip(axes[:, 0], flight.vehicles, strict=True)):
        c = colours[k % len(colours)]
        first = True
        for t0, t1, speed, kind in v.planned_speeds:
            x0, x1 = flight.t(t0), flight.t(t1)
            ax.plot(
                [x0, x1],
                [speed, speed],
                "-",
                color=c,
                lw=0.8,
                alpha=0.6,
                label="planned" if first else None,
            )
            if kind == "loiter":
                ax.axvspan(x0, x1, color=c, alpha=0.12)
            first = False
        if v.commanded:
            xs = [flight.t(cmd[0]) for cmd in v.commanded] + [end]
            ys = [cmd[1] for cmd in v.commanded]
            ax.step(xs, [*ys, ys[-1]], where="post", color=c, lw=2.0, label="commanded")
        if len(v.track):
            tx = v.track[:, 0] - flight.start_utc_s
            ax.plot(tx, v.track[:, 4], "-", color="black", lw=0.8, label="airspeed (flown)")
            ax.plot(
                tx, v.track[:, 5], "-", color="gray", lw=0.8, alpha=0.7, label="groundspeed (flown)"
            )
        for lim in (v.speed_min_m_s, v.speed_max_m_s):
            if lim is not None:
                ax.axhline(lim, color=c, lw=0.8, ls=":")
        if v.takeoff_utc_s is not None:
            ax.axvline(flight.t(v.takeoff_utc_s), color="green", ls="--", lw=1.0, label="launch")
        for i, (tid, t) in enumerate(popups):
            ax.axvline(t, color="red", ls=":", lw=1.2, label="pop-up" if i == 0 else None)
            ax.annotate(
                tid,
                (t, 1.0),
                xycoords=("data", "axes fraction"),
                fontsize=6,
                color="red",
                ha="left",
                va="top",
            )
        ax.axvline(flight.t(v.target_utc_s), color="gray", ls="-.", lw=1.0, label="target")
        if v.arrival_utc_s is not None:
            ax.axvline(flight.t(v.arrival_utc_s), color="black", lw=1.0, label="arrival")
        err = "not arrived" if v.error_s is None else f"error {v.error_s:+.2f} s"
        ax.set_title(f"{v.id}: {err}", fontsize=9)
        ax.set_ylabel("speed (m/s)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    axes[-1, 0].set_xlabel("mission time (s)")
    fig.suptitle(f"{title}: commanded and flown speeds", fontsize=10)
    fig.tight_layout()
    _save(fig, out)


_MARKERS: dict[str, tuple[str, str]] = {
    "takeoff_delay": ("s", "tab:blue"),
    "speed": ("^", "tab:orange"),
    "loiter": ("o", "tab:green"),
    "launch": ("P", "black"),
    "arrival": ("*", "gold"),
    "late": ("v", "red"),
    "popup": ("X", "red"),
    "replan": ("D", "tab:purple"),
    "link": ("x", "gray"),
    "upload": ("|", "gray"),
}


def plot_timeline(flight: Flight, title: str, out: Path) -> None:
    """``timeline.png``: the events per vehicle and the team on a mission-time axis."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [v.id for v in flight.vehicles]
    extra = sorted({e.vehicle for e in flight.events if e.vehicle and e.vehicle not in rows})
    rows += [*extra, "team"]
    y = {name: i for i, name in enumerate(rows)}
    fig, ax = plt.subplots(figsize=(10, 1.0 + 0.55 * len(rows)))
    marks = list(flight.events)
    if not any(e.strategy for e in marks):
        marks += flight.adjustments  # no strategy in the events: show the adjustments
    seen: set[str] = set()
    for e in marks:
        key = e.strategy or e.kind
        marker, colour = _MARKERS.get(key, (".", "gray"))
        ax.plot(
            flight.t(e.utc_s),
            y[e.vehicle or "team"],
            marker,
            color=colour,
            ms=8,
            mec="black",
            mew=0.5,
            ls="",
            label=None if key in seen else key,
        )
        seen.add(key)
    for v in flight.vehicles:
        ax.plot(flight.t(v.target_utc_s), y[v.id], "|", color="gray", ms=16, mew=1.5)
    if flight.required_utc_s is not None:
        ax.axvline(
            flight.t(flight.required_utc_s),
            color="black",
            ls="--",
            lw=1.0,
            label="required arrival",
        )
    ax.set_yticks(range(len(rows)), rows)
    ax.set_ylim(-0.7, len(rows) - 0.3)
    lo = min(0.0, *(flight.t(e.utc_s) for e in marks))
    hi = _time_end(flight)
    pad = 0.02 * (hi - lo) + 1.0
    ax.set_xlim(lo - pad, hi + pad)
    ax.set_xlabel("mission time (s)")
    ax.set_title(f"{title}: events (| = vehicle's target arrival)", fontsize=10)
    ax.grid(axis="x", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.tight_layout()
    _save(fig, out)
