"""A flight worker's planning jobs run in processes of their own
(:class:`gcs.service.flightjobs.FlightJobs`): the result comes back, and what a job raises is
raised again as it was (the runner tells a planner's refusal from a failure by its type)."""

from __future__ import annotations

import os
from dataclasses import dataclass

import pytest

from gcs.errors import GcsError
from gcs.service.flightjobs import FlightJobs
from planner.errors import InfeasibleError


@dataclass(frozen=True)
class _Job:
    """A stand-in for a planning job: its ``run()`` says where it ran, or raises."""

    raises: Exception | None = None
    raises_unpicklable: bool = False

    def run(self) -> int:
        if self.raises is not None:
            raise self.raises
        if self.raises_unpicklable:
            raise _Unpicklable(1, 2)
        return os.getpid()


class _Unpicklable(Exception):
    def __init__(self, a: int, b: int) -> None:
        super().__init__(f"{a} and {b}")  # its args do not make it again


async def test_a_job_runs_in_a_process_of_its_own_and_its_errors_come_back() -> None:
    jobs = FlightJobs()
    try:
        assert await jobs.run(_Job()) != os.getpid()  # type: ignore[arg-type]
        refused = InfeasibleError("no route round Z", earliest_s=12.0, vehicle="UAV2")
        with pytest.raises(InfeasibleError, match="no route round Z") as got:
            await jobs.run(_Job(refused))  # type: ignore[arg-type]
        assert (got.value.earliest_s, got.value.vehicle) == (12.0, "UAV2")
        with pytest.raises(GcsError, match="_Unpicklable: 1 and 2"):
            await jobs.run(_Job(raises_unpicklable=True))  # type: ignore[arg-type]
    finally:
        jobs.close()
