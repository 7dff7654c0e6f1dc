"""A zone widened for a re-routed vehicle's route search (:func:`planner.replanoffset.
widened`): every point within the widening outside the zone is inside the widened one, by the
test's own sampling; a radar's disc grows by its radius."""

from __future__ import annotations

import numpy as np
import pytest

from planner.replanoffset import widened
from planner.threats import NoFlyZone, RadarSite


def test_a_radar_disc_grows_by_its_radius() -> None:
    radar = RadarSite("POP", 1_000.0, 2_000.0, 2_500.0, 3_000.0, True, 95.0)
    grown = widened(radar, 450.0)
    assert isinstance(grown, RadarSite)
    assert (grown.east_m, grown.north_m, grown.radius_m) == (1_000.0, 2_000.0, 2_950.0)
    assert (grown.id, grown.ceiling_m, grown.forbidden, grown.appears_at_s) == (
        "POP",
        3e3,
        True,
        95.0,
    )


@pytest.mark.parametrize(
    "vertices",
    [
        ((0.0, 0.0), (4_000.0, 0.0), (4_000.0, 1_000.0), (0.0, 1_000.0)),  # long and thin
        ((0.0, 0.0), (3_000.0, -500.0), (5_000.0, 2_000.0), (1_000.0, 3_000.0)),
    ],
    ids=["rectangle", "quadrilateral"],
)
def test_a_convex_polygon_grows_at_least_the_widening_all_round(
    vertices: tuple[tuple[float, float], ...],
) -> None:
    zone = NoFlyZone("OP1", vertices, 2_000.0, True)
    grown = widened(zone, 450.0)
    assert isinstance(grown, NoFlyZone) and grown.id == "OP1" and grown.ceiling_m == 2_000.0
    e, n = np.meshgrid(np.arange(-1_500.0, 6_500.0, 25.0), np.arange(-2_000.0, 4_500.0, 25.0))
    e, n = e.ravel(), n.ravel()
    # The distance to the zone's edges, the test's own (point to segment, least of them).
    v = np.asarray(vertices)
    w = np.roll(v, -1, axis=0)
    d = np.full(e.shape, np.inf)
    for (ax, ay), (bx, by) in zip(v, w, strict=True):
        dx, dy = bx - ax, by - ay
        u = np.clip(((e - ax) * dx + (n - ay) * dy) / (dx * dx + dy * dy), 0.0, 1.0)
        d = np.minimum(d, np.hypot(e - ax - u * dx, n - ay - u * dy))
    near = d < 449.0  # (on the grown edge itself a point is neither in nor out)
    assert near.sum() > 1_000 and grown.contains(e[near], n[near]).all()


def test_a_polygon_not_about_its_centroid_is_not_grown() -> None:
    """A C shape: its vertices' centroid lies in its mouth, outside it."""
    c_shape = (
        (0.0, 0.0), (3_000.0, 0.0), (3_000.0, 500.0), (500.0, 500.0),
        (500.0, 2_500.0), (3_000.0, 2_500.0), (3_000.0, 3_000.0), (0.0, 3_000.0),
    )  # fmt: skip
    assert widened(NoFlyZone("C", c_shape, 2_000.0, True), 450.0) is None
