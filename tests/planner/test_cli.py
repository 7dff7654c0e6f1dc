from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml

from tests.planner.conftest import small_scenario

ROOT = Path(__file__).resolve().parents[2]


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "planner", *args],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )


def test_plan_paper_scenario_writes_the_contract_fields(tmp_path: Path) -> None:
    out = tmp_path / "plan.json"
    proc = run("plan", "scenarios/paper_three_uav.yaml", "--seed", "1", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(out.read_text())
    assert doc["elapsed_s"] > 0
    assert [v["id"] for v in doc["vehicles"]] == ["UAV1", "UAV2", "UAV3"]
    for v in doc["vehicles"]:
        assert v["length_m"] > 0 and v["cost"] <= 1.05 * v["optimal_cost"]
        assert v["cost"] >= v["optimal_cost"] - 1e-3
        wp = v["waypoints"]
        assert len(wp) >= 2 and set(wp[0]) >= {"lat_deg", "lon_deg", "alt_m"}
        assert 33.0 < wp[0]["lat_deg"] < 37.0 and 107.0 < wp[0]["lon_deg"] < 111.0
    png = tmp_path / "paths.png"
    proc = run("plot", str(out), "--out", str(png))
    assert proc.returncode == 0, proc.stderr
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _bad(tmp_path: Path, data: dict[str, Any]) -> str:
    f = tmp_path / "bad.yaml"
    f.write_text(yaml.safe_dump(data))
    return _bad_file(f)


def _bad_file(f: Path, command: str = "plan") -> str:
    out = f.with_name("p.json")
    proc = run(command, str(f), "--out", str(out))
    assert proc.returncode == 1, proc.stderr
    assert proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr  # one clear line, no traceback
    assert not out.exists()
    return lines[0]


def _nan_speed() -> bytes:
    data = small_scenario()
    data["vehicles"][1]["speed_max_m_s"] = float("nan")
    return yaml.safe_dump(data).encode()


def _named(arrival: dict[str, Any]) -> bytes:
    return yaml.safe_dump(small_scenario(arrival=arrival)).encode()


@pytest.mark.parametrize("command", ["plan", "schedule"])
@pytest.mark.parametrize(
    ("name", "content", "expected"),
    [
        (
            "s.yaml",
            b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\x00\x00",
            "s.yaml: not a text file (NUL byte at offset 8)",
        ),
        (
            "s.yaml",
            "name: café\n".encode("cp1252"),
            "s.yaml: not UTF-8 text (byte 0xe9 at offset 9)",
        ),
        (
            "s.yaml",
            b"name: x\narea:\n  origin: {lat_deg: 1\n  width_m: 3\n",
            "s.yaml: line 4, column 10: not valid YAML: expected ',' or '}'",
        ),
        ("s.json", b'{"name": "x",\n "area": }', "s.json: line 2, column 10: not valid JSON"),
        ("s.yaml", _nan_speed(), "s.yaml: vehicles[1].speed_max_m_s: not a number (NaN)"),
        (
            "s.yaml",
            _named({"kind": "spaced", "interval_s": 60, "order": ["B", "UAV9"]}),
            "s.yaml: arrival.order[1]: unknown vehicle 'UAV9'",
        ),
        (
            "s.yaml",
            _named(
                {
                    "kind": "windows",
                    "windows": [
                        {"vehicle": "A", "earliest_s": 0, "latest_s": 9000},
                        {"vehicle": "UAV9", "earliest_s": 0, "latest_s": 9000},
                    ],
                }
            ),
            "s.yaml: arrival.windows[1].vehicle: unknown vehicle 'UAV9'",
        ),
    ],
)
def test_bad_scenario_file_is_one_line(
    tmp_path: Path, command: str, name: str, content: bytes, expected: str
) -> None:
    f = tmp_path / name
    f.write_bytes(content)
    line = _bad_file(f, command)
    assert line.startswith(f"error: {f}: "), line  # the file is named
    assert line.startswith(f"error: {tmp_path}/{expected}"), line


def test_start_in_forbidden_zone_is_one_line(tmp_path: Path) -> None:
    data = small_scenario()
    data["vehicles"][0]["start"] = {"east_m": 20000, "north_m": 21000, "alt_m": 500}
    assert "vehicle A: start (20000, 21000) m is inside forbidden zone SAM" in _bad(tmp_path, data)


def test_unreachable_goal_is_one_line(tmp_path: Path) -> None:
    data = small_scenario()
    data["vehicles"][1]["goal"] = {"east_m": 31000, "north_m": 38000, "alt_m": 500}
    data["vehicles"][0]["goal"] = {"east_m": 39500, "north_m": 39500, "alt_m": 500}
    data["threats"].append(
        {
            "kind": "no_fly",
            "id": "RING",
            "polygon": [
                {"east_m": 33000, "north_m": 33000},
                {"east_m": 40000, "north_m": 33000},
                {"east_m": 40000, "north_m": 34000},
                {"east_m": 33000, "north_m": 34000},
            ],
        }
    )
    data["threats"].append(
        {
            "kind": "no_fly",
            "id": "RING2",
            "polygon": [
                {"east_m": 33000, "north_m": 33000},
                {"east_m": 34000, "north_m": 33000},
                {"east_m": 34000, "north_m": 40000},
                {"east_m": 33000, "north_m": 40000},
            ],
        }
    )
    msg = _bad(tmp_path, data)
    assert "vehicle A: goal unreachable" in msg


def test_vmin_above_vmax_is_one_line(tmp_path: Path) -> None:
    data = small_scenario()
    data["vehicles"][0]["speed_min_m_s"] = 35
    assert "vehicles[0]: speed_min_m_s 35 is above speed_max_m_s 28" in _bad(tmp_path, data)


def test_unknown_field_is_one_line(tmp_path: Path) -> None:
    data = small_scenario()
    data["area"]["colour"] = "blue"
    assert _bad(tmp_path, data).endswith("area.colour: unknown field")


def test_missing_terrain_tile_is_one_line(tmp_path: Path) -> None:
    (tmp_path / "tiles").mkdir()
    data = small_scenario(terrain={"kind": "srtm", "directory": "tiles"})
    msg = _bad(tmp_path, data)
    assert re.search(r"terrain tile N4[45]E007\.hgt not found in .*tiles", msg), msg


def test_missing_scenario_file_is_one_line(tmp_path: Path) -> None:
    proc = run("plan", str(tmp_path / "nope.yaml"), "--out", str(tmp_path / "p.json"))
    assert proc.returncode == 1
    assert proc.stderr.strip().endswith("cannot read scenario file (No such file or directory)")


@pytest.mark.parametrize(
    "args",
    [
        ["plan"],
        ["plan", "x.yaml", "--method", "greedy", "--out", "p"],
        ["schedule", "x.yaml"],
        ["schedule", "x.yaml", "--out", "s.json", "--allow-conflicts", "extra"],
    ],
)
def test_bad_arguments_exit_2(args: list[str]) -> None:
    assert run(*args).returncode == 2
