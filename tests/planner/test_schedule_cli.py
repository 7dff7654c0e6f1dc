"""``python -m planner schedule`` and ``export``: contract fields and the mission round trip."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from planner.__main__ import main
from planner.mission import MAV_CMD_DO_CHANGE_SPEED, MAV_CMD_NAV_LOITER_TURNS, items_equal
from planner.missionfile import read_mission_file
from planner.schedulefile import mission_from_json
from tests.planner.conftest import small_scenario

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def schedule_doc(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:  # type: ignore[type-arg]
    out = tmp_path_factory.mktemp("sched") / "schedule.json"
    png = out.with_name("speeds.png")
    scenario = ROOT / "scenarios" / "paper_three_uav.yaml"
    args = ["schedule", str(scenario), "--popup", "--seed", "1", "--out", str(out)]
    assert main([*args, "--plot", str(png)]) == 0
    assert png.stat().st_size > 10_000
    return out, json.loads(out.read_text())


def test_contract_fields(schedule_doc: tuple[Path, dict]) -> None:  # type: ignore[type-arg]
    _, doc = schedule_doc
    for key in ("required_arrival_s", "separation_required_m", "min_separation_m", "adjustments"):
        assert key in doc
    assert doc["min_separation_m"] >= doc["separation_required_m"]
    assert {a["strategy"] for a in doc["adjustments"]} == {"takeoff_delay", "speed", "loiter"}
    for a in doc["adjustments"]:
        assert {"time_s", "vehicle", "strategy", "value"} <= set(a)
    assert [v["id"] for v in doc["vehicles"]] == ["UAV1", "UAV2", "UAV3"]
    for v in doc["vehicles"]:
        assert abs(v["arrival_s"] - doc["required_arrival_s"]) < 0.1
        for leg in v["legs"]:
            assert v["speed_min_m_s"] <= leg["speed_m_s"] <= v["speed_max_m_s"]
        for lo in v["loiters"]:
            assert {"turns", "radius_m", "lat_deg", "lon_deg"} <= set(lo)
        assert "takeoff_s" in v


@pytest.mark.parametrize("fmt, ext", [("qgc", ".plan"), ("wpl", ".waypoints")])
def test_export_round_trip(
    schedule_doc: tuple[Path, dict],  # type: ignore[type-arg]
    tmp_path: Path,
    fmt: str,
    ext: str,
) -> None:
    path, doc = schedule_doc
    out = tmp_path / f"uav3{ext}"
    assert main(["export", str(path), "--vehicle", "UAV3", "--format", fmt, "--out", str(out)]) == 0
    items = read_mission_file(out)
    assert items_equal(items, mission_from_json(doc, "UAV3"))
    commands = [it.command for it in items]
    assert MAV_CMD_NAV_LOITER_TURNS in commands
    speeds = {it.param2 for it in items if it.command == MAV_CMD_DO_CHANGE_SPEED}
    assert speeds == {
        leg["speed_m_s"] for leg in next(v for v in doc["vehicles"] if v["id"] == "UAV3")["legs"]
    }


def test_export_unknown_vehicle_is_one_line(
    schedule_doc: tuple[Path, dict],  # type: ignore[type-arg]
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    path, _ = schedule_doc
    args = [
        "export",
        str(path),
        "--vehicle",
        "NOPE",
        "--format",
        "wpl",
        "--out",
        str(tmp_path / "x.txt"),
    ]
    assert main(args) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "NOPE" in err


def test_infeasible_schedule_exits_1_naming_the_vehicle(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = small_scenario(arrival={"kind": "simultaneous", "required_s": 9000})
    data["vehicles"][0]["airborne"] = True
    data["vehicles"][1]["takeoff_window_s"] = [8000, 9000]
    scenario = tmp_path / "s.json"
    scenario.write_text(json.dumps(data))
    args = ["schedule", str(scenario), "--method", "astar", "--out", str(tmp_path / "o.json")]
    assert main(args) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: vehicle A:") and "short by" in err and err.count("\n") == 1


def _schedule(
    tmp_path: Path,
    data: dict,
    *extra: str,  # type: ignore[type-arg]
) -> tuple[int, Path]:
    scenario = tmp_path / "s.json"
    scenario.write_text(json.dumps(data))
    out = tmp_path / "o.json"
    args = ["schedule", str(scenario), "--method", "astar", "--out", str(out), *extra]
    return main(args), out


def _refused(
    tmp_path: Path,
    data: dict,
    capsys: pytest.CaptureFixture[str],  # type: ignore[type-arg]
) -> str:
    """Schedule ``data``: exit 1, nothing written, one line on stderr (returned)."""
    code, out = _schedule(tmp_path, data)
    captured = capsys.readouterr()
    assert code == 1 and not out.exists()
    assert captured.out == "" and captured.err.count("\n") == 1, captured.err
    return captured.err


def test_infeasible_requested_arrival_exits_1_naming_times_and_vehicle(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = small_scenario(arrival={"kind": "simultaneous", "required_s": 10})
    err = _refused(tmp_path, data, capsys)
    assert re.match(
        r"error: requested arrival 10\.0 s is too early: earliest feasible \d+\.\d s, "
        r"forced by vehicle [AB]: ",
        err,
    ), err


def test_collision_exits_1_naming_pair_time_and_distance_unless_allowed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = small_scenario()
    data["vehicles"][1]["goal"] = dict(data["vehicles"][0]["goal"])
    err = _refused(tmp_path, data, capsys)
    assert re.match(
        r"error: vehicles A and B come within 0\.\d m of each other at \d+\.\d s, under the "
        r"separation minimum d_s 300 m \(--allow-conflicts writes the schedule anyway\)$",
        err,
    ), err
    code, out = _schedule(tmp_path, data, "--allow-conflicts")
    assert code == 0
    doc = json.loads(out.read_text())
    assert doc["min_separation_m"] < 1.0 and len(doc["conflicts"]) == 1
    assert "conflict allowed: A and B within 0." in capsys.readouterr().out
