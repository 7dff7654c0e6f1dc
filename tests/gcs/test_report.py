"""The rehearsal report: figures, tables and clear errors for malformed flight records."""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any

import pytest

from gcs.errors import GcsError
from gcs.rehearsal.flightrecord import _scenario_file
from gcs.rehearsal.report import arrival_table, write_report
from planner.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "scenarios" / "paper_three_uav.yaml"
START = 1_790_000_000.0
PNG = b"\x89PNG\r\n\x1a\n"


def _line(
    start: tuple[float, float], goal: tuple[float, float], t0: float, t1: float, speed: float
) -> list[list[float]]:
    """A straight track of 200 points from ``start`` at ``t0`` to ``goal`` at ``t1``."""
    n = 200
    out = []
    for i in range(n):
        f = i / (n - 1)
        e = start[0] + f * (goal[0] - start[0])
        no = start[1] + f * (goal[1] - start[1])
        out.append([START + t0 + f * (t1 - t0), e, no, 1000.0, speed, speed + 3.0 * math.sin(f)])
    return out


def _event(
    t_s: float,
    vehicle: str | None,
    kind: str,
    strategy: str | None,
    value: float | None,
    reason: str,
) -> dict[str, Any]:
    return {
        "utc_s": START + t_s,
        "t_s": t_s,
        "vehicle": vehicle,
        "kind": kind,
        "strategy": strategy,
        "value": value,
        "reason": reason,
    }


def _adjustment(
    t_s: float, vehicle: str, strategy: str, value: float, reason: str
) -> dict[str, Any]:
    return {
        "utc_s": START + t_s,
        "vehicle": vehicle,
        "strategy": strategy,
        "value": value,
        "reason": reason,
    }


def _flight() -> dict[str, Any]:
    """Three vehicles of the paper scenario: UAV2 launched early, UAV3 loitered in B3, UAV1
    replanned around POPUP1; UAV3 never arrived."""
    required = START + 6000.0

    def vehicle(
        vid: str,
        sysid: int,
        start: tuple[float, float],
        goal: tuple[float, float],
        takeoff: float,
        arrival: float | None,
        limits: tuple[float, float],
    ) -> dict[str, Any]:
        end = 6000.0 if arrival is None else arrival - START
        dist = math.dist(start, goal)
        speed = dist / (end - takeoff)
        return {
            "id": vid,
            "system_id": sysid,
            "speed_min_m_s": limits[0],
            "speed_max_m_s": limits[1],
            "target_arrival_utc_s": required,
            "arrival_utc_s": arrival,
            "error_s": None if arrival is None else arrival - required,
            "takeoff_utc_s": START + takeoff,
            "planned_paths": [
                {"label": "initial", "utc_s": START, "en_m": [list(start), list(goal)]},
            ],
            "loiters": [],
            "track": _line(start, goal, takeoff, end, speed),
            "commanded": [
                [START + takeoff, speed, "plan"],
                [START + takeoff + 2000.0, speed + 1.0, "command"],
            ],
            "planned_speeds": [[START + takeoff, START + end, speed, "leg"]],
        }

    uav1 = vehicle("UAV1", 1, (100e3, 160e3), (198e3, 200e3), 300.0, required + 1.2345, (20, 30))
    uav1["planned_paths"].append(
        {
            "label": "after POPUP1",
            "utc_s": START + 1500.0,
            "en_m": [[140e3, 176e3], [170e3, 150e3], [198e3, 200e3]],
        }
    )
    uav2 = vehicle("UAV2", 2, (130e3, 60e3), (200e3, 198e3), 0.0, required - 0.5, (20, 30))
    uav3 = vehicle("UAV3", 3, (130e3, 240e3), (198.9e3, 201.1e3), 100.0, None, (15, 25))
    uav3["loiters"] = [
        {
            "centre_east_m": 175e3,
            "centre_north_m": 210.5e3,
            "radius_m": 250.0,
            "turns": 1,
            "buffer_id": "B3",
            "utc_s": START + 2500.0,
        }
    ]
    uav3["planned_speeds"].append([START + 2500.0, START + 2600.0, 15.0, "loiter"])
    return {
        "format": "tcgcs-flight/1",
        "scenario_file": "scenarios/paper_three_uav.yaml",
        "start_utc_s": START,
        "required_arrival_utc_s": required,
        "separation_m": 500.0,
        "min_separation_m": 1421.3,
        "min_separation_pair": ["UAV1", "UAV3"],
        "min_separation_utc_s": required - 20.0,
        "wall_s": 95.2,
        "speedup": 200.0,
        "wind": {"speed_m_s": 5, "from_deg": 270},
        "loss": 0.1,
        "arrival_source": "simulator",
        "vehicles": [uav1, uav2, uav3],
        "events": [
            _event(0.0, "UAV2", "launch", "takeoff_delay", -1620.0, "longest path"),
            _event(300.0, "UAV1", "launch", None, None, "window opens"),
            _event(1500.0, None, "popup", None, None, "POPUP1 <radar> | 15 km"),
            _event(1510.0, "UAV1", "speed", "speed", 27.5, "replanned route is longer"),
            _event(2500.0, "UAV3", "loiter", "loiter", 1, "below v_min"),
            _event(6001.2345, "UAV1", "arrival", None, 1.2345, "crossed the goal"),
        ],
        "adjustments": [
            _adjustment(0.0, "UAV2", "takeoff_delay", -1620.0, "longest path"),
            _adjustment(1510.0, "UAV1", "speed", 27.5, "replanned route is longer"),
            _adjustment(2500.0, "UAV3", "loiter", 1, "below v_min"),
        ],
        "threats_appeared": [{"id": "POPUP1", "utc_s": START + 1500.0}],
    }


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, Any], list[Path]]:
    flight = _flight()
    out = tmp_path_factory.mktemp("report") / "rehearsal"
    return flight, write_report(flight, out, scenario_path=SCENARIO)


def test_every_file_is_written(report: tuple[dict[str, Any], list[Path]]) -> None:
    _, paths = report
    assert [p.name for p in paths] == [
        "paths.png",
        "speeds.png",
        "timeline.png",
        "arrivals.md",
        "index.html",
    ]
    for p in paths:
        assert p.is_file() and p.stat().st_size > 0, p
        if p.suffix == ".png":
            assert p.read_bytes()[:8] == PNG, p


def test_markdown_and_html_carry_the_tables(report: tuple[dict[str, Any], list[Path]]) -> None:
    _, paths = report
    md = (paths[0].parent / "arrivals.md").read_text(encoding="utf-8")
    page = (paths[0].parent / "index.html").read_text(encoding="utf-8")
    for vid in ("UAV1", "UAV2", "UAV3"):
        assert vid in md and vid in page
    assert "+1.23" in md and "-0.50" in md and "not arrived" in md
    assert "![paths](paths.png)" in md
    assert "POPUP1 &lt;radar&gt; \\| 15 km" in md  # pipes and markup escaped in markdown
    assert "POPUP1 &lt;radar&gt; | 15 km" in page  # text escaped in HTML
    for name in ("paths.png", "speeds.png", "timeline.png"):
        assert f'<img src="{name}"' in page


def test_arrival_table() -> None:
    table = arrival_table(_flight())
    lines = table.splitlines()
    assert lines[0].split()[:4] == ["vehicle", "target_s", "arrival_s", "error_s"]
    uav1 = next(line for line in lines if line.startswith("UAV1"))
    uav2 = next(line for line in lines if line.startswith("UAV2"))
    uav3 = next(line for line in lines if line.startswith("UAV3"))
    assert "6000.00" in uav1 and "6001.23" in uav1 and "+1.23" in uav1 and "speed" in uav1
    assert "300.00" in uav1
    assert "-0.50" in uav2 and "takeoff_delay" in uav2
    assert "not arrived" in uav3 and "loiter" in uav3
    assert uav3.split()[-2] == "1"  # one loiter turn
    assert "required arrival 6000.00 s" in lines[-1]
    assert "min separation 1421.3 m (UAV1-UAV3 at 5980.00 s)" in lines[-1]
    assert "d_s 500.0 m" in lines[-1] and "wall time 95.2 s (x200)" in lines[-1]
    # numbers are right-aligned under their header
    assert uav1.index("+1.23") + len("+1.23") == lines[0].index("error_s") + len("error_s")


def test_turns_and_commanded_speeds() -> None:
    flight = _flight()
    flight["vehicles"][2]["commanded"] = [[START + 100.0, 18.0, "plan"], [START, 16.5, "command"]]
    uav3 = next(line for line in arrival_table(flight).splitlines() if line.startswith("UAV3"))
    assert uav3.split()[-2:] == ["1", "16.5/18.0"]


def test_missing_track_names_the_field() -> None:
    flight = _flight()
    del flight["vehicles"][0]["track"]
    with pytest.raises(GcsError, match=r"vehicles\[0\]\.track: missing"):
        arrival_table(flight)


def test_missing_field_raises_before_writing(tmp_path: Path) -> None:
    flight = _flight()
    del flight["vehicles"][1]["target_arrival_utc_s"]
    with pytest.raises(GcsError, match=r"vehicles\[1\]\.target_arrival_utc_s: missing"):
        write_report(flight, tmp_path / "out", scenario_path=SCENARIO)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda f: f.update(format="tcgcs-plan/1"), r"format: expected 'tcgcs-flight/1'"),
        (lambda f: f.pop("start_utc_s"), r"start_utc_s: missing"),
        (lambda f: f.update(vehicles=[]), r"vehicles: empty"),
        (lambda f: f["vehicles"][0]["track"][5].pop(), r"vehicles\[0\]\.track\[5\]: expected"),
        (lambda f: f["vehicles"][1]["track"][3].__setitem__(1, "x"), r"track\[3\]: .* str"),
        (lambda f: f["vehicles"][2].update(arrival_utc_s=True), r"arrival_utc_s: .* bool"),
        (lambda f: f["events"][2].pop("kind"), r"events\[2\]\.kind: missing"),
        (lambda f: f["vehicles"][2]["loiters"][0].pop("radius_m"), r"loiters\[0\]\.radius_m"),
        (lambda f: f["vehicles"].append(copy.deepcopy(f["vehicles"][0])), r"duplicate vehicle"),
    ],
)
def test_malformed_records(edit: Any, message: str) -> None:
    flight = _flight()
    edit(flight)
    with pytest.raises(GcsError, match=message):
        arrival_table(flight)


def test_optional_fields_may_be_missing(tmp_path: Path) -> None:
    flight = _flight()
    for key in ("events", "adjustments", "threats_appeared", "wind", "min_separation_pair"):
        del flight[key]
    for v in flight["vehicles"]:
        for key in ("planned_paths", "loiters", "commanded", "planned_speeds", "error_s"):
            del v[key]
    flight["vehicles"][2]["track"] = []
    table = arrival_table(flight)
    assert "+1.23" in table  # error_s defaults to arrival - target
    assert "not arrived" in table


def test_scenario_file_is_resolved_against_the_out_dir_parent(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)  # scenarios/... is not under the working directory
    flight = _flight()
    flight["scenario_file"] = "missing/nowhere.yaml"
    with pytest.raises(GcsError, match=r"scenario_file: 'missing/nowhere.yaml' not found"):
        write_report(flight, ROOT / "out" / "never-written")
    assert not (ROOT / "out" / "never-written").exists()


def test_scenario_file_relative_to_the_out_dir_parent(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path / "..")
    (tmp_path / "scenarios").mkdir()
    (tmp_path / "scenarios" / "s.yaml").write_text("name: s\n", encoding="utf-8")
    record = {"scenario_file": "scenarios/s.yaml"}
    assert _scenario_file(record, tmp_path / "report") == tmp_path / "scenarios" / "s.yaml"
    monkeypatch.chdir(tmp_path)
    assert _scenario_file(record, tmp_path / "x" / "report") == Path("scenarios/s.yaml")


def test_a_record_that_carries_its_world_needs_no_scenario_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The record holds the scenario as flown and the operator's threats: the report is drawn
    from it alone (run from a folder where the scenario file does not exist)."""
    flight = _flight()
    flight["scenario_file"] = "no/such/file.yaml"
    flight["scenario"] = load_scenario(SCENARIO).model_dump(mode="json", exclude_none=True)
    box = [[185_600, 203_200], [189_600, 203_200], [189_600, 207_200], [185_600, 207_200]]
    flight["operator_threats"] = [
        {
            "kind": "no_fly",
            "id": "OP1",
            "polygon": [{"east_m": e, "north_m": n} for e, n in box],
            "appears": {"at_s": 2500},
        }
    ]
    monkeypatch.chdir(tmp_path)
    paths = write_report(flight, tmp_path / "report")
    assert [p.name for p in paths][-1] == "index.html" and all(p.is_file() for p in paths)
    flight["operator_threats"] = [{"kind": "no_fly", "id": "OP2"}]
    with pytest.raises(GcsError, match=r"flight record: .*polygon"):
        write_report(flight, tmp_path / "report2")


def test_a_flight_in_arrival_windows_has_no_team_time_and_is_reported(tmp_path: Path) -> None:
    """Arrival windows give each vehicle a slot of its own: the record's
    ``required_arrival_utc_s`` is null (as ``rehearse --json`` writes it), and the report draws
    and tabulates every vehicle against its own target, with no team line."""
    flight = _flight()
    flight["required_arrival_utc_s"] = None
    for k, v in enumerate(flight["vehicles"]):
        v["target_arrival_utc_s"] = START + 5900.0 + 60.0 * k
    files = write_report(flight, tmp_path / "windows", scenario_path=SCENARIO)
    assert {p.name for p in files} >= {"index.html", "arrivals.md", "timeline.png"}
    text = (tmp_path / "windows" / "arrivals.md").read_text(encoding="utf-8")
    assert "arrival windows (a slot per vehicle)" in text
    assert "required arrival" not in text
    # The key is still required: a record without it is not one.
    del flight["required_arrival_utc_s"]
    with pytest.raises(GcsError, match="required_arrival_utc_s"):
        write_report(flight, tmp_path / "never", scenario_path=SCENARIO)
