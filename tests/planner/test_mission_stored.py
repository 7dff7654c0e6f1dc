"""What an autopilot gives back for a mission item, and comparisons made in that form.

Known answers follow ArduPilot's libraries/AP_Mission/AP_Mission.cpp
(mavlink_int_to_mission_cmd / mission_cmd_to_mavlink_int: the packed 15-byte command, the
Location with its altitude in int32 centimetres) and PX4's
src/modules/mavlink/mavlink_mission.cpp (format_mavlink_mission_item).
"""

from __future__ import annotations

import math
import struct
from dataclasses import replace

import pytest
from hypothesis import given
from hypothesis import strategies as st

from planner.mission import (
    MAV_CMD_DO_CHANGE_SPEED,
    MAV_CMD_NAV_LAND,
    MAV_CMD_NAV_LOITER_TURNS,
    MAV_CMD_NAV_TAKEOFF,
    MAV_CMD_NAV_WAYPOINT,
    MAV_FRAME_GLOBAL,
    MAV_FRAME_GLOBAL_INT,
    MAV_FRAME_GLOBAL_RELATIVE_ALT,
    MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
    MAV_FRAME_MISSION,
    Autopilot,
    Loiter,
    MissionItem,
    SpeedChange,
    Waypoint,
    ardupilot_alt_m,
    compile_mission,
    first_difference,
    items_equal,
    stored_alt_m,
    stored_item,
)


def _f32(v: float) -> float:
    return float(struct.unpack("<f", struct.pack("<f", v))[0])


def _centi(cm: int) -> float:
    """ArduPilot's ``alt * 0.01f`` for a stored altitude in centimetres."""
    return _f32(_f32(float(cm)) * _f32(0.01))


def _item(command: int, frame: int, z: float = 0.0, **params: float) -> MissionItem:
    p = {"param1": 0.0, "param2": 0.0, "param3": 0.0, "param4": 0.0, **params}
    return MissionItem(
        seq=1,
        frame=frame,
        command=command,
        current=0,
        autocontinue=1,
        x=-353632610,
        y=1491652300,
        z=z,
        **p,
    )


def test_ardupilot_gives_takeoff_back_in_its_relative_frame_and_whole_centimetres() -> None:
    # Seen on ArduPlane V4.7.0-dev: sent frame 6 z 827.496, read back frame 3 z 827.49.
    sent = _item(MAV_CMD_NAV_TAKEOFF, MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 827.496, param1=15.0)
    back = stored_item(sent, Autopilot.ARDUPILOT)
    assert back.frame == MAV_FRAME_GLOBAL_RELATIVE_ALT
    assert back.z == _centi(82749)
    assert (back.x, back.y) == (sent.x, sent.y)
    assert back.param1 == 15.0


def test_ardupilot_truncates_altitudes_towards_zero() -> None:
    assert stored_alt_m(100.019) == _centi(10001)
    assert stored_alt_m(-3.337) == _centi(-333)
    assert stored_alt_m(0.004) == 0.0
    # float32: 612.72 * 100.0f is 61271.996, kept as 61271 cm.
    assert stored_alt_m(612.72) == _centi(61271)


@given(st.floats(-499.0, 19_999.0, allow_nan=False))
def test_compiled_altitudes_are_kept_by_ardupilot_as_their_own_centimetre(z: float) -> None:
    sent = ardupilot_alt_m(z)
    ulp = abs(z) * 2.0**-23
    assert abs(sent - z) < 0.0101 + 8 * ulp
    assert stored_alt_m(sent) == pytest.approx(sent, abs=max(2e-4, 4 * ulp))
    assert stored_alt_m(sent) == stored_alt_m(z)


def test_ardupilot_gives_amsl_frames_back_as_global() -> None:
    for frame in (MAV_FRAME_GLOBAL, MAV_FRAME_GLOBAL_INT):
        back = stored_item(_item(MAV_CMD_NAV_WAYPOINT, frame, 612.5), Autopilot.ARDUPILOT)
        assert back.frame == MAV_FRAME_GLOBAL


def test_ardupilot_do_change_speed_comes_back_with_no_position_and_frame_zero() -> None:
    sent = replace(
        _item(MAV_CMD_DO_CHANGE_SPEED, MAV_FRAME_MISSION, param2=21.5, param3=-1.0), x=0, y=0
    )
    back = stored_item(sent, Autopilot.ARDUPILOT)
    assert (back.frame, back.x, back.y, back.z) == (MAV_FRAME_GLOBAL, 0, 0, 0.0)
    assert (back.param1, back.param2, back.param3, back.param4) == (0.0, 21.5, -1.0, 0.0)


def test_ardupilot_plane_waypoint_keeps_only_its_radii_as_bytes() -> None:
    sent = _item(MAV_CMD_NAV_WAYPOINT, MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 300.0)
    sent = replace(sent, param1=5.0, param2=300.7, param3=12.9, param4=45.0)
    back = stored_item(sent, Autopilot.ARDUPILOT)
    assert (back.param1, back.param2, back.param3, back.param4) == (0.0, 255.0, 12.0, 0.0)


def test_ardupilot_loiter_turns_keeps_turns_radius_and_exit_flag() -> None:
    sent = _item(MAV_CMD_NAV_LOITER_TURNS, MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 500.0)
    sent = replace(sent, param1=3.0, param2=7.0, param3=-1234.0, param4=1.0)
    back = stored_item(sent, Autopilot.ARDUPILOT)
    assert (back.param1, back.param2, back.param3, back.param4) == (3.0, 0.0, -1230.0, 1.0)


def test_ardupilot_land_gives_its_direction_back_as_plus_or_minus_one() -> None:
    back = stored_item(_item(MAV_CMD_NAV_LAND, MAV_FRAME_GLOBAL, 0.0), Autopilot.ARDUPILOT)
    assert back.param4 == 1.0


def test_px4_gives_global_frames_back_as_int_frames_and_drops_the_takeoff_pitch() -> None:
    sent = _item(MAV_CMD_NAV_TAKEOFF, MAV_FRAME_GLOBAL_RELATIVE_ALT, 827.496, param1=15.0)
    back = stored_item(sent, Autopilot.PX4)
    assert back.frame == MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
    assert back.z == _f32(827.496)
    assert back.param1 == 0.0
    amsl = stored_item(_item(MAV_CMD_NAV_WAYPOINT, MAV_FRAME_GLOBAL, 5.0), Autopilot.PX4)
    assert amsl.frame == MAV_FRAME_GLOBAL_INT


def test_autopilot_from_heartbeat() -> None:
    assert Autopilot.from_heartbeat(3) is Autopilot.ARDUPILOT
    assert Autopilot.from_heartbeat(12) is Autopilot.PX4
    assert Autopilot.from_heartbeat(0) is Autopilot.EXACT
    assert Autopilot.from_heartbeat(None) is Autopilot.UNKNOWN


def test_an_unknown_autopilot_may_give_items_back_in_any_known_form() -> None:
    sent = _paper_like_mission()
    got = _as_ardupilot_gives_it_back(sent)
    assert first_difference(sent, got, autopilot=Autopilot.EXACT, compare_home=False) == 1
    assert first_difference(sent, got, autopilot=Autopilot.UNKNOWN, compare_home=False) is None
    got[3] = replace(got[3], z=got[3].z + 0.5)
    assert first_difference(sent, got, autopilot=Autopilot.UNKNOWN, compare_home=False) == 3


def _paper_like_mission() -> list[MissionItem]:
    return compile_mission(
        home=Waypoint(-35.36, 149.16, 584.0),
        waypoints=[
            Waypoint(-35.35, 149.17, 1211.496),
            Waypoint(-35.34, 149.18, 1187.3333),
            Waypoint(-35.33, 149.19, 1100.0049),
        ],
        takeoff_alt_m=827.496,
        speeds=[SpeedChange(1, 21.5)],
        loiters=[Loiter(1, -35.345, 149.175, 1187.3333, 2, 250.0)],
        land=True,
    )


def _as_ardupilot_gives_it_back(items: list[MissionItem]) -> list[MissionItem]:
    """An independent rendering of the ArduPilot download: frame 3 for the relative NAV
    items, frame 0 and no position for DO items, float32 of whole centimetres, NAV_LAND's
    param4 as +1."""
    out = []
    for it in items:
        if it.command == MAV_CMD_DO_CHANGE_SPEED:
            out.append(replace(it, frame=0, x=0, y=0, z=0.0, param4=0.0))
            continue
        if it.command == MAV_CMD_NAV_LAND:
            it = replace(it, param4=1.0)  # the deepstall direction: -1 or 1
        frame = 3 if it.frame in (3, 6) else 0
        cm = int(_f32(_f32(it.z) * 100.0))
        out.append(replace(it, frame=frame, z=_centi(cm)))
    return out


def test_a_compiled_mission_verifies_against_what_ardupilot_gives_back() -> None:
    sent = _paper_like_mission()
    got = _as_ardupilot_gives_it_back(sent)
    assert not items_equal(sent, got, compare_home=False)  # not the same on the wire ...
    assert first_difference(sent, got, autopilot=Autopilot.ARDUPILOT, compare_home=False) is None
    assert items_equal(sent, got, compare_home=False, autopilot=Autopilot.ARDUPILOT)


def test_compiled_altitudes_are_what_ardupilot_keeps() -> None:
    for it in _paper_like_mission():
        assert stored_item(it, Autopilot.ARDUPILOT).z == pytest.approx(it.z, abs=2e-4)


@pytest.mark.parametrize(
    ("field", "value"),
    [("z", 1.5), ("x", 10), ("param2", 0.5), ("command", MAV_CMD_NAV_LAND)],
)
def test_first_difference_names_the_item_that_really_differs(field: str, value: float) -> None:
    sent = _paper_like_mission()
    got = _as_ardupilot_gives_it_back(sent)
    k = next(i for i, it in enumerate(sent) if it.command == MAV_CMD_DO_CHANGE_SPEED) + 1
    if field == "param2":
        k -= 1  # the speed itself
        got[k] = replace(got[k], param2=got[k].param2 + value)
    elif field == "command":
        got[k] = replace(got[k], command=int(value))
    else:
        got[k] = replace(got[k], **{field: getattr(got[k], field) + value})
    found = first_difference(sent, got, autopilot=Autopilot.ARDUPILOT, compare_home=False)
    assert found == k


def test_first_difference_of_a_shorter_read_back_is_where_it_stops() -> None:
    sent = _paper_like_mission()
    got = _as_ardupilot_gives_it_back(sent)[:-2]
    assert first_difference(sent, got, autopilot=Autopilot.ARDUPILOT) == len(got)


@given(st.floats(-499.0, 19_999.0, allow_nan=False))
def test_ardupilot_altitude_is_within_a_centimetre_and_never_further_from_zero(z: float) -> None:
    back = stored_alt_m(z)
    assert abs(back - z) < 0.0101 + abs(z) * 2.0**-21
    assert abs(back) <= abs(z) * (1.0 + 2.0**-22) + 1e-6
    assert math.isfinite(back)
