"""Landing slots: the straight final before each slot fix and the glide after it.

A scenario's :class:`~planner.scenario.Landing` puts every goal (a slot fix) on the runway's
extended centreline. The route must cross the fix on the approach course, so the grid search
ends where the final begins (``approach_m`` before the fix, on the course) and the final is
flown straight from there (:func:`final_m`). After the fix the aircraft glides to the
touchdown (ArduPlane's NAV_LAND flies the slope from the previous waypoint): that glide must
stay out of the forbidden zones and above the terrain (:func:`check_glide`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from planner.errors import InfeasibleError
from planner.geo import LocalFrame
from planner.scenario import Landing, Vehicle
from planner.terrain import Terrain
from planner.threats import ThreatZone

GLIDE_STEP_M = 25.0
FLARE_M = 300.0
"""The last stretch before the touchdown, where the glide meets the runway: not checked
against the terrain clearance (the runway is there)."""


def course_unit(landing: Landing) -> tuple[float, float]:
    """(east, north) unit vector of the approach course."""
    c = math.radians(landing.heading_deg)
    return math.sin(c), math.cos(c)


def final_m(landing: Landing, v: Vehicle, frame: LocalFrame) -> tuple[tuple[float, float], ...]:
    """The final's start and the slot fix (local metres): the last two route points."""
    ge, gn = v.goal.local(frame)
    ue, un = course_unit(landing)
    return (ge - landing.approach_m * ue, gn - landing.approach_m * un), (ge, gn)


def glide_en_alt(
    landing: Landing, v: Vehicle, frame: LocalFrame
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Samples of the glide from the slot fix to the touchdown: east, north, altitude AMSL
    and distance to go to the touchdown (m)."""
    ge, gn = v.goal.local(frame)
    te, tn = landing.touchdown.local(frame)
    length = math.hypot(te - ge, tn - gn)
    f = np.linspace(0.0, 1.0, max(2, math.ceil(length / GLIDE_STEP_M) + 1))
    east = ge + f * (te - ge)
    north = gn + f * (tn - gn)
    alt = v.goal.alt_m + f * (landing.touchdown.alt_m - v.goal.alt_m)
    return east, north, alt, (1.0 - f) * length


def check_glide(
    landing: Landing,
    v: Vehicle,
    frame: LocalFrame,
    terrain: Terrain,
    threats: Sequence[ThreatZone],
) -> None:
    """Refuse a glide that enters a forbidden zone, or passes closer to the terrain than
    the smaller of ``clearance_m`` and half its height above the touchdown, short of the
    last ``FLARE_M``.

    Raises
    ------
    InfeasibleError
        Naming the vehicle, the position and the shortfall.
    """
    east, north, alt, to_go = glide_en_alt(landing, v, frame)
    for t in threats:
        if not t.forbidden:
            continue
        inside = (t.distance_m(east, north) < 0.0) & (alt < t.ceiling_m)
        if inside.any():
            k = int(np.argmax(inside))
            raise InfeasibleError(
                f"vehicle {v.id}: the glide from its slot fix to the touchdown enters "
                f"forbidden zone {t.id} at ({east[k]:.0f}, {north[k]:.0f}) m",
                vehicle=v.id,
            )
    ground = terrain.elevation_m(east, north)
    height = alt - landing.touchdown.alt_m
    need = np.minimum(v.clearance_m, 0.5 * height)
    short = (alt - ground < need) & (to_go > FLARE_M)
    if short.any():
        k = int(np.argmax(short))
        raise InfeasibleError(
            f"vehicle {v.id}: the glide from its slot fix to the touchdown passes "
            f"{alt[k] - ground[k]:.0f} m above the terrain at ({east[k]:.0f}, {north[k]:.0f}) m, "
            f"{to_go[k]:.0f} m before the touchdown (it needs {need[k]:.0f} m)",
            vehicle=v.id,
        )
