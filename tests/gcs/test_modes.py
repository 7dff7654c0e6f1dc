"""Mode tables checked against pymavlink's own (an independent source) and round trips."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from gcs.mavlink.modes import (
    ARDUPLANE_MODES,
    AUTOPILOT_ARDUPILOT,
    AUTOPILOT_PX4,
    PX4_MODES,
    mode_name,
    mode_names,
    mode_number,
    px4_custom_mode,
    px4_main_sub,
)

APM = AUTOPILOT_ARDUPILOT
PX4 = AUTOPILOT_PX4
CUSTOM = int(mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)

# pymavlink's PX4 names -> ours
PYMAVLINK_PX4_TO_OURS = {
    "MANUAL": "MANUAL",
    "STABILIZED": "STABILIZED",
    "ACRO": "ACRO",
    "RATTITUDE": "RATTITUDE",
    "ALTCTL": "ALTCTL",
    "POSCTL": "POSCTL",
    "LOITER": "AUTO.LOITER",
    "MISSION": "AUTO.MISSION",
    "RTL": "AUTO.RTL",
    "LAND": "AUTO.LAND",
    "RTGS": "AUTO.RTGS",
    "FOLLOWME": "AUTO.FOLLOW_TARGET",
    "OFFBOARD": "OFFBOARD",
    "TAKEOFF": "AUTO.TAKEOFF",
}


def test_arduplane_table_matches_pymavlink_by_number() -> None:
    assert {n: name for name, n in ARDUPLANE_MODES.items()} == dict(mavutil.mode_mapping_apm)


def test_arduplane_table_matches_pymavlink_for_fixed_wing_heartbeats() -> None:
    by_name = mavutil.mode_mapping_byname(mavlink2.MAV_TYPE_FIXED_WING)
    for name, number in by_name.items():
        assert mode_number(name, APM) == number
        assert mode_name(number, APM, CUSTOM) == name


@pytest.mark.parametrize(
    ("name", "number"),
    [("MANUAL", 0), ("CIRCLE", 1), ("FBWA", 5), ("AUTO", 10), ("RTL", 11), ("GUIDED", 15)],
)
def test_arduplane_known_numbers(name: str, number: int) -> None:
    assert mode_number(name, APM) == number


def test_px4_modes_match_pymavlink_px4_map() -> None:
    assert set(PYMAVLINK_PX4_TO_OURS) == set(mavutil.px4_map)
    for theirs, (_base, main, sub) in mavutil.px4_map.items():
        ours = PYMAVLINK_PX4_TO_OURS[theirs]
        packed = mode_number(ours, PX4)
        assert px4_main_sub(packed) == (main, sub)
        # pymavlink's short names are accepted too
        assert mode_number(theirs, PX4) == packed


def test_px4_mode_names_match_pymavlink_interpretation() -> None:
    for name, packed in PX4_MODES.items():
        assert mode_name(packed, PX4) == name
        theirs = mavutil.interpret_px4_mode(0, packed)
        if theirs != "UNKNOWN":
            ours = PYMAVLINK_PX4_TO_OURS[theirs]
            # pymavlink ignores the sub mode of non-AUTO main modes (POSCTL.ORBIT -> POSCTL)
            assert name == ours or (name.startswith(ours + ".") and not ours.startswith("AUTO"))


def test_px4_packing_is_main_shifted_16_and_sub_shifted_24() -> None:
    assert mode_number("AUTO.MISSION", PX4) == (4 << 16) | (4 << 24)
    assert mode_number("POSCTL", PX4) == 3 << 16
    assert px4_custom_mode(4, 5) == 0x05040000


def test_lookup_is_case_insensitive_and_strips_blanks() -> None:
    assert mode_number(" fbwa ", APM) == 5
    assert mode_number("auto.mission", PX4) == mode_number("AUTO.MISSION", PX4)
    assert mode_number("Fly_By_Wire_A", APM) == 5


def test_unknown_name_lists_valid_names() -> None:
    with pytest.raises(ValueError, match="valid modes: MANUAL, CIRCLE") as err:
        mode_number("HOVER", APM)
    assert "'HOVER'" in str(err.value)
    assert "GUIDED" in str(err.value)


def test_unknown_autopilot_is_a_value_error_naming_it() -> None:
    with pytest.raises(ValueError, match="MAV_AUTOPILOT_GENERIC"):
        mode_number("AUTO", int(mavlink2.MAV_AUTOPILOT_GENERIC))


@pytest.mark.parametrize(
    ("custom", "autopilot", "expected"),
    [
        (9, APM, "MODE(9)"),
        (99, APM, "MODE(99)"),
        ((4 << 16) | (77 << 24), PX4, f"MODE({(4 << 16) | (77 << 24)})"),
        (12345, PX4, "MODE(12345)"),
        (5, int(mavlink2.MAV_AUTOPILOT_GENERIC), "MODE(5)"),
    ],
)
def test_unknown_numbers_are_named_mode_n(custom: int, autopilot: int, expected: str) -> None:
    assert mode_name(custom, autopilot, CUSTOM) == expected


def test_px4_sub_mode_ignored_for_main_modes_without_sub_modes() -> None:
    assert mode_name(px4_custom_mode(7, 3), PX4) == "STABILIZED"


def test_custom_mode_flag_clear_means_custom_mode_is_meaningless() -> None:
    assert mode_name(10, APM, base_mode=0x80) == "BASE_MODE(0x80)"
    assert mode_name(10, APM, base_mode=0x81) == "AUTO"


@given(st.sampled_from(mode_names(APM)) | st.sampled_from(mode_names(PX4)))
def test_name_number_round_trip(name: str) -> None:
    autopilot = APM if name in ARDUPLANE_MODES else PX4
    assert mode_name(mode_number(name, autopilot), autopilot) == name
    assert mode_number(name.lower(), autopilot) == mode_number(name, autopilot)


@given(st.integers(0, 2**32 - 1), st.sampled_from([APM, PX4]))
def test_mode_name_never_raises_and_round_trips_when_known(custom: int, autopilot: int) -> None:
    name = mode_name(custom, autopilot)
    if not name.startswith("MODE("):
        number = mode_number(name, autopilot)
        # PX4 main modes without sub modes ignore the sub-mode byte
        assert number == custom or (autopilot == PX4 and number == custom & 0x00FF0000)
