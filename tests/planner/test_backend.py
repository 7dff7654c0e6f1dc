"""Planning backends: the routes finished on a local Ray instance (started here, as a cluster
would be joined) are the routes finished in this process, for the same seed."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from planner.backend import (
    AUTH_MODE_ENV,
    AUTH_TOKEN_ENV,
    AUTH_TOKEN_PATH_ENV,
    LOOPBACK_ONLY_ENV,
    RAY_START_TRIES,
    LocalBackend,
    RayBackend,
)
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


class _SlowRay:
    """Stands in for the ``ray`` module: its first ``fail`` starts time out as Ray's node does
    on a busy machine (``ray._private.node``: "The current node timed out during startup")."""

    def __init__(
        self, fail: int, error: str = "The current node timed out during startup."
    ) -> None:
        self.fail, self.error = fail, error
        self.calls: list[str] = []
        self.options: list[dict[str, object]] = []

    def is_initialized(self) -> bool:
        return False

    def init(self, **options: object) -> None:
        self.calls.append("init")
        self.options.append(options)
        if self.calls.count("init") <= self.fail:
            raise Exception(self.error)

    def shutdown(self) -> None:
        self.calls.append("shutdown")

    def remote(self, fn: object) -> object:
        return fn


@pytest.mark.parametrize("fail", [1, 2])
def test_a_ray_started_here_is_started_again_while_its_node_times_out(
    monkeypatch: pytest.MonkeyPatch, fail: int
) -> None:
    slow = _SlowRay(fail)
    monkeypatch.setitem(sys.modules, "ray", slow)
    backend = RayBackend(num_cpus=1)
    assert slow.calls == ["init", "shutdown"] * fail + ["init"]
    # A new Ray each time, not the cluster RAY_ADDRESS or the last `ray start` here names.
    assert [o["address"] for o in slow.options] == ["local"] * (fail + 1)
    backend.close()
    assert slow.calls[-1] == "shutdown"


def test_a_ray_that_times_out_every_time_or_fails_otherwise_says_so(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    slow = _SlowRay(RAY_START_TRIES)
    monkeypatch.setitem(sys.modules, "ray", slow)
    with pytest.raises(Exception, match="timed out during startup"):
        RayBackend(num_cpus=1)
    assert slow.calls.count("init") == RAY_START_TRIES
    broken = _SlowRay(1, "raylet binary not found")
    monkeypatch.setitem(sys.modules, "ray", broken)
    with pytest.raises(Exception, match="raylet binary not found"):
        RayBackend(num_cpus=1)
    assert broken.calls == ["init"]  # not a timeout: not tried again
    joining = _SlowRay(1)
    monkeypatch.setitem(sys.modules, "ray", joining)
    with pytest.raises(Exception, match="timed out"):
        RayBackend("auto")
    assert joining.calls == ["init"]  # a cluster joined is not started here
    assert joining.options == [{**joining.options[0], "address": "auto"}]


@pytest.mark.parametrize(
    ("address", "loopback"),
    [
        ("127.0.0.1:6379", True),
        ("ray://localhost:10001", True),
        ("[::1]:6379", True),
        ("head.example:6379", False),
        ("10.1.2.3:6379", False),
        ("auto", False),
    ],
)
@pytest.mark.parametrize("token", ["file", "default_file", "env", "none", "mode_set"])
def test_a_cluster_is_joined_on_its_loopback_address_and_with_the_token_at_hand(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, address: str, loopback: bool, token: str
) -> None:
    """Ray's ``ray start`` turns token authentication on when a token is at hand; a driver
    sends it only in ``RAY_AUTH_MODE=token`` (Ray's ``authentication_token_setup``), which the
    backend sets when it is unset and a token is where Ray looks for one. A cluster on a
    loopback address is joined on it (``ray._private.services.resolve_ip_for_localhost``
    otherwise puts the machine's network address in its place)."""
    for name in (AUTH_MODE_ENV, AUTH_TOKEN_ENV, AUTH_TOKEN_PATH_ENV, LOOPBACK_ONLY_ENV):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))
    if token == "file":
        (tmp_path / "token").write_text("t")
        monkeypatch.setenv(AUTH_TOKEN_PATH_ENV, str(tmp_path / "token"))
    elif token == "default_file":
        (tmp_path / ".ray").mkdir()
        (tmp_path / ".ray" / "auth_token").write_text("t")
    elif token == "env":
        monkeypatch.setenv(AUTH_TOKEN_ENV, "t")
    elif token == "mode_set":
        monkeypatch.setenv(AUTH_MODE_ENV, "disabled")
        monkeypatch.setenv(AUTH_TOKEN_ENV, "t")
    joined = _SlowRay(0)
    monkeypatch.setitem(sys.modules, "ray", joined)
    RayBackend(address).close()
    assert joined.options[0]["address"] == address
    assert os.environ.get(LOOPBACK_ONLY_ENV) == ("0" if loopback else None)
    expected = {"none": None, "mode_set": "disabled"}.get(token, "token")
    assert os.environ.get(AUTH_MODE_ENV) == expected
