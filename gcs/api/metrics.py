"""Prometheus ``/metrics``: read from the engine when scraped (links, messages, malformed
frames, commands, uploads, arrival errors, event-bus drops, flights, separation events)."""

from __future__ import annotations

import gc
from collections import Counter
from collections.abc import Iterator

from prometheus_client import CollectorRegistry, generate_latest
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from gcs.service.engine import Engine
from gcs.service.loopwatch import LoopWatch

__all__ = ["metrics_text"]


class _EngineCollector(Collector):
    def __init__(self, engine: Engine) -> None:
        self.engine = engine

    def collect(self) -> Iterator[Metric]:
        e = self.engine
        links = e.link_counters()
        yield GaugeMetricFamily("tcgcs_links", "vehicle links open", value=len(links))
        fields = {
            "received": "messages received",
            "sent": "messages sent",
            "malformed": "malformed frames dropped",
            "crc_errors": "frames with a bad CRC dropped",
            "seq_lost": "packets missing from the senders' sequence numbers",
        }
        for name, doc in fields.items():
            m = CounterMetricFamily(f"tcgcs_link_{name}", doc, labels=["connection"])
            for conn, counters in links.items():
                m.add_metric([conn], float(counters[name]))
            yield m
        figures = {fid: f.figures() for fid, f in e.flights.items()}
        flights = GaugeMetricFamily("tcgcs_flights", "flights by state", labels=["state"])
        states = Counter(f.state.value for f in e.flights.values())
        for state, n in states.items():
            flights.add_metric([state], n)
        yield flights
        commands = CounterMetricFamily(
            "tcgcs_commands", "commands sent, by kind and result", labels=["kind", "result"]
        )
        uploads = CounterMetricFamily(
            "tcgcs_uploads", "mission uploads, by result", labels=["result"]
        )
        error = GaugeMetricFamily(
            "tcgcs_arrival_error_seconds",
            "arrival error against the slot (+late), from telemetry",
            labels=["flight", "vehicle"],
        )
        drops = CounterMetricFamily(
            "tcgcs_event_drops", "events a subscriber could not take", labels=["flight"]
        )
        separations = CounterMetricFamily(
            "tcgcs_separation_events",
            "conflicts a flight met, by kind: predicted, resolved, released, unresolved (a "
            "re-plan's, alarmed), loss (under the separation)",
            labels=["flight", "kind"],
        )
        least = GaugeMetricFamily(
            "tcgcs_separation_loss_min_meters",
            "the least distance a separation alarm of the flight reported (telemetry)",
            labels=["flight"],
        )
        tally: Counter[tuple[str, str]] = Counter()
        up: Counter[str] = Counter()
        for fid, fig in figures.items():
            if not fig:
                continue
            for kind_result, n in fig["commands"].items():
                kind, result = kind_result.split(" ", 1)
                tally[kind, result] += n
            up.update(fig["uploads"])
            for vid, late_s in fig["arrival_error_s"].items():
                error.add_metric([fid, vid], float(late_s))
            drops.add_metric([fid], float(fig["event_drops"]))
            for kind, n in fig["separation_events"].items():
                separations.add_metric([fid, kind], float(n))
            if fig["separation_loss_min_m"] is not None:
                least.add_metric([fid], float(fig["separation_loss_min_m"]))
        for (kind, result), n in tally.items():
            commands.add_metric([kind, result], float(n))
        for result, n in up.items():
            uploads.add_metric([result], float(n))
        yield from (commands, uploads, error, drops, separations, least)


class _ProcessCollector(Collector):
    """The API process's own loop: how long it was held at most (its :class:`LoopWatch`,
    where the service runs one), and how many objects are kept out of the collector's
    passes."""

    def __init__(self, watch: LoopWatch | None) -> None:
        self.watch = watch

    def collect(self) -> Iterator[Metric]:
        if self.watch is not None:
            yield GaugeMetricFamily(
                "tcgcs_api_loop_stall_max_seconds",
                "the longest the API process's event loop was held (woke late) since it started",
                value=self.watch.stall_max_s,
            )
        yield GaugeMetricFamily(
            "tcgcs_gc_frozen_objects",
            "objects of the API process kept out of the garbage collector's passes",
            value=gc.get_freeze_count(),
        )


def metrics_text(engine: Engine, watch: LoopWatch | None = None) -> bytes:
    registry = CollectorRegistry(auto_describe=False)
    registry.register(_EngineCollector(engine))
    registry.register(_ProcessCollector(watch))
    return generate_latest(registry)
