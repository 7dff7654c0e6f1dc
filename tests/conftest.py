"""Test-wide settings.

Under CI (``CI`` set, as the CI runner does) hypothesis draws a fixed, derandomised set of
examples so a landing is decided by the code, not by the draw; local runs keep exploring new
examples, and a failure found there becomes an ``@example`` regression. Either way no verdict
is on wall time: no deadline per example, and no health check on how slowly examples are drawn
(on a busy machine one failed with 8 drawn in 1.2 s).
"""

from __future__ import annotations

import os

import pytest
from hypothesis import HealthCheck, settings

_UNTIMED = {"deadline": None, "suppress_health_check": [HealthCheck.too_slow]}
settings.register_profile("local", **_UNTIMED)
settings.register_profile("ci", derandomize=True, database=None, **_UNTIMED)
settings.load_profile("ci" if os.environ.get("CI") else "local")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Every test under its own id, and the long ones (marked ``slow``: the whole flights
    among them) first.

    - pytest-xdist hands tests out by node id: two tests under one id (schemathesis'
      operation tests on pytest 9 all had one) would run once, so such a session stops here.
    - On several workers (``pytest -n``) the longest tests then start at once and the short
      ones fill in behind them, instead of one flight starting last.
    """
    seen: set[str] = set()
    for item in items:
        if item.nodeid in seen:
            raise pytest.UsageError(f"two tests are collected as {item.nodeid}")
        seen.add(item.nodeid)
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
