from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest
import yaml

from planner.errors import ScenarioError
from planner.scenario import Scenario, json_schema, load_scenario, parse_scenario
from tests.planner.conftest import small_scenario

ROOT = Path(__file__).resolve().parents[2]


def test_paper_scenario_matches_table_ii() -> None:
    s = load_scenario(ROOT / "scenarios" / "paper_three_uav.yaml")
    frame = s.frame()
    starts = {v.id: (*v.start.local(frame), v.start.alt_m) for v in s.vehicles}
    assert starts == {
        "UAV1": (100000.0, 160000.0, 1000.0),
        "UAV2": (130000.0, 60000.0, 1000.0),
        "UAV3": (130000.0, 240000.0, 1200.0),
    }
    speeds = {v.id: (v.speed_min_m_s, v.speed_max_m_s) for v in s.vehicles}
    assert speeds == {"UAV1": (20, 30), "UAV2": (20, 30), "UAV3": (15, 25)}
    assert (s.area.width_m, s.area.height_m) == (200000, 200000)
    popups = [t for t in s.threats if t.appears is not None]
    assert len(popups) == 1 and popups[0].appears is not None
    assert popups[0].appears.after_takeoff_of == "UAV1"
    assert popups[0].appears.delay_s == 1200
    assert {b.id for b in s.buffers} == {"B1", "B2", "B3"}


def _error(data: dict[str, Any]) -> str:
    with pytest.raises(ScenarioError) as info:
        parse_scenario(data, "s.yaml")
    return str(info.value)


def test_unknown_field_is_named() -> None:
    data = small_scenario()
    data["vehicles"][0]["colour"] = "red"
    assert _error(data) == "s.yaml: vehicles[0].colour: unknown field"


def test_vmin_above_vmax_is_named() -> None:
    data = small_scenario()
    data["vehicles"][1]["speed_min_m_s"] = 40
    msg = _error(data)
    assert msg.startswith("s.yaml: vehicles[1]: speed_min_m_s 40 is above speed_max_m_s 28")


@pytest.mark.parametrize(
    ("path", "value", "expected"),
    [
        (("separation_m",), -5, "separation_m"),
        (("area", "resolution_m"), 0, "area.resolution_m"),
        (("vehicles", 0, "min_turn_radius_m"), 0, "vehicles[0].min_turn_radius_m"),
        (("vehicles", 0, "start", "lat_deg"), 95, "vehicles[0].start"),
        (("arrival", "kind"), "sometime", "arrival"),
    ],
)
def test_impossible_values_name_the_field(path: tuple[Any, ...], value: Any, expected: str) -> None:
    data = small_scenario()
    node: Any = data
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    assert _error(data).startswith(f"s.yaml: {expected}")


def test_start_outside_area_is_refused() -> None:
    data = small_scenario()
    data["vehicles"][0]["start"]["east_m"] = 90000
    assert "vehicles[0] (A).start" in _error(data)


def test_duplicate_vehicle_ids_are_refused() -> None:
    data = small_scenario()
    data["vehicles"][1]["id"] = "A"
    assert "vehicle id 'A' is used twice" in _error(data)


def test_popup_must_name_a_known_vehicle() -> None:
    data = small_scenario()
    data["threats"][0]["appears"] = {"after_takeoff_of": "Z", "delay_s": 60}
    assert "unknown vehicle 'Z'" in _error(data)


def test_geographic_and_local_points_agree() -> None:
    data = small_scenario()
    s = parse_scenario(data)
    lat, lon = s.frame().to_geodetic(2000.0, 2000.0)
    data["vehicles"][0]["start"] = {"lat_deg": lat, "lon_deg": lon, "alt_m": 500}
    s2 = parse_scenario(data)
    e, n = s2.vehicles[0].start.local(s2.frame())
    assert abs(e - 2000.0) < 0.01 and abs(n - 2000.0) < 0.01


def test_yaml_and_json_load_alike(tmp_path: Path) -> None:
    data = small_scenario()
    (tmp_path / "a.yaml").write_text(yaml.safe_dump(data))
    (tmp_path / "a.json").write_text(json.dumps(data))
    assert load_scenario(tmp_path / "a.yaml") == load_scenario(tmp_path / "a.json")


def _load_error(path: Path) -> str:
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(f"{path}: ")
    return msg[len(f"{path}: ") :]


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("area: [unclosed\n", "line 2, column 1: not valid YAML: expected ',' or ']'"),
        (
            "name: x\narea:\n  origin: {lat_deg: 1\n  width_m: 3\n",
            "line 4, column 10: not valid YAML: expected ',' or '}', but got ':' "
            "(while parsing a flow mapping at line 3, column 11)",
        ),
        ("name: x\narea:\n\tfoo: 1\n", "line 3, column 1: not valid YAML: found character '\\t'"),
        ("name: x\n  area: 1\n", "line 2, column 7: not valid YAML: mapping values"),
        ("a: &x 1\nb: *y\n", "line 2, column 4: not valid YAML: found undefined alias 'y'"),
    ],
)
def test_yaml_syntax_error_names_line_and_column(tmp_path: Path, text: str, expected: str) -> None:
    (tmp_path / "bad.yaml").write_text(text)
    assert _load_error(tmp_path / "bad.yaml").startswith(expected)


def test_json_syntax_error_names_line_and_column(tmp_path: Path) -> None:
    (tmp_path / "bad.json").write_text('{"name": "x",\n "area": }\n')
    assert (
        _load_error(tmp_path / "bad.json") == "line 2, column 10: not valid JSON: Expecting value"
    )


def test_binary_file_is_not_a_text_file(tmp_path: Path) -> None:
    png = b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR" + bytes(range(256))
    (tmp_path / "s.yaml").write_bytes(png)
    assert _load_error(tmp_path / "s.yaml").startswith("not a text file (NUL byte at offset 8)")


def test_non_utf8_file_is_named(tmp_path: Path) -> None:
    (tmp_path / "s.yaml").write_bytes("name: café\n".encode("latin-1"))
    assert _load_error(tmp_path / "s.yaml").startswith("not UTF-8 text (byte 0xe9 at offset 9)")


def test_utf8_byte_order_mark_is_accepted(tmp_path: Path) -> None:
    (tmp_path / "s.json").write_bytes(b"\xef\xbb\xbf" + json.dumps(small_scenario()).encode())
    assert load_scenario(tmp_path / "s.json").name == "small"


@pytest.mark.parametrize(
    ("path", "expected"),
    [
        (("separation_m",), "separation_m"),
        (("vehicles", 0, "speed_max_m_s"), "vehicles[0].speed_max_m_s"),
        (("vehicles", 1, "start", "east_m"), "vehicles[1].start.east_m"),
        (("vehicles", 0, "alt_min_m"), "vehicles[0].alt_min_m"),
        (("vehicles", 0, "takeoff_window_s", 1), "vehicles[0].takeoff_window_s[1]"),
        (("threats", 0, "radius_m"), "threats[0].radius_m"),
        (("terrain", "elevation_m"), "terrain.elevation_m"),
    ],
)
def test_nan_is_not_a_number_naming_the_field(
    tmp_path: Path, path: tuple[Any, ...], expected: str
) -> None:
    data = small_scenario()
    node: Any = data
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = float("nan")
    # As a YAML file writes it (.nan), and as a string the model would otherwise convert.
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(data))
    assert ".nan" in (tmp_path / "s.yaml").read_text()
    assert _load_error(tmp_path / "s.yaml") == f"{expected}: not a number (NaN)"
    node[path[-1]] = "nan"
    assert _error(data) == f"s.yaml: {expected}: not a number (NaN)"


def test_infinity_is_not_a_finite_number() -> None:
    data = small_scenario()
    data["vehicles"][0]["max_range_m"] = math.inf
    assert _error(data) == "s.yaml: vehicles[0].max_range_m: not a finite number (inf)"


def _spaced(order: list[str]) -> dict[str, Any]:
    return small_scenario(arrival={"kind": "spaced", "interval_s": 60, "order": order})


def _windows(*vehicles: str) -> dict[str, Any]:
    windows = [{"vehicle": v, "earliest_s": 0, "latest_s": 9000} for v in vehicles]
    return small_scenario(arrival={"kind": "windows", "windows": windows})


def _waves(**fields: Any) -> dict[str, Any]:
    return small_scenario(arrival={"kind": "waves", "gap_s": 120, **fields})


@pytest.mark.parametrize(
    ("data", "expected"),
    [
        (_waves(groups=[["A"], ["Z"]]), "arrival.groups[1][0]: unknown vehicle 'Z'"),
        (_waves(groups=[["A", "B"], ["A"]]), "arrival.groups[1][0]: vehicle 'A' is named twice"),
        (
            _waves(groups=[["A"]]),
            "arrival.groups: vehicle 'B' missing (each vehicle flies in exactly one wave)",
        ),
        (_waves(sizes=[1, 2]), "arrival.sizes: the waves hold 3 vehicles, the team has 2"),
        (_spaced(["A", "Z"]), "arrival.order[1]: unknown vehicle 'Z'"),
        (_spaced(["A", "A"]), "arrival.order[1]: vehicle 'A' is named twice"),
        (
            _spaced(["B"]),
            "arrival.order: vehicle 'A' missing (the order names each vehicle exactly once)",
        ),
        (_windows("A", "Q"), "arrival.windows[1].vehicle: unknown vehicle 'Q'"),
        (_windows("B", "B"), "arrival.windows[1].vehicle: vehicle 'B' is named twice"),
        (
            _windows("A"),
            "arrival.windows: vehicle 'B' missing (each vehicle needs exactly one window)",
        ),
    ],
)
def test_arrival_vehicles_are_checked_naming_field_and_vehicle(
    data: dict[str, Any], expected: str
) -> None:
    assert _error(data) == f"s.yaml: {expected}"


def test_srtm_directory_is_relative_to_the_file(tmp_path: Path) -> None:
    data = small_scenario(terrain={"kind": "srtm", "directory": "tiles"})
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(data))
    s = load_scenario(tmp_path / "s.yaml")
    assert s.terrain.kind == "srtm"
    assert Path(s.terrain.directory) == (tmp_path / "tiles").resolve()


def test_published_schema_is_current() -> None:
    published = json.loads((ROOT / "docs" / "scenario.schema.json").read_text())
    assert published == json.loads(json.dumps(json_schema()))
    assert set(Scenario.model_fields) <= set(published["properties"])


def test_waves_need_groups_or_sizes_and_a_positive_gap() -> None:
    assert "either groups" in _error(_waves())
    assert "either groups" in _error(_waves(groups=[["A", "B"]], sizes=[2]))
    assert _error(_waves(gap_s=0, sizes=[2])).startswith("s.yaml: arrival")


def test_wave_offsets_follow_the_groups_or_the_soonest_arrivals() -> None:
    given = parse_scenario(_waves(groups=[["B"], ["A"]]))
    assert given.arrival_offsets_s() == {"B": 0.0, "A": 120.0}
    # By size: B (36 km... to its goal 35 km away) against A (49 km): B can arrive sooner.
    data = _waves(sizes=[1, 1])
    free = parse_scenario(data)
    a, b = data["vehicles"]
    dist = {
        v["id"]: math.hypot(
            v["goal"]["east_m"] - v["start"]["east_m"], v["goal"]["north_m"] - v["start"]["north_m"]
        )
        for v in (a, b)
    }
    first = min(dist, key=lambda k: dist[k])
    assert free.arrival_offsets_s()[first] == 0.0
    assert max(free.arrival_offsets_s().values()) == 120.0
