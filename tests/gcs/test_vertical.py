"""Vertical resolution (:mod:`gcs.coordination.vertical`) with a fake clock: two aircraft
head-on on one line at one height, which no speed can keep apart. The test works out, with
its own arithmetic, each aircraft's position and height second by second as commanded (the
tracks are straight lines, the climb and the return at the commanded rate) and their least
3-D distance; the mover's room (ceiling and floor) and its slot are checked alike."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gcs.coordination.resolution import Ahead, resolve
from gcs.coordination.vertical import Room, resolve_vertical

D_S = 500.0
LAYER_M = 300.0
RATE_M_S = 5.0
SPEED_M_S = 25.0
NOW_S = 1_000.0


def _ahead(vid: str, east0_m: float, heading_east: float, alt_m: float, slot_in_s: float) -> Ahead:
    """A vehicle at ``east0_m`` on the line north = 0, flying east (+1) or west (-1)."""
    s = np.array([0.0, 60_000.0])
    east = east0_m + heading_east * s
    return Ahead(
        vid, NOW_S, 0.0, SPEED_M_S, SPEED_M_S, 1.0, 16.0, 30.0, alt_m, s, east, np.zeros(2),
        slot_in_s,
    )  # fmt: skip


def _flown(east0_m: float, heading_east: float, t_s: np.ndarray) -> np.ndarray:
    return east0_m + heading_east * SPEED_M_S * (t_s - NOW_S)


def _height(alt_m: float, offset_m: float, start_s: float, until_s: float, t: float) -> float:
    """The commanded height at ``t``: away at the rate from ``start_s``, back from
    ``until_s`` (the test's own ramp)."""
    if t <= start_s:
        return alt_m
    up = min((t - start_s) * RATE_M_S, abs(offset_m))
    if t > until_s:
        up = max(up - (t - until_s) * RATE_M_S, 0.0)
    return alt_m + math.copysign(up, offset_m)


def _isa_eas2tas(h_m: float) -> float:
    """ISA troposphere: T = 288.15 - 0.0065 h; rho/rho0 = (T/T0)^4.2559; TAS/EAS =
    sqrt(rho0/rho)."""
    return 1.0 / math.sqrt(((288.15 - 0.0065 * h_m) / 288.15) ** 4.2559)


def test_a_head_on_pair_is_kept_apart_by_layers_and_the_mover_keeps_its_slot() -> None:
    # A flies east from 0, B west from 6 km, both at 1,000 m: they meet 120 s on.
    a = _ahead("A", 0.0, 1.0, 1_000.0, slot_in_s=900.0)
    b = _ahead("B", 6_000.0, -1.0, 1_000.0, slot_in_s=2_400.0)
    room = {"A": Room(3_000.0, 400.0), "B": Room(3_000.0, 400.0)}
    # No speed resolves a head-on meeting on one line.
    speed = resolve(a, b, now_s=NOW_S, separation_m=D_S, look_ahead_s=180.0)
    assert speed is None or not speed.keeps_separation
    v = resolve_vertical(
        a, b, now_s=NOW_S, separation_m=D_S, layer_m=LAYER_M, rate_m_s=RATE_M_S, room=room,
        look_ahead_s=180.0,
    )  # fmt: skip
    assert v is not None
    # The priority rule: B, with 2,400 s to its slot against A's 900 s, moves; at one height,
    # it climbs, by two layers (one, 300 m, is less than the 500 m they meet within).
    assert (v.vehicle, v.other, v.offset_m) == ("B", "A", 2 * LAYER_M)
    assert v.alt_m == 1_600.0 and v.unresolved_m == pytest.approx(0.0, abs=1.0)
    assert v.at_s == pytest.approx(NOW_S + 120.0, abs=1.0)
    # The test's own closest approach over the encounter as commanded, every 0.1 s.
    t = np.arange(NOW_S, NOW_S + 400.0, 0.1)
    ea, eb = _flown(0.0, 1.0, t), _flown(6_000.0, -1.0, t)
    zb = np.array([_height(1_000.0, v.offset_m, v.start_s, v.until_s, x) for x in t])
    d = np.sqrt((ea - eb) ** 2 + (1_000.0 - zb) ** 2)
    assert float(d.min()) >= D_S, float(d.min())
    assert float(d.min()) == pytest.approx(v.predicted_m, abs=5.0)
    # Within its room, and back on its profile once they are past (horizontally apart).
    assert room["B"].floor_m <= zb.min() and zb.max() <= room["B"].ceiling_m
    apart = t[np.abs(ea - eb) >= D_S]
    back_s = v.until_s + abs(v.offset_m) / RATE_M_S
    assert back_s < NOW_S + 400.0 and zb[t >= back_s].max() == pytest.approx(1_000.0)
    assert v.until_s >= apart[apart > v.at_s].min()
    # Its slot still made: higher, it flies faster over the ground at the same commanded
    # airspeed; what it gains meanwhile its arrival controller takes back over the rest of
    # the way with a fraction of its speed range (16-30 m/s).
    gained_m = sum(SPEED_M_S * (_isa_eas2tas(z) / _isa_eas2tas(1_000.0) - 1.0) * 0.1 for z in zb)
    left_s = b.horizon_s - (back_s - NOW_S)
    assert gained_m > 0.0 and gained_m < 0.1 * (SPEED_M_S - 16.0) * left_s


def test_the_higher_of_a_pair_climbs_and_one_with_no_room_above_descends() -> None:
    a = _ahead("A", 0.0, 1.0, 1_100.0, slot_in_s=2_000.0)  # 100 m above B
    b = _ahead("B", 6_000.0, -1.0, 1_000.0, slot_in_s=2_000.0)
    kw = {"now_s": NOW_S, "separation_m": D_S, "layer_m": LAYER_M, "rate_m_s": RATE_M_S}
    free = {"A": Room(3_000.0, 400.0), "B": Room(3_000.0, 400.0)}
    v = resolve_vertical(a, b, room=free, look_ahead_s=180.0, **kw)
    # Two layers either way keep 500 m (one, 400 m of height, does not), and each widens
    # the gap: the climb.
    assert v is not None and (v.vehicle, v.offset_m) == ("A", 2 * LAYER_M)
    capped = {"A": Room(1_200.0, 400.0), "B": Room(1_200.0, 400.0)}
    v = resolve_vertical(a, b, room=capped, look_ahead_s=180.0, **kw)
    # A cannot climb under a 1,200 m ceiling; B descends to its floor, 400 m.
    assert v is not None and (v.vehicle, v.offset_m, v.alt_m) == ("B", -2 * LAYER_M, 400.0)
    boxed = {"A": Room(1_200.0, 1_000.0), "B": Room(1_200.0, 900.0)}
    assert resolve_vertical(a, b, room=boxed, look_ahead_s=180.0, **kw) is None


def test_a_pair_that_keeps_its_separation_is_left_alone() -> None:
    a = _ahead("A", 0.0, 1.0, 1_000.0, slot_in_s=2_000.0)
    b = _ahead("B", 6_000.0, -1.0, 1_600.0, slot_in_s=2_000.0)  # 600 m above
    room = {"A": Room(3_000.0, 400.0), "B": Room(3_000.0, 400.0)}
    kw = {"now_s": NOW_S, "separation_m": D_S, "layer_m": LAYER_M, "rate_m_s": RATE_M_S}
    assert resolve_vertical(a, b, room=room, look_ahead_s=180.0, **kw) is None
