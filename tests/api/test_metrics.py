"""``/metrics`` counts a flight's separation events by kind and gives the least distance its
separation alarms reported (read from the flight's events when scraped: those of
:func:`tests.gcs.test_separationlog.an_encounter`, one of each kind and three resolutions)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

from prometheus_client.parser import text_string_to_metric_families

from gcs.api.metrics import metrics_text
from gcs.coordination.events import FlightEvent
from gcs.coordination.runner import FlightState
from gcs.service.flight import Flight
from tests.gcs.test_separationlog import an_encounter


def _engine(events: list[FlightEvent]) -> Any:
    """An engine with one flight whose worker's figures are those of ``events``
    (:meth:`Flight.figures`)."""
    runner = SimpleNamespace(events=events, members={}, bus=SimpleNamespace(dropped=0))
    flight = SimpleNamespace(runner=runner, bus=runner.bus, state=FlightState.RUNNING)
    figures = Flight.figures(flight)  # type: ignore[arg-type]
    told = SimpleNamespace(state=FlightState.RUNNING, figures=lambda: figures)
    return SimpleNamespace(link_counters=dict, flights={"f1": told})


def test_metrics_count_separation_events_by_kind_and_the_least_loss() -> None:
    events = an_encounter()
    text = metrics_text(_engine(events)).decode()
    samples = {
        (s.name, tuple(sorted(s.labels.items()))): s.value
        for family in text_string_to_metric_families(text)
        for s in family.samples
    }
    count = "tcgcs_separation_events_total"
    said = {
        kind: samples[(count, (("flight", "f1"), ("kind", kind)))]
        for kind in ("predicted", "resolved", "released", "unresolved", "loss")
    }
    assert said == {"predicted": 1, "resolved": 3, "released": 1, "unresolved": 1, "loss": 1}
    assert len([k for k in samples if k[0] == count]) == 5
    assert samples[("tcgcs_separation_loss_min_meters", (("flight", "f1"),))] == 224.0
