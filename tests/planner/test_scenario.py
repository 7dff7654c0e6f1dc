from __future__ import annotations

import json
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


def test_broken_yaml_is_one_line(tmp_path: Path) -> None:
    (tmp_path / "bad.yaml").write_text("area: [unclosed\n")
    with pytest.raises(ScenarioError) as info:
        load_scenario(tmp_path / "bad.yaml")
    assert "not valid YAML/JSON" in str(info.value) and "\n" not in str(info.value)


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
