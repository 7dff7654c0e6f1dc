"""Prometheus ``/metrics``: read from the engine when scraped (links, messages, malformed
frames, commands, uploads, arrival errors, event-bus drops, flights, separation events)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator

from prometheus_client import CollectorRegistry, generate_latest
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from gcs.coordination.events import EventKind
from gcs.coordination.separationlog import separation_kind
from gcs.service.engine import Engine

__all__ = ["metrics_text"]


class _EngineCollector(Collector):
    def __init__(self, engine: Engine) -> None:
        self.engine = engine

    def collect(self) -> Iterator[Metric]:
        e = self.engine
        found = [e.fleet.held(c) for c in e.vehicle_ids.values()]
        links = [v for v in found if v is not None]
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
            for v in links:
                m.add_metric([v.connection], float(getattr(v.link.counters, name)))
            yield m
        flights = GaugeMetricFamily("tcgcs_flights", "flights by state", labels=["state"])
        states = Counter(h.runner.state.value for h in e.flights.values())
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
        for fid, h in e.flights.items():
            kinds: Counter[str] = Counter()
            lost_m: list[float] = []
            for ev in h.runner.events:
                sep = separation_kind(ev)
                if sep is not None:
                    kinds[sep.kind] += 1
                    if sep.kind == "loss" and sep.said_m is not None:
                        lost_m.append(sep.said_m)
                if ev.kind is EventKind.SPEED:
                    tally["speed", "failed" if "failed" in ev.reason else "ok"] += 1
                elif ev.kind is EventKind.LAUNCH:
                    tally["launch", "ok" if ev.payload.get("ok", True) else "failed"] += 1
                elif ev.kind is EventKind.UPLOAD:
                    up["failed" if "failed" in ev.reason else "ok"] += 1
            for member in h.runner.members.values():
                if member.arrival_s is not None:
                    late_s = member.arrival_s - member.target_s
                    error.add_metric([fid, member.vehicle_id], late_s)
            drops.add_metric([fid], float(h.runner.bus.dropped))
            for kind, n in kinds.items():
                separations.add_metric([fid, kind], float(n))
            if lost_m:
                least.add_metric([fid], min(lost_m))
        for (kind, result), n in tally.items():
            commands.add_metric([kind, result], float(n))
        for result, n in up.items():
            uploads.add_metric([result], float(n))
        yield from (commands, uploads, error, drops, separations, least)


def metrics_text(engine: Engine) -> bytes:
    registry = CollectorRegistry(auto_describe=False)
    registry.register(_EngineCollector(engine))
    return generate_latest(registry)
