"""Error classes of the planner. Each names what is wrong in one line."""

from __future__ import annotations


class PlannerError(Exception):
    """Base class of every error the planner raises on purpose."""


class ScenarioError(PlannerError, ValueError):
    """A scenario file or value is invalid; the message names the field."""


class TerrainError(PlannerError, ValueError):
    """Terrain data is missing or unreadable; the message names the tile or file."""


class InfeasibleError(PlannerError, ValueError):
    """No path or schedule satisfies the constraints; the message names the vehicle."""
