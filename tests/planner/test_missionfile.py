"""Tests of planner.missionfile: QGC WPL 110 and QGroundControl .plan, checked against peers.

pymavlink's own waypoint loader (``mavwp``, which MAVProxy's ``wp load``/``wp save`` use) reads
what we write and writes what we read; MAVProxy's conversion to MISSION_ITEM_INT gets the same
integers; exported plans validate against a JSON Schema of QGroundControl's documented format
(tests/planner/data/qgc_plan.schema.json).
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import json
import math
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import jsonschema
import pytest
from hypothesis import given
from hypothesis import strategies as st

from planner import mission as m
from planner.mission import (
    INT32_UNSET,
    Loiter,
    MissionError,
    MissionItem,
    SpeedChange,
    Waypoint,
    compile_mission,
)
from planner.missionfile import (
    from_qgc_plan,
    from_wpl,
    read_mission_file,
    to_qgc_plan,
    to_wpl,
    write_mission_file,
)

DATA = Path(__file__).resolve().parent / "data"
PLAN_SCHEMA: dict[str, Any] = json.loads((DATA / "qgc_plan.schema.json").read_text())
HOME = Waypoint(-35.363261, 149.165230, 584.0)


def item(seq: int, frame: int, command: int, *p: float, current: int = 0) -> MissionItem:
    """An item from (p1, p2, p3, p4, x, y, z), autocontinue 1."""
    p1, p2, p3, p4, x, y, z = p
    return MissionItem(
        seq=seq, frame=frame, command=command, current=current, autocontinue=1,
        param1=float(p1), param2=float(p2), param3=float(p3), param4=float(p4),
        x=int(x), y=int(y), z=float(z),
    )  # fmt: skip


def key(items: list[MissionItem]) -> list[tuple[object, ...]]:
    """Items as tuples with floats as repr: exact, NaN equal to NaN, -0.0 unequal to 0.0."""
    return [
        tuple(repr(v) if isinstance(v, float) else v for v in dataclasses.astuple(it))
        for it in items
    ]


def sample_mission(**kw: Any) -> list[MissionItem]:
    args: dict[str, Any] = {
        "home": HOME,
        "waypoints": [
            Waypoint(-35.3547213, 149.1690214, 684.0),
            Waypoint(-35.3500546, 149.1752171, 704.25),
            Waypoint(-35.3412345, 149.1801239, 650.5),
        ],
        "takeoff_alt_m": 50.0,
        "speeds": [SpeedChange(0, 22.0), SpeedChange(2, 26.5)],
        "loiters": [Loiter(1, -35.3490001, 149.1760009, 704.25, turns=2, radius_m=120.0)],
        "land": True,
    }
    args.update(kw)
    return compile_mission(**args)


# --- strategies ------------------------------------------------------------------------------

_FRAMES = (0, 2, 3, 5, 6, 10, 11)
_params = st.floats(allow_nan=True, allow_infinity=False)


@st.composite
def _item(draw: st.DrawFn, seq: int, current: st.SearchStrategy[int]) -> MissionItem:
    frame = draw(st.sampled_from(_FRAMES))
    if frame == m.MAV_FRAME_MISSION:
        x = draw(st.integers(-(2**31), 2**31 - 1))
        y = draw(st.integers(-(2**31), 2**31 - 1))
    else:
        x = draw(st.integers(-900_000_000, 900_000_000) | st.just(INT32_UNSET))
        y = draw(st.integers(-1_800_000_000, 1_800_000_000) | st.just(INT32_UNSET))
    return MissionItem(
        seq=seq,
        frame=frame,
        command=draw(st.sampled_from((16, 17, 18, 19, 20, 21, 22, 178, 31, 183))),
        current=draw(current),
        autocontinue=draw(st.integers(0, 1)),
        param1=draw(_params),
        param2=draw(_params),
        param3=draw(_params),
        param4=draw(_params),
        x=x,
        y=y,
        z=draw(_params),
    )


@st.composite
def _home(draw: st.DrawFn, current: st.SearchStrategy[int]) -> MissionItem:
    return item(
        0, 0, 16, 0.0, 0.0, 0.0, 0.0,
        draw(st.integers(-900_000_000, 900_000_000)),
        draw(st.integers(-1_800_000_000, 1_800_000_000)),
        draw(st.floats(-500.0, 9000.0)),
        current=draw(current),
    )  # fmt: skip


@st.composite
def wpl_missions(draw: st.DrawFn) -> list[MissionItem]:
    n = draw(st.integers(0, 8))
    bit = st.integers(0, 1)
    return [draw(_home(bit)), *(draw(_item(k, bit)) for k in range(1, n + 1))]


@st.composite
def plan_missions(draw: st.DrawFn) -> list[MissionItem]:
    n = draw(st.integers(0, 8))
    zero = st.just(0)
    return [draw(_home(zero)), *(draw(_item(k, zero)) for k in range(1, n + 1))]


# --- WPL 110 ---------------------------------------------------------------------------------


def test_wpl_text_known_answer() -> None:
    items = compile_mission(
        home=HOME,
        waypoints=[Waypoint(-35.36, 149.17, 700.0)],
        takeoff_alt_m=60.0,
        speeds=[SpeedChange(0, 22.0)],
    )
    assert to_wpl(items) == (
        "QGC WPL 110\n"
        "0\t0\t0\t16\t0.0\t0.0\t0.0\t0.0\t-35.36326101\t149.16523001\t584.0\t1\n"
        "1\t0\t6\t22\t15.0\t0.0\t0.0\t0.0\t-35.36326101\t149.16523001\t60.0\t1\n"
        "2\t0\t2\t178\t0.0\t22.0\t-1.0\t0.0\t0.00000000\t0.00000000\t0.0\t1\n"
        "3\t0\t6\t16\t0.0\t0.0\t0.0\t0.0\t-35.36000001\t149.17000001\t116.0\t1\n"
    )


@given(wpl_missions())
def test_wpl_round_trip_is_exact(items: list[MissionItem]) -> None:
    text = to_wpl(items)
    assert key(from_wpl(text)) == key(items)
    assert to_wpl(from_wpl(text)) == text


@given(st.integers(-1_800_000_000, 1_800_000_000))
def test_degrees_text_gives_y_back_to_rounding_and_truncating_readers(y: int) -> None:
    item_ = item(1, m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 16, 0, 0, 0, 0, 0, y, 0.0)
    lon_text = to_wpl([item(0, 0, 16, 0, 0, 0, 0, 0, 0, 0.0), item_]).splitlines()[2].split()[9]
    lon = float(lon_text)
    assert len(lon_text.split(".")[1]) == 8
    assert round(lon * 1e7) == y  # this module
    assert int(lon * 1e7) == y  # QGroundControl's and MAVProxy's uploads truncate
    assert abs(lon - y * 1e-7) < 1.5e-8


def test_reads_a_mission_planner_file_with_crlf_and_full_precision_degrees() -> None:
    text = (
        "QGC WPL 110\r\n"
        "0\t1\t0\t16\t0\t0\t0\t0\t-35.3632621765137\t149.165237426758\t584.090026855469\t1\r\n"
        "1\t0\t3\t22\t15.000000\t0.000000\t0.000000\t0.000000\t0.000000\t0.000000\t50.000000\t1\r\n"
        "2\t0\t3\t178\t0\t22\t-1\t0\t0\t0\t0\t1\r\n"
        "3\t0\t3\t16\t0\t0\t0\t0\t-35.3547213\t149.1690214\t100\t1\r\n"
    )
    assert key(from_wpl(text)) == key(
        [
            item(0, 0, 16, 0, 0, 0, 0, -353632622, 1491652374, 584.090026855469, current=1),
            item(1, 3, 22, 15.0, 0, 0, 0, 0, 0, 50.0),
            item(2, 3, 178, 0, 22.0, -1.0, 0, 0, 0, 0.0),
            item(3, 3, 16, 0, 0, 0, 0, -353547213, 1491690214, 100.0),
        ]
    )


def test_reads_the_mavlink_docs_example_with_spaces_and_an_old_home_command() -> None:
    text = (
        "QGC WPL 110\n"
        "0 1 0 0 0.149999999999999994 0 0 0 8.54800000000000004 47.3759999999999977 550 1\n"
        "\n"
        "# a comment, as pymavlink allows\n"
        "1 0 0 16 0.149999999999999994 0 0 0 8.54800000000000004 47.3759999999999977 550 1\n"
    )
    items = from_wpl(text)
    assert [(it.seq, it.command, it.param1, it.x, it.y, it.z) for it in items] == [
        (0, 16, 0.15, 85480000, 473760000, 550.0),
        (1, 16, 0.15, 85480000, 473760000, 550.0),
    ]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("QGC WPL 120\n", "m.txt: line 1: header 'QGC WPL 120' is not 'QGC WPL 110'"),
        ("", "m.txt: line 1: header '' is not 'QGC WPL 110'"),
        (
            "QGC WPL 110\n0\t0\t0\t16\t0\t0\t0\t0\t1\t2\t3\n",
            "m.txt: line 2: 11 fields, expected 12 (seq current frame command param1 param2 "
            "param3 param4 lat lon alt autocontinue)",
        ),
        (
            "QGC WPL 110\n0\t0\t0\t16\t0\t0\t0\t0\t1\t2\t3\t1\n"
            "2\t0\t3\t16\t0\t0\t0\t0\t1\t2\t3\t1\n",
            "m.txt: line 3: seq 2 is out of order (expected 1)",
        ),
        (
            "QGC WPL 110\n0\t0\tthree\t16\t0\t0\t0\t0\t1\t2\t3\t1\n",
            "m.txt: line 2: frame 'three' is not an integer",
        ),
        (
            "QGC WPL 110\n0\t2\t0\t16\t0\t0\t0\t0\t1\t2\t3\t1\n",
            "m.txt: line 2: current 2 is outside [0, 1]",
        ),
        (
            "QGC WPL 110\n0\t0\t0\t16\t0\tx\t0\t0\t1\t2\t3\t1\n",
            "m.txt: line 2: param2 'x' is not a number",
        ),
        (
            "QGC WPL 110\n0\t0\t0\t16\t0\t0\t0\t0\t91.5\t2\t3\t1\n",
            "m.txt: line 2: lat 91.5 is outside [-90, 90]",
        ),
        (
            "QGC WPL 110\n0\t0\t0\t16\t0\t0\t0\t0\t1\t2\tinf\t1\n",
            "m.txt: line 2: alt 'inf' is not finite",
        ),
        (
            "QGC WPL 110\n0\t0\t2\t178\t0\t0\t0\t0\t0.5\t0\t0\t1\n",
            "m.txt: line 2: lat 0.5 must be an int32 in frame 2 (MAV_FRAME_MISSION)",
        ),
    ],
)
def test_bad_wpl_errors_name_the_line_and_field(text: str, message: str) -> None:
    with pytest.raises(MissionError) as info:
        from_wpl(text, source="m.txt")
    assert str(info.value) == message


@pytest.mark.parametrize(
    ("items", "message"),
    [
        ([], "WPL: no items; item 0 (home) is required"),
        (
            [item(0, 0, 16, 0, 0, 0, 0, 0, 0, 0.0), item(2, 3, 16, 0, 0, 0, 0, 0, 0, 0.0)],
            "item 1: seq 2 does not match its position 1",
        ),
        (
            [item(0, 3, 22, 0, 0, 0, 0, 0, 0, 0.0)],
            "item 0: command 22 is not home (NAV_WAYPOINT 16)",
        ),
        (
            [item(0, 0, 16, 0, 0, 0, 0, 0, 0, 0.0), item(1, 3, 16, math.inf, 0, 0, 0, 0, 0, 0.0)],
            "item 1: param1 inf is not finite",
        ),
        (
            [dataclasses.replace(item(0, 0, 16, 0, 0, 0, 0, 0, 0, 0.0), mission_type=1)],
            "item 0: mission_type 1 cannot be stored in a WPL file (missions only)",
        ),
        (
            [
                item(0, 0, 16, 0, 0, 0, 0, 0, 0, 0.0),
                item(1, 6, 16, 0, 0, 0, 0, 950_000_000, 0, 0.0),
            ],
            "item 1: x 950000000 is outside [-900000000, 900000000] (+-90 deg)",
        ),
        (
            [item(0, 0, 16, 0, 0, 0, 0, 0, 0, 0.0, current=2)],
            "item 0: current 2 is outside [0, 1]",
        ),
    ],
)
def test_unwritable_missions_are_refused_by_to_wpl(items: list[MissionItem], message: str) -> None:
    with pytest.raises(MissionError) as info:
        to_wpl(items)
    assert str(info.value) == message


# --- pymavlink's waypoint loader and MAVProxy ---------------------------------------------------


@contextlib.contextmanager
def _mavutil_wire(version: int) -> Iterator[Any]:
    """pymavlink.mavutil with its ardupilotmega dialect for one wire version, then restored.

    mavutil picks MAVLink 1 or 2 from the MAVLINK20 environment variable; MAVProxy sets it.
    """
    from pymavlink import mavutil

    saved = os.environ.get("MAVLINK20")
    if version == 2:
        os.environ["MAVLINK20"] = "1"
    else:
        os.environ.pop("MAVLINK20", None)
    mavutil.set_dialect("ardupilotmega")
    try:
        yield mavutil
    finally:
        if saved is None:
            os.environ.pop("MAVLINK20", None)
        else:
            os.environ["MAVLINK20"] = saved
        mavutil.set_dialect("ardupilotmega")


@pytest.fixture(params=[1, 2], ids=["mavlink1", "mavlink2"])
def mavutil(request: pytest.FixtureRequest) -> Iterator[Any]:
    with _mavutil_wire(request.param) as mu:
        yield mu


def test_mavwp_loads_our_wpl_to_the_same_items(mavutil: Any, tmp_path: Path) -> None:
    from pymavlink import mavwp

    items = sample_mission()
    path = tmp_path / "sample.waypoints"
    write_mission_file(path, items)
    loader = mavwp.MAVWPLoader()
    assert loader.load(str(path)) == len(items)
    for it in items:
        w = loader.wp(it.seq)
        assert (w.seq, w.frame, w.command, w.current, w.autocontinue) == (
            it.seq,
            it.frame,
            it.command,
            it.current,
            it.autocontinue,
        )
        assert (w.param1, w.param2, w.param3, w.param4, w.z) == (
            it.param1,
            it.param2,
            it.param3,
            it.param4,
            it.z,
        )
        assert abs(w.x - it.lat_deg) <= 1e-7 and abs(w.y - it.lon_deg) <= 1e-7
        assert (int(w.x * 1e7), int(w.y * 1e7)) == (it.x, it.y)


def test_mavproxy_converts_our_wpl_to_the_same_mission_item_ints(tmp_path: Path) -> None:
    """MAVProxy's ``wp load``: mavwp reads the file, then MISSION_ITEM -> MISSION_ITEM_INT."""
    from MAVProxy.modules.lib.mission_item_protocol import MissionItemProtocolModule
    from pymavlink import mavwp

    class _Module:  # the two methods need nothing else of a running MAVProxy module
        def has_location(self, cmd_id: int) -> bool:
            return bool(MissionItemProtocolModule.has_location(self, cmd_id))

    items = sample_mission()
    path = tmp_path / "sample.txt"
    write_mission_file(path, items)
    with _mavutil_wire(2):  # mavproxy.py runs with MAVLink 2
        loader = mavwp.MAVWPLoader()
        loader.load(str(path))
        sent = [
            MissionItemProtocolModule.wp_to_mission_item_int(_Module(), loader.wp(k))
            for k in range(loader.count())
        ]
    back = [
        MissionItem(**{f.name: getattr(msg, f.name) for f in dataclasses.fields(MissionItem)})
        for msg in sent
    ]
    assert key(back) == key(items)


def _mavwp_saved(mavutil: Any, items: list[MissionItem], path: Path) -> None:
    from pymavlink import mavwp

    loader = mavwp.MAVWPLoader()
    extra = [0] if mavutil.mavlink20() else []
    for it in items:
        loader.add(
            mavutil.mavlink.MAVLink_mission_item_message(
                0, 0, it.seq, it.frame, it.command, it.current, it.autocontinue,
                it.param1, it.param2, it.param3, it.param4, it.lat_deg, it.lon_deg, it.z, *extra,
            )
        )  # fmt: skip
    loader.save(str(path))


def test_we_read_mavwp_saved_files_to_the_same_items(mavutil: Any, tmp_path: Path) -> None:
    # mavwp (MAVProxy's "wp save") prints every number with %f: 6 decimals. A mission on a
    # 1e-6 deg grid with altitudes in quarter metres comes back exactly; others to 1e-6 deg.
    home = Waypoint(-35.363261, 149.16523, 584.0)
    wps = [Waypoint(-35.354721, 149.169021, 684.0), Waypoint(-35.350054, 149.175217, 704.25)]
    grid = compile_mission(
        home=home,
        waypoints=wps,
        takeoff_alt_m=50.0,
        speeds=[SpeedChange(1, 26.5)],
        loiters=[Loiter(0, -35.35, 149.17, 690.5, turns=3, radius_m=90.0, clockwise=False)],
    )
    path = tmp_path / "grid.waypoints"
    _mavwp_saved(mavutil, grid, path)
    assert key(read_mission_file(path)) == key(grid)

    items = sample_mission()
    _mavwp_saved(mavutil, items, path)
    back = read_mission_file(path)
    assert len(back) == len(items)
    for a, b in zip(items, back, strict=True):
        assert (a.seq, a.frame, a.command, a.current, a.autocontinue) == (
            b.seq,
            b.frame,
            b.command,
            b.current,
            b.autocontinue,
        )
        assert abs(a.x - b.x) <= 5 and abs(a.y - b.y) <= 5  # 0.5e-6 deg
        assert b.z == pytest.approx(a.z, abs=5e-7)


# --- QGroundControl .plan --------------------------------------------------------------------

QGC_WRITTEN_PLAN = """
{
    "fileType": "Plan",
    "geoFence": {
        "circles": [
        ],
        "polygons": [
        ],
        "version": 2
    },
    "groundStation": "QGroundControl",
    "mission": {
        "cruiseSpeed": 22,
        "firmwareType": 3,
        "globalPlanAltitudeMode": 1,
        "hoverSpeed": 5,
        "items": [
            {
                "AMSLAltAboveTerrain": null,
                "Altitude": 50,
                "AltitudeMode": 1,
                "autoContinue": true,
                "command": 22,
                "doJumpId": 1,
                "frame": 3,
                "params": [15, 0, 0, null, -35.3598793, 149.1624131, 50],
                "type": "SimpleItem"
            },
            {
                "autoContinue": true,
                "command": 178,
                "doJumpId": 2,
                "frame": 2,
                "params": [0, 22, -1, 0, 0, 0, 0],
                "type": "SimpleItem"
            },
            {
                "AMSLAltAboveTerrain": null,
                "Altitude": 100,
                "AltitudeMode": 1,
                "autoContinue": true,
                "command": 16,
                "doJumpId": 3,
                "frame": 3,
                "params": [0, 0, 0, null, -35.3547213, 149.1690214, 100],
                "type": "SimpleItem"
            },
            {
                "AMSLAltAboveTerrain": null,
                "Altitude": 120,
                "AltitudeMode": 1,
                "autoContinue": true,
                "command": 18,
                "doJumpId": 4,
                "frame": 3,
                "params": [2, 0, 80, 1, -35.3500546, 149.1752171, 120],
                "type": "SimpleItem"
            },
            {
                "autoContinue": true,
                "command": 20,
                "doJumpId": 5,
                "frame": 2,
                "params": [0, 0, 0, 0, 0, 0, 0],
                "type": "SimpleItem"
            }
        ],
        "plannedHomePosition": [-35.3632621, 149.1652374, 584.09],
        "vehicleType": 1,
        "version": 2
    },
    "rallyPoints": {
        "points": [
        ],
        "version": 2
    },
    "version": 1
}
"""
NAN = math.nan
QGC_WRITTEN_ITEMS = [
    item(0, 0, 16, 0, 0, 0, 0, -353632621, 1491652374, 584.09),
    item(1, 3, 22, 15.0, 0, 0, NAN, -353598793, 1491624131, 50.0),
    item(2, 2, 178, 0, 22.0, -1.0, 0, 0, 0, 0.0),
    item(3, 3, 16, 0, 0, 0, NAN, -353547213, 1491690214, 100.0),
    item(4, 3, 18, 2.0, 0, 80.0, 1.0, -353500546, 1491752171, 120.0),
    item(5, 2, 20, 0, 0, 0, 0, 0, 0, 0.0),
]


def _validate(doc: dict[str, Any]) -> None:
    jsonschema.Draft202012Validator(PLAN_SCHEMA).validate(doc)


def test_plan_schema_is_a_valid_schema_that_rejects_bad_plans() -> None:
    jsonschema.Draft202012Validator.check_schema(PLAN_SCHEMA)
    doc = to_qgc_plan(sample_mission())
    _validate(doc)
    for path, value in [
        (("fileType",), "Mission"),
        (("mission", "items", 0, "params"), [0, 0, 0, 0, 0, 0]),
        (("mission", "items", 0, "autoContinue"), 1),
        (("mission", "plannedHomePosition"), [0, 0]),
        (("mission", "items", 0, "colour"), "red"),
    ]:
        bad = copy.deepcopy(doc)
        target: Any = bad
        for part in path[:-1]:
            target = target[part]
        target[path[-1]] = value
        with pytest.raises(jsonschema.ValidationError):
            _validate(bad)
    bad = copy.deepcopy(doc)
    del bad["mission"]["items"][0]["AltitudeMode"]
    with pytest.raises(jsonschema.ValidationError, match="AltitudeMode"):
        _validate(bad)


def test_exported_plan_validates_and_has_qgc_fields() -> None:
    items = sample_mission()
    doc = to_qgc_plan(items)
    _validate(doc)
    mission = doc["mission"]
    assert (mission["firmwareType"], mission["vehicleType"], mission["cruiseSpeed"]) == (3, 1, 22.0)
    assert mission["globalPlanAltitudeMode"] == 1
    assert mission["plannedHomePosition"] == [-35.36326101, 149.16523001, 584.0]
    assert [it["doJumpId"] for it in mission["items"]] == list(range(1, len(items)))
    takeoff, speed = mission["items"][0], mission["items"][1]
    assert takeoff["command"] == 22 and takeoff["Altitude"] == 50.0 and takeoff["AltitudeMode"] == 1
    assert speed["command"] == 178 and "Altitude" not in speed
    assert speed["params"] == [0.0, 22.0, -1.0, 0.0, 0.0, 0.0, 0.0]
    assert doc["geoFence"] == {"circles": [], "polygons": [], "version": 2}
    assert doc["rallyPoints"] == {"points": [], "version": 2}


@given(plan_missions())
def test_plan_round_trip_is_exact(items: list[MissionItem]) -> None:
    doc = to_qgc_plan(items)
    _validate(doc)
    text = json.dumps(doc, allow_nan=False)
    assert key(from_qgc_plan(json.loads(text))) == key(items)


def test_plan_file_round_trip_and_strict_json(tmp_path: Path) -> None:
    items = sample_mission(frame=m.MAV_FRAME_GLOBAL_RELATIVE_ALT)
    nan_yaw = [
        dataclasses.replace(it, param4=NAN) if it.command == 16 and it.seq else it for it in items
    ]
    path = tmp_path / "sample.plan"
    write_mission_file(path, nan_yaw)

    def no_constants(name: str) -> None:
        raise AssertionError(f"{name} in a .plan")

    doc = json.loads(path.read_text(), parse_constant=no_constants)
    _validate(doc)
    assert key(read_mission_file(path)) == key(nan_yaw)


def test_imports_a_plan_as_qgc_writes_it() -> None:
    doc = json.loads(QGC_WRITTEN_PLAN)
    _validate(doc)
    items = from_qgc_plan(doc)
    assert key(items) == key(QGC_WRITTEN_ITEMS)
    assert key(from_qgc_plan(to_qgc_plan(items))) == key(items)
    assert key(from_wpl(to_wpl(items))) == key(items)


def _broken(path: tuple[str | int, ...], value: Any = None, *, delete: bool = False) -> Any:
    doc = json.loads(QGC_WRITTEN_PLAN)
    target: Any = doc
    for part in path[:-1]:
        target = target[part]
    if delete:
        del target[path[-1]]
    else:
        target[path[-1]] = value
    return doc


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        (_broken(("mission",), delete=True), "f.plan: mission: missing"),
        (
            _broken(("mission", "items", 2, "params"), [0, 0, 0, 0, -35.35, 149.16]),
            "f.plan: mission.items[2].params: 6 values, expected 7 (param1-4, lat, lon, alt)",
        ),
        (_broken(("fileType",), "Mission"), "f.plan: fileType: 'Mission' is not 'Plan'"),
        (_broken(("version",), 2), "f.plan: version: 2 is not supported (expected 1)"),
        (
            _broken(("mission", "version"), 1),
            "f.plan: mission.version: 1 is not supported (expected 2)",
        ),
        (
            _broken(("mission", "plannedHomePosition"), [1.0, 2.0]),
            "f.plan: mission.plannedHomePosition: [1.0, 2.0] is not [lat_deg, lon_deg, alt_m]",
        ),
        (
            _broken(("mission", "items", 0, "command"), "takeoff"),
            "f.plan: mission.items[0].command: 'takeoff' is not an integer",
        ),
        (
            _broken(("mission", "items", 1, "autoContinue"), 1),
            "f.plan: mission.items[1].autoContinue: 1 is not true or false",
        ),
        (
            _broken(("mission", "items", 3, "frame"), delete=True),
            "f.plan: mission.items[3].frame: missing",
        ),
        (
            _broken(("mission", "items", 2, "params", 4), 123.0),
            "f.plan: mission.items[2].params[4]: lat 123.0 is outside [-90, 90]",
        ),
        (
            _broken(("mission", "items", 2, "params", 1), "0"),
            "f.plan: mission.items[2].params[1]: '0' is not a number or null",
        ),
        (
            _broken(("mission", "items", 4), {"type": "ComplexItem", "complexItemType": "survey"}),
            "f.plan: mission.items[4]: ComplexItem 'survey' is not supported (save the plan as "
            "simple items, or export a .waypoints file from QGC)",
        ),
        (
            _broken(("geoFence", "polygons"), [{"inclusion": True, "polygon": []}]),
            "f.plan: geoFence.polygons: not empty; only the mission of a plan is read (remove "
            "the fence/rally points or upload them separately)",
        ),
        ([1, 2], "f.plan: top level: is not a JSON object"),
    ],
)
def test_malformed_plans_name_the_field(doc: Any, message: str) -> None:
    with pytest.raises(MissionError) as info:
        from_qgc_plan(doc, source="f.plan")
    assert str(info.value) == message


def test_plan_export_needs_an_amsl_home() -> None:
    items = sample_mission()
    relative_home = [dataclasses.replace(items[0], frame=3), *items[1:]]
    with pytest.raises(MissionError, match=r"^item 0 \(home\): frame 3 is not AMSL \(0 or 5\)"):
        to_qgc_plan(relative_home)


def test_plan_export_keeps_home_position_only_and_drops_current() -> None:
    items = sample_mission()
    planner_home = [dataclasses.replace(items[0], current=1), *items[1:]]
    assert key(from_qgc_plan(to_qgc_plan(planner_home))) == key(items)


def test_cruise_speed_default_and_override() -> None:
    assert to_qgc_plan(sample_mission(speeds=[]))["mission"]["cruiseSpeed"] == 15.0
    assert to_qgc_plan(sample_mission(), cruise_speed_m_s=24.0)["mission"]["cruiseSpeed"] == 24.0


# --- files -----------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["m.plan", "m.PLAN", "m.waypoints", "m.wpl", "m.txt"])
def test_mission_files_round_trip_by_extension(tmp_path: Path, name: str) -> None:
    items = sample_mission()
    path = tmp_path / name
    write_mission_file(path, items)
    head = path.read_text().splitlines()[0]
    assert head == ("{" if name.lower().endswith(".plan") else "QGC WPL 110")
    assert key(read_mission_file(path)) == key(items)


def test_file_errors_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(MissionError, match=r"m\.kml: unknown mission file extension '\.kml'"):
        write_mission_file(tmp_path / "m.kml", sample_mission())
    with pytest.raises(MissionError, match=r"missing\.plan: cannot read: No such file"):
        read_mission_file(tmp_path / "missing.plan")
    bad = tmp_path / "bad.plan"
    bad.write_text('{\n  "fileType": "Plan",\n  "version": 1,,\n}\n')
    with pytest.raises(MissionError, match=r"bad\.plan: line 3: invalid JSON: "):
        read_mission_file(bad)
    wpl = tmp_path / "bad.waypoints"
    wpl.write_text("QGC WPL 110\n0\t0\t0\t16\t0\t0\t0\t0\t1\t2\n")
    with pytest.raises(MissionError, match=r"bad\.waypoints: line 2: 10 fields, expected 12"):
        read_mission_file(wpl)
    binary = tmp_path / "bin.wpl"
    binary.write_bytes(b"QGC WPL 110\n\xff\xfe\n")
    with pytest.raises(MissionError, match=r"bin\.wpl: byte 12: not UTF-8 text"):
        read_mission_file(binary)
