"""Planning backends: the routes finished on a local Ray instance (started here, as a cluster
would be joined) are the routes finished in this process, for the same seed."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from planner.backend import LocalBackend, RayBackend
from planner.errors import InfeasibleError
from planner.plan import Plan, plan
from planner.scenario import load_scenario, parse_scenario
from tests.planner.conftest import small_scenario

ROOT = Path(__file__).resolve().parents[2]
# One local Ray for the module, started on one worker under pytest -n.
pytestmark = pytest.mark.xdist_group("ray")


@pytest.fixture(scope="module")
def ray_backend() -> Iterator[RayBackend]:
    backend = RayBackend(num_cpus=2)
    try:
        yield backend
    finally:
        backend.close()


def _same(a: Plan, b: Plan) -> None:
    assert [r.vehicle_id for r in a.routes] == [r.vehicle_id for r in b.routes]
    for x, y in zip(a.routes, b.routes, strict=True):
        assert x.grid_nodes == y.grid_nodes and x.cost == y.cost
        np.testing.assert_array_equal(x.simplified_m, y.simplified_m)
        np.testing.assert_array_equal(x.waypoints_m, y.waypoints_m)
        assert x.path.length_m == y.path.length_m
        np.testing.assert_array_equal(x.profile.alt_m, y.profile.alt_m)
        assert x.constraints == y.constraints
    assert a.min_separation_m == b.min_separation_m


@pytest.mark.parametrize("name", ["paper_three_uav.yaml"])
def test_a_plan_finished_on_ray_is_the_plan_finished_here(
    ray_backend: RayBackend, name: str
) -> None:
    scenario = load_scenario(ROOT / "scenarios" / name)
    import ray

    assert ray.util.get_node_ip_address() == "127.0.0.1"  # this machine's alone
    here = plan(scenario, rng=np.random.default_rng(3))
    on_ray = plan(scenario, rng=np.random.default_rng(3), backend=ray_backend)
    _same(here, on_ray)
    _same(here, plan(scenario, rng=np.random.default_rng(3), backend=LocalBackend(workers=1)))


def test_a_route_that_cannot_be_made_flyable_on_ray_fails_as_it_does_here(
    ray_backend: RayBackend,
) -> None:
    data = small_scenario()
    data["vehicles"][0]["min_turn_radius_m"] = 5000  # its turns swing into the SAM's disc
    scenario = parse_scenario(data)
    with pytest.raises(InfeasibleError, match="vehicle A: smoothed path enters") as here:
        plan(scenario, "astar")
    with pytest.raises(InfeasibleError) as remote:
        plan(scenario, "astar", backend=ray_backend)
    assert str(here.value) in str(remote.value)
