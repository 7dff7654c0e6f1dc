"""A generated scenario rehearsed on the bundled simulator, for the flight tests that judge
it from the simulator's truth log."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from gcs.coordination.config import FlightConfig
from gcs.rehearsal.rehearse import RehearsalOptions, rehearse
from planner.scenario import Scenario, load_scenario


async def rehearse_data(
    data: dict[str, Any],
    directory: Path,
    *,
    speedup: float = 100.0,
    config: FlightConfig | None = None,
) -> tuple[dict[str, Any], Scenario, Path]:
    """Write ``data`` as ``scenario.yaml`` in ``directory`` and rehearse it (seed 0, lock
    step, quiet): the flight record, the scenario as read and the truth log's path. The
    record is kept as ``flight.json`` beside them for a failure's post-mortem."""
    path = directory / "scenario.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    scenario = load_scenario(path)
    truth = directory / "truth.jsonl"
    record = await rehearse(
        RehearsalOptions(
            scenario_path=path,
            scenario=scenario,
            speedup=speedup,
            seed=0,
            truth=truth,
            json_out=directory / "flight.json",
            quiet=True,
            config=config or FlightConfig(seed=0),
        )
    )
    return record, scenario, truth
