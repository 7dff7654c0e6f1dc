"""Test-wide settings.

Under CI (``CI`` set, as the CI runner does) hypothesis draws a fixed, derandomised set of
examples so a landing is decided by the code, not by the draw; local runs keep exploring new
examples, and a failure found there becomes an ``@example`` regression.
"""

from __future__ import annotations

import os

import pytest
from hypothesis import settings

settings.register_profile("ci", derandomize=True, database=None)
if os.environ.get("CI"):
    settings.load_profile("ci")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Every test under its own id, and the long ones (marked ``slow``: the whole flights
    among them) first.

    - Schemathesis names each operation's test ``test_operation[GET /v1/...]`` but leaves
      them all one node id; pytest-xdist hands tests out by node id and ran one of the 31.
      Each gets its name in its id, and a session with two tests under one id stops here.
    - On several workers (``pytest -n``) the longest tests then start at once and the short
      ones fill in behind them, instead of one flight starting last.
    """
    for item in items:
        named = f"{item.parent.nodeid}::{item.name}" if item.parent is not None else item.nodeid
        if item.nodeid != named:  # pytest 9 keeps the id apart from the node's name
            item._id = type(item.id).parse(named)
    seen: set[str] = set()
    for item in items:
        if item.nodeid in seen:
            raise pytest.UsageError(f"two tests are collected as {item.nodeid}")
        seen.add(item.nodeid)
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
