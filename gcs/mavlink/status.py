"""One line of live telemetry per vehicle, for operators (``python -m gcs status``)."""

from __future__ import annotations

import datetime as dt

from gcs.mavlink.link import LinkCounters
from gcs.mavlink.telemetry import VehicleState


def _num(v: float | None, fmt: str, unit: str = "") -> str:
    return "-" if v is None else f"{v:{fmt}}{unit}"


def status_line(
    state: VehicleState, counters: LinkCounters, now_s: float, *, link_name: str = ""
) -> str:
    """``sys 1 AUTO armed  -35.363261 149.165230 alt 684.0 m (rel 100.0) ...`` on one line."""
    age = state.heartbeat_age_s(now_s)
    health = "no heartbeat" if age is None else ("ok" if age < 3.0 else f"LOST {age:.0f} s")
    armed = "-" if state.armed is None else ("armed" if state.armed else "disarmed")
    utc = "-"
    vehicle_utc = state.vehicle_utc_s(now_s)
    if vehicle_utc is not None:
        utc = dt.datetime.fromtimestamp(vehicle_utc, dt.UTC).strftime("%H:%M:%S.%f")[:-4] + "Z"
    wind = "-"
    if state.wind_speed_m_s is not None and state.wind_from_deg is not None:
        wind = f"{state.wind_speed_m_s:.1f}/{state.wind_from_deg:03.0f}"
    rtt = "-" if counters.rtt_s is None else f"{counters.rtt_s * 1e3:.0f} ms"
    parts = [
        f"sys {state.system_id}",
        f"{state.mode or '-'} {armed}",
        f"{_num(state.lat_deg, '.6f')} {_num(state.lon_deg, '.6f')}",
        f"alt {_num(state.alt_amsl_m, '.1f', ' m')} (rel {_num(state.alt_rel_m, '.1f')})",
        f"as {_num(state.airspeed_m_s, '.1f')} gs {_num(state.groundspeed_m_s, '.1f')} m/s",
        f"hdg {_num(state.heading_deg, '03.0f')}",
        f"wind {wind}",
        f"wp {_num(state.mission_current_seq, 'd')}",
        f"bat {_num(state.battery_remaining_pct, 'd', '%')}",
        f"utc {utc}",
        f"link {health} rx {counters.received} lost {counters.seq_lost} rtt {rtt}"
        + (f" unknown {counters.unknown_message}" if counters.unknown_message else ""),
    ]
    line = "  ".join(parts)
    return f"{line}  [{link_name}]" if link_name else line
