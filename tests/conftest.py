"""Test-wide settings.

Under CI (``CI`` set, as the CI runner does) hypothesis draws a fixed, derandomised set of
examples so a landing is decided by the code, not by the draw; local runs keep exploring new
examples, and a failure found there becomes an ``@example`` regression.
"""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, database=None)
if os.environ.get("CI"):
    settings.load_profile("ci")
