"""Sharing the team's approach points among its vehicles.

Where the goals are interchangeable (approach points around one target, any vehicle to any
point), which vehicle flies to which decides whether the routes cross. The assignment that
makes the sum of squared start-goal distances least is the one under which straight routes
flown in step do not cross (Turpin, Michael and Kumar, "CAPT: Concurrent assignment and
planning of trajectories for multiple robots", IJRR 33(1), 2014, section 4): routes that
converge on a target from two edges of the map then fan in side by side instead of
crossing near the goals, where no takeoff time or speed can keep them apart (the arrivals
are simultaneous there).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def assign_goals(
    starts: Sequence[tuple[float, float]], goals: Sequence[tuple[float, float]]
) -> list[int]:
    """For each start (local metres), the index of the goal it flies to: a permutation of
    the goals with the least sum of squared horizontal distances."""
    if len(starts) != len(goals):
        raise ValueError(f"{len(starts)} starts for {len(goals)} goals")
    s = np.asarray(starts, dtype=np.float64).reshape(-1, 2)
    g = np.asarray(goals, dtype=np.float64).reshape(-1, 2)
    cost = ((s[:, None, :] - g[None, :, :]) ** 2).sum(axis=-1)
    # Imported here: a scenario is read (and refused) without loading scipy.optimize.
    from scipy.optimize import linear_sum_assignment

    rows, cols = linear_sum_assignment(cost)
    order = [0] * len(starts)
    for r, c in zip(rows, cols, strict=True):
        order[int(r)] = int(c)
    return order
