"""The planning space: an 8-connected grid graph whose edge cost is length x node cost.

Node cost is ``1 + w_threat * exposure + w_terrain * climb_penalty``; nodes where the vehicle
cannot fly (terrain + clearance above its ceiling, or within reach of a forbidden zone) are
blocked. Forbidden zones are inflated by half a diagonal so that no edge between two free
nodes can cross one.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from planner.threats import ThreatZone, exposure, forbidden_mask

if TYPE_CHECKING:
    from scipy import sparse

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

# (d_east, d_north) of the 8 moves, counter-clockwise from east.
MOVES: tuple[tuple[int, int], ...] = (
    (1, 0),
    (1, 1),
    (0, 1),
    (-1, 1),
    (-1, 0),
    (-1, -1),
    (0, -1),
    (1, -1),
)
MOVE_LENGTH = np.array([math.hypot(de, dn) for de, dn in MOVES])
CLIMB_PENALTY_SCALE_M = 1000.0


@dataclass(frozen=True, slots=True)
class Grid:
    """Nodes at ``min + i * resolution`` for ``i`` in ``[0, n)`` along east and north."""

    min_east_m: float
    min_north_m: float
    resolution_m: float
    n_east: int
    n_north: int

    @classmethod
    def covering(
        cls, min_east_m: float, min_north_m: float, width_m: float, height_m: float, res_m: float
    ) -> Grid:
        n_e = int(math.floor(width_m / res_m + 1e-9)) + 1
        n_n = int(math.floor(height_m / res_m + 1e-9)) + 1
        return cls(min_east_m, min_north_m, res_m, n_e, n_n)

    @property
    def size(self) -> int:
        return self.n_east * self.n_north

    def coords(self) -> tuple[FloatArray, FloatArray]:
        """(east_m, north_m) of every node, flattened north-major (index = j * n_east + i)."""
        i = np.arange(self.size) % self.n_east
        j = np.arange(self.size) // self.n_east
        east = self.min_east_m + i * self.resolution_m
        north = self.min_north_m + j * self.resolution_m
        return east.astype(np.float64), north.astype(np.float64)

    def node_coords(self, nodes: Sequence[int] | IntArray) -> FloatArray:
        idx = np.asarray(nodes, dtype=np.int64)
        e = self.min_east_m + (idx % self.n_east) * self.resolution_m
        n = self.min_north_m + (idx // self.n_east) * self.resolution_m
        return np.stack([e, n], axis=-1).astype(np.float64)

    def nearest(self, east_m: float, north_m: float) -> int:
        i = int(round((east_m - self.min_east_m) / self.resolution_m))
        j = int(round((north_m - self.min_north_m) / self.resolution_m))
        i = min(max(i, 0), self.n_east - 1)
        j = min(max(j, 0), self.n_north - 1)
        return j * self.n_east + i

    def neighbors(self) -> IntArray:
        """(N, 8) neighbour index per move, -1 off the grid."""
        i = np.arange(self.size) % self.n_east
        j = np.arange(self.size) // self.n_east
        out = np.full((self.size, 8), -1, dtype=np.int64)
        for k, (de, dn) in enumerate(MOVES):
            ii, jj = i + de, j + dn
            ok = (ii >= 0) & (ii < self.n_east) & (jj >= 0) & (jj < self.n_north)
            out[ok, k] = (jj * self.n_east + ii)[ok]
        return out


@dataclass(frozen=True, slots=True)
class VehicleClass:
    """The vehicle limits that shape a cost map; vehicles alike share one."""

    clearance_m: float
    alt_min_m: float
    alt_max_m: float
    cruise_alt_m: float


@dataclass(frozen=True, eq=False)
class CostMap:
    """Per-node and per-edge costs of one vehicle class on a grid."""

    grid: Grid
    vehicle: VehicleClass
    neighbors: IntArray
    node_cost: FloatArray
    blocked: NDArray[np.bool_]
    flight_alt_m: FloatArray
    edge_cost: FloatArray = field(repr=False)

    def graph(self) -> sparse.csr_array:
        """The directed (symmetric) edge-cost graph for scipy.sparse.csgraph.

        Built once per cost map (vehicles of one class share it) and kept: callers must not
        modify it.
        """
        return self._graph

    @cached_property
    def _graph(self) -> sparse.csr_array:
        n = self.grid.size
        src = np.repeat(np.arange(n), 8)
        dst = self.neighbors.ravel()
        w = self.edge_cost.ravel()
        ok = np.isfinite(w)
        from scipy import sparse  # a sixth of a second: only where routes are searched

        return sparse.csr_array((w[ok], (src[ok], dst[ok])), shape=(n, n))

    def path_cost(self, nodes: Sequence[int] | IntArray) -> float:
        """Graph cost of a node sequence (inf if it uses a missing edge)."""
        idx = np.asarray(nodes, dtype=np.int64)
        if len(idx) < 2:
            return 0.0
        a, b = idx[:-1], idx[1:]
        match = self.neighbors[a] == b[:, None]
        if not match.any(axis=1).all():
            return math.inf
        k = match.argmax(axis=1)
        return float(self.edge_cost[a, k].sum())


def build_cost_map(
    grid: Grid,
    terrain_m: FloatArray,
    threats: Sequence[ThreatZone],
    vehicle: VehicleClass,
    *,
    threat_weight: float,
    terrain_weight: float,
    neighbors: IntArray | None = None,
) -> CostMap:
    """Cost map of one vehicle class.

    Parameters
    ----------
    grid : the planning grid.
    terrain_m : terrain elevation AMSL (m) at every node, flattened as ``grid.coords()``.
    threats : threats in force; forbidden ones block nodes, costed ones add exposure.
    vehicle : clearance (m), altitude limits (m AMSL) and nominal cruise altitude (m AMSL).
    threat_weight, terrain_weight : weights of exposure and of the climb penalty.
    """
    east, north = grid.coords()
    flight_alt = np.maximum(terrain_m + vehicle.clearance_m, vehicle.alt_min_m)
    margin = 0.5 * math.sqrt(2.0) * grid.resolution_m + 1.0
    blocked = (flight_alt > vehicle.alt_max_m) | forbidden_mask(
        threats, east, north, flight_alt, margin_m=margin
    )
    climb = np.maximum(flight_alt - vehicle.cruise_alt_m, 0.0) / CLIMB_PENALTY_SCALE_M
    node_cost = 1.0 + threat_weight * exposure(threats, east, north, flight_alt)
    node_cost = node_cost + terrain_weight * climb
    nb = grid.neighbors() if neighbors is None else neighbors
    valid = nb >= 0
    safe_nb = np.where(valid, nb, 0)
    valid &= ~blocked[:, None] & ~blocked[safe_nb]
    edge = (
        0.5 * (node_cost[:, None] + node_cost[safe_nb]) * MOVE_LENGTH[None, :] * grid.resolution_m
    )
    edge = np.where(valid, edge, np.inf)
    return CostMap(grid, vehicle, nb, node_cost, blocked, flight_alt, edge)
