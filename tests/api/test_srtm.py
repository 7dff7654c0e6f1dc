"""A scenario's SRTM terrain is read only from the service's own SRTM folder
(``TCGCS_SRTM_DIR``): its ``terrain.directory`` names a folder under it. Without that setting,
with an absolute path, with ``..`` or a link out of it, or with no such folder, the scenario is
a 422 naming ``terrain.directory`` and nothing is kept; a folder under it is planned on."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from fastapi import FastAPI

from tests.api.conftest import app_with, auth, job_until, problem, running
from tests.api.test_bad_input import row_counts
from tests.planner.conftest import small_scenario
from tests.planner.test_terrain import write_tile

_JSON = {"Content-Type": "application/json"}
TILES = [(44, 6), (44, 7), (45, 6), (45, 7)]
"""The SRTM tiles (south-west corners, degrees) round the scenario's origin."""


def _srtm(directory: str) -> str:
    """The planner tests' small scenario (40 km square round 45 N 7 E) on SRTM terrain."""
    return json.dumps(small_scenario(terrain={"kind": "srtm", "directory": directory}))


@pytest.fixture
def srtm_dir(tmp_path: Path) -> Path:
    """The service's SRTM folder: ``alps`` holds the tile, ``empty`` none; beside it, outside,
    a folder with a tile of its own and a link to it from inside."""
    root = tmp_path / "srtm"
    (root / "alps").mkdir(parents=True)
    (root / "empty").mkdir()
    outside = tmp_path / "private"
    outside.mkdir()
    for lat, lon in TILES:
        write_tile(root / "alps", lat, lon, np.full((1201, 1201), 120))
        write_tile(outside, lat, lon, np.full((1201, 1201), 120))
    (root / "link").symlink_to(outside, target_is_directory=True)
    return root


def _kept(app: FastAPI) -> int:
    return row_counts(app)["scenarios"]


async def test_without_an_srtm_folder_srtm_terrain_is_refused(tmp_path: Path) -> None:
    app = app_with(tmp_path, srtm_dir=None)
    async for client in running(app):
        r = await client.post("/v1/scenarios", content=_srtm("."), headers=auth("plan") | _JSON)
        detail = problem(r, 422)["detail"]
        assert "terrain.directory" in detail and "TCGCS_SRTM_DIR" in detail, detail
        assert _kept(app) == 0


@pytest.mark.parametrize(
    ("directory", "said"),
    [
        ("/etc", "no absolute path"),
        ("../private", "no '..'"),
        ("alps/../../private", "no '..'"),
        ("link", "not a folder of the service's SRTM folder"),
        ("missing", "not a folder of the service's SRTM folder"),
        ("alps/N45E007.hgt", "not a folder of the service's SRTM folder"),
    ],
)
async def test_a_folder_outside_the_srtm_folder_is_422_and_nothing_is_kept(
    tmp_path: Path, srtm_dir: Path, directory: str, said: str
) -> None:
    app = app_with(tmp_path, srtm_dir=srtm_dir)
    async for client in running(app):
        r = await client.post(
            "/v1/scenarios", content=_srtm(directory), headers=auth("plan") | _JSON
        )
        detail = problem(r, 422)["detail"]
        assert detail.startswith("scenario: terrain.directory: "), detail
        assert said in detail, detail
        assert str(tmp_path) not in detail  # the service's own paths are not told
        assert _kept(app) == 0


async def _planned(client: httpx.AsyncClient, scenario_id: str) -> dict[str, Any]:
    """The schedule job of a scenario, once it has ended."""
    r = await client.post("/v1/schedules", json={"scenario_id": scenario_id}, headers=auth("plan"))
    assert r.status_code == 202, r.text
    return await job_until(client, r.json()["id"], "succeeded", "failed")


async def test_a_folder_under_the_srtm_folder_is_planned_on_that_folders_tiles(
    tmp_path: Path, srtm_dir: Path
) -> None:
    app = app_with(tmp_path, srtm_dir=srtm_dir)
    async for client in running(app):
        ids = {}
        for name in ("alps", "empty"):
            r = await client.post(
                "/v1/scenarios", content=_srtm(name), headers=auth("plan") | _JSON
            )
            assert r.status_code == 201, r.text
            ids[name] = r.json()["id"]
        assert _kept(app) == 2
        done = await _planned(client, ids["alps"])
        assert done["state"] == "succeeded", done
        # The empty folder is where the planner looked: no tile there, though the same name
        # exists in the service's other folders.
        failed = await _planned(client, ids["empty"])
        assert failed["state"] == "failed", failed
        assert ".hgt not found in" in json.dumps(failed), failed
