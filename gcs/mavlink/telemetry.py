"""Vehicle telemetry: a cheap message-to-state reducer and the state snapshot it produces.

:class:`TelemetryReducer` takes every message of one vehicle (``update(msg, rx_time_s)``; it
fits ``Link.add_listener``) and keeps the latest values in a plain dict; :attr:`state` builds
a frozen :class:`VehicleState` only when asked (and caches it until the next update), so the
per-message cost is one dict lookup and a few stores. No I/O, no clock: times come in.

Malformed values (NaN, inf, latitude outside +-90, a heading of 400 deg, battery 150 %) leave
the previous value in place and count the message in ``malformed``. The protocol's own
"unknown" markers (GLOBAL_POSITION_INT hdg 65535, battery_remaining -1, voltage 65535,
satellites 255, SYSTEM_TIME time_unix_usec 0, lat = lon = 0 before a GPS fix) are normal: a
marker on a value the vehicle cannot know sets it to None, a marker on a value another message
also reports (heading) keeps that one.

Position history uses the vehicle's own clock (GLOBAL_POSITION_INT.time_boot_ms) so link
latency jitter does not corrupt speed estimates; a position older than the last one
(reordered or duplicated on the link) is dropped and counted in ``stale``, and a jump back by
more than ``REBOOT_BACKSTEP_S`` is taken as a reboot (history cleared).
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Final, NamedTuple

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from gcs.mavlink.modes import mode_name

REBOOT_BACKSTEP_S: Final = 10.0
DEFAULT_HISTORY_LEN: Final = 256
LINK_TIMEOUT_S: Final = 3.0
"""A link with no HEARTBEAT for longer is down (three missed at MAVLink's 1 Hz)."""
DEFAULT_STATUSTEXT_LEN: Final = 16
STATUSTEXT_CHUNK_LEN: Final = 50

_ARMED: Final = int(mavlink2.MAV_MODE_FLAG_SAFETY_ARMED)
_AUTOPILOT_INVALID: Final = int(mavlink2.MAV_AUTOPILOT_INVALID)
_UINT16_MAX: Final = 65535
_MAX_SPEED_M_S: Final = 1000.0  # beyond any fixed-wing UAV: a larger value is corrupt
_WGS84_A_M: Final = 6378137.0
_WGS84_E2: Final = 6.69437999014e-3
_DEG: Final = math.pi / 180.0


class TrackSample(NamedTuple):
    """One position fix on the vehicle's clock."""

    time_boot_s: float
    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    groundspeed_m_s: float


class StatusText(NamedTuple):
    """A STATUSTEXT (chunks joined), with its MAV_SEVERITY and receive time."""

    severity: int
    text: str
    rx_time_s: float


@dataclass(frozen=True, slots=True)
class HomePosition:
    lat_deg: float
    lon_deg: float
    alt_amsl_m: float


def _empty_rx_times() -> Mapping[str, float]:
    return MappingProxyType({})


@dataclass(frozen=True, slots=True)
class VehicleState:
    """What one vehicle last told us; None where it has not said (or said "unknown")."""

    system_id: int | None = None
    # HEARTBEAT
    mode: str | None = None
    armed: bool | None = None
    base_mode: int | None = None
    custom_mode: int | None = None
    system_status: int | None = None
    mav_type: int | None = None
    autopilot: int | None = None
    # GLOBAL_POSITION_INT
    lat_deg: float | None = None
    lon_deg: float | None = None
    alt_amsl_m: float | None = None
    alt_rel_m: float | None = None
    vn_m_s: float | None = None
    ve_m_s: float | None = None
    vd_m_s: float | None = None
    position_time_boot_s: float | None = None
    # VFR_HUD (heading also from GLOBAL_POSITION_INT hdg, whichever came last)
    airspeed_m_s: float | None = None
    groundspeed_m_s: float | None = None
    heading_deg: float | None = None
    climb_m_s: float | None = None
    throttle_pct: int | None = None
    # WIND (ArduPilot): direction the wind blows FROM, compass degrees [0, 360)
    wind_speed_m_s: float | None = None
    wind_from_deg: float | None = None
    wind_vertical_m_s: float | None = None
    # MISSION_CURRENT / MISSION_ITEM_REACHED
    mission_current_seq: int | None = None
    mission_total: int | None = None
    mission_state: int | None = None
    items_reached: frozenset[int] = frozenset()
    last_reached: int | None = None
    # SYS_STATUS
    battery_remaining_pct: int | None = None
    voltage_v: float | None = None
    current_a: float | None = None
    # GPS_RAW_INT
    gps_fix_type: int | None = None
    satellites: int | None = None
    # SYSTEM_TIME
    utc_s: float | None = None
    utc_rx_s: float | None = None
    time_boot_s: float | None = None
    # NAV_CONTROLLER_OUTPUT
    nav_bearing_deg: float | None = None
    target_bearing_deg: float | None = None
    wp_dist_m: float | None = None
    xtrack_error_m: float | None = None
    # HOME_POSITION
    home: HomePosition | None = None
    # receive times (the caller's monotonic clock)
    last_heartbeat_rx_s: float | None = None
    last_position_rx_s: float | None = None
    rx_times: Mapping[str, float] = field(default_factory=_empty_rx_times)
    statustexts: tuple[StatusText, ...] = ()
    history: tuple[TrackSample, ...] = ()
    # counters
    received: int = 0
    malformed: int = 0
    stale: int = 0
    ignored: int = 0

    # -- link health -------------------------------------------------------------------

    def heartbeat_age_s(self, now_s: float) -> float | None:
        """Seconds since the last HEARTBEAT was received (None: never)."""
        t = self.last_heartbeat_rx_s
        return None if t is None else now_s - t

    def link_ok(self, now_s: float, timeout_s: float = LINK_TIMEOUT_S) -> bool:
        """A HEARTBEAT came within ``timeout_s``."""
        age = self.heartbeat_age_s(now_s)
        return age is not None and age <= timeout_s

    def mode_now(
        self, now_s: float, timeout_s: float = LINK_TIMEOUT_S
    ) -> tuple[str | None, bool | None]:
        """``(mode, armed)`` as the vehicle says them while its link is up (:meth:`link_ok`);
        ``(None, None)`` once it is down: what it does now is unknown, and its last word is
        :attr:`mode` and :attr:`armed`."""
        if not self.link_ok(now_s, timeout_s):
            return None, None
        return self.mode, self.armed

    def message_age_s(self, msg_type: str, now_s: float) -> float | None:
        t = self.rx_times.get(msg_type)
        return None if t is None else now_s - t

    # -- time ------------------------------------------------------------------------------

    def vehicle_utc_s(self, rx_now_s: float) -> float | None:
        """The vehicle's UTC now: last SYSTEM_TIME plus the receive time elapsed since."""
        if self.utc_s is None or self.utc_rx_s is None:
            return None
        return self.utc_s + (rx_now_s - self.utc_rx_s)

    # -- track -------------------------------------------------------------------------------

    def track_velocity_ne_m_s(self, window_s: float) -> tuple[float, float] | None:
        """(north, east) ground velocity, m/s: least-squares fit of the window's fixes."""
        return track_velocity_ne_m_s(self.history, window_s)

    def groundspeed_along_track_m_s(
        self, window_s: float, track_bearing_deg: float
    ) -> float | None:
        """Speed made good along ``track_bearing_deg`` over the last ``window_s`` (vehicle time)."""
        v = track_velocity_ne_m_s(self.history, window_s)
        if v is None:
            return None
        b = track_bearing_deg * _DEG
        return v[0] * math.cos(b) + v[1] * math.sin(b)

    def track_speed_m_s(self, window_s: float) -> float | None:
        """Speed along the flown ground track (path length / time) over the last ``window_s``."""
        return track_speed_m_s(self.history, window_s)


# -- track estimates (pure functions over samples) ---------------------------------------


def _window(samples: tuple[TrackSample, ...], window_s: float) -> tuple[TrackSample, ...]:
    if not (math.isfinite(window_s) and window_s > 0):
        raise ValueError(f"window_s must be a positive number of seconds, got {window_s!r}")
    if len(samples) < 2:
        return ()
    t_end = samples[-1].time_boot_s - window_s - 1e-9
    i = len(samples) - 1
    while i > 0 and samples[i - 1].time_boot_s >= t_end:
        i -= 1
    return samples[i:]


def _scales(lat_deg: float) -> tuple[float, float]:
    """Metres per degree north and east at a latitude (WGS84 radii of curvature)."""
    s = math.sin(lat_deg * _DEG)
    w2 = 1.0 - _WGS84_E2 * s * s
    n = _WGS84_A_M / math.sqrt(w2)
    m = n * (1.0 - _WGS84_E2) / w2
    return m * _DEG, n * math.cos(lat_deg * _DEG) * _DEG


def _local_ne(samples: tuple[TrackSample, ...]) -> list[tuple[float, float, float]]:
    ref = samples[-1]
    kn, ke = _scales(ref.lat_deg)
    out = []
    for s in samples:
        dlon = (s.lon_deg - ref.lon_deg + 180.0) % 360.0 - 180.0
        out.append((s.time_boot_s, (s.lat_deg - ref.lat_deg) * kn, dlon * ke))
    return out


def track_velocity_ne_m_s(
    samples: tuple[TrackSample, ...], window_s: float
) -> tuple[float, float] | None:
    """Least-squares (north, east) velocity of the fixes in the last ``window_s``."""
    win = _window(samples, window_s)
    if len(win) < 2 or win[-1].time_boot_s - win[0].time_boot_s <= 0:
        return None
    pts = _local_ne(win)
    k = len(pts)
    tm = sum(p[0] for p in pts) / k
    nm = sum(p[1] for p in pts) / k
    em = sum(p[2] for p in pts) / k
    stt = sum((p[0] - tm) ** 2 for p in pts)
    vn = sum((p[0] - tm) * (p[1] - nm) for p in pts) / stt
    ve = sum((p[0] - tm) * (p[2] - em) for p in pts) / stt
    return vn, ve


def track_speed_m_s(samples: tuple[TrackSample, ...], window_s: float) -> float | None:
    """Path length over elapsed vehicle time of the fixes in the last ``window_s``."""
    win = _window(samples, window_s)
    if len(win) < 2:
        return None
    dt = win[-1].time_boot_s - win[0].time_boot_s
    if dt <= 0:
        return None
    pts = _local_ne(win)
    length = sum(math.hypot(b[1] - a[1], b[2] - a[2]) for a, b in itertools.pairwise(pts))
    return length / dt


# -- the reducer ---------------------------------------------------------------------------


def _fin(v: float, lo: float, hi: float) -> bool:
    """lo <= v <= hi, False for NaN."""
    return lo <= v <= hi


class TelemetryReducer:
    """Folds one vehicle's messages into its latest state.

    ``system_id`` / ``component_id`` (None: any) select the vehicle's autopilot; messages
    from anything else are counted in ``ignored``. ``update`` is the hot path; ``state`` is a
    cached snapshot.
    """

    __slots__ = (
        "_cache",
        "_counts",
        "_f",
        "_handlers",
        "_hist",
        "_mode_cache",
        "_pos_t",
        "_reached",
        "_rx",
        "_text_parts",
        "_texts",
        "component_id",
        "system_id",
    )

    def __init__(
        self,
        system_id: int | None = None,
        component_id: int | None = 1,
        *,
        history_len: int = DEFAULT_HISTORY_LEN,
        statustext_len: int = DEFAULT_STATUSTEXT_LEN,
    ) -> None:
        if history_len < 2:
            raise ValueError(f"history_len must be >= 2, got {history_len}")
        self.system_id = system_id
        self.component_id = component_id
        self._f: dict[str, Any] = {"system_id": system_id}
        self._rx: dict[str, float] = {}
        self._hist: deque[TrackSample] = deque(maxlen=history_len)
        self._texts: deque[StatusText] = deque(maxlen=statustext_len)
        # (id, severity, next chunk_seq, parts) of a STATUSTEXT being reassembled
        self._text_parts: tuple[int, int, int, list[str]] | None = None
        self._reached: set[int] = set()
        # received, malformed, stale, ignored
        self._counts = [0, 0, 0, 0]
        self._pos_t: float | None = None
        self._mode_cache: dict[tuple[int, int, int], str] = {}
        self._cache: VehicleState | None = None
        self._handlers: dict[str, Callable[[Any, float], None]] = {
            "HEARTBEAT": self._heartbeat,
            "GLOBAL_POSITION_INT": self._global_position_int,
            "VFR_HUD": self._vfr_hud,
            "WIND": self._wind,
            "SYS_STATUS": self._sys_status,
            "GPS_RAW_INT": self._gps_raw_int,
            "SYSTEM_TIME": self._system_time,
            "NAV_CONTROLLER_OUTPUT": self._nav_controller_output,
            "MISSION_CURRENT": self._mission_current,
            "MISSION_ITEM_REACHED": self._mission_item_reached,
            "HOME_POSITION": self._home_position,
            "STATUSTEXT": self._statustext,
        }

    # -- input -----------------------------------------------------------------------------

    def update(self, msg: Any, rx_time_s: float) -> None:
        """Take one received message (any type; ``rx_time_s`` on the caller's clock)."""
        sysid = self.system_id
        if (sysid is not None and msg.get_srcSystem() != sysid) or (
            self.component_id is not None and msg.get_srcComponent() != self.component_id
        ):
            self._counts[3] += 1
            return
        mtype = msg.get_type()
        self._rx[mtype] = rx_time_s
        self._counts[0] += 1
        self._cache = None
        handler = self._handlers.get(mtype)
        if handler is not None:
            handler(msg, rx_time_s)

    __call__ = update  # a reducer is itself a Link listener

    def clear_reached(self) -> None:
        """Forget MISSION_ITEM_REACHED history (e.g. after uploading a new mission)."""
        self._reached.clear()
        self._f["last_reached"] = None
        self._cache = None

    # -- output ----------------------------------------------------------------------------

    @property
    def state(self) -> VehicleState:
        """The current state (a new frozen snapshot after each update, else the cached one)."""
        st = self._cache
        if st is None:
            received, malformed, stale, ignored = self._counts
            st = VehicleState(
                **self._f,
                items_reached=frozenset(self._reached),
                rx_times=MappingProxyType(dict(self._rx)),
                statustexts=tuple(self._texts),
                history=tuple(self._hist),
                received=received,
                malformed=malformed,
                stale=stale,
                ignored=ignored,
            )
            self._cache = st
        return st

    @property
    def malformed(self) -> int:
        return self._counts[1]

    # -- handlers ----------------------------------------------------------------------------

    def _bad(self) -> None:
        self._counts[1] += 1

    def _heartbeat(self, msg: Any, rx: float) -> None:
        autopilot = msg.autopilot
        if autopilot == _AUTOPILOT_INVALID:
            # Not a flight controller (a gimbal, a companion computer on our component id).
            self._counts[3] += 1
            return
        f = self._f
        base = msg.base_mode
        custom = msg.custom_mode
        key = (autopilot, base, custom)
        name = self._mode_cache.get(key)
        if name is None:
            name = mode_name(custom, autopilot, base)
            self._mode_cache[key] = name
        f["mode"] = name
        f["armed"] = bool(base & _ARMED)
        f["base_mode"] = base
        f["custom_mode"] = custom
        f["system_status"] = msg.system_status
        f["mav_type"] = msg.type
        f["autopilot"] = autopilot
        f["last_heartbeat_rx_s"] = rx

    def _global_position_int(self, msg: Any, rx: float) -> None:
        f = self._f
        t = msg.time_boot_ms * 1e-3
        last = self._pos_t
        if last is not None and t <= last:
            if t > last - REBOOT_BACKSTEP_S:
                self._counts[2] += 1  # reordered or duplicated: older than what we have
                return
            self._hist.clear()  # the vehicle rebooted
        self._pos_t = t
        f["position_time_boot_s"] = t
        vn = msg.vx * 0.01
        ve = msg.vy * 0.01
        f["vn_m_s"] = vn
        f["ve_m_s"] = ve
        f["vd_m_s"] = msg.vz * 0.01
        f["last_position_rx_s"] = rx
        bad = False
        hdg = msg.hdg
        if hdg != _UINT16_MAX:
            if 0 <= hdg < 36000:
                f["heading_deg"] = hdg * 0.01
            else:
                bad = True
        lat_i = msg.lat
        lon_i = msg.lon
        if lat_i == 0 and lon_i == 0:
            pass  # no position yet (ArduPilot before a fix)
        elif -900_000_000 <= lat_i <= 900_000_000 and -1_800_000_000 <= lon_i <= 1_800_000_000:
            lat = lat_i * 1e-7
            lon = lon_i * 1e-7
            alt = msg.alt * 1e-3
            f["lat_deg"] = lat
            f["lon_deg"] = lon
            f["alt_amsl_m"] = alt
            f["alt_rel_m"] = msg.relative_alt * 1e-3
            self._hist.append(TrackSample(t, lat, lon, alt, math.hypot(vn, ve)))
        else:
            bad = True
        if bad:
            self._counts[1] += 1

    def _vfr_hud(self, msg: Any, rx: float) -> None:
        f = self._f
        bad = False
        v = msg.airspeed
        if 0.0 <= v <= _MAX_SPEED_M_S:
            f["airspeed_m_s"] = v
        else:
            bad = True
        v = msg.groundspeed
        if 0.0 <= v <= _MAX_SPEED_M_S:
            f["groundspeed_m_s"] = v
        else:
            bad = True
        v = msg.climb
        if -_MAX_SPEED_M_S <= v <= _MAX_SPEED_M_S:
            f["climb_m_s"] = v
        else:
            bad = True
        h = msg.heading
        if 0 <= h <= 360:
            f["heading_deg"] = float(h % 360)
        else:
            bad = True
        thr = msg.throttle
        if 0 <= thr <= 100:
            f["throttle_pct"] = thr
        else:
            bad = True
        if bad:
            self._counts[1] += 1

    def _wind(self, msg: Any, rx: float) -> None:
        f = self._f
        d = msg.direction
        s = msg.speed
        z = msg.speed_z
        if -360.0 <= d <= 360.0 and 0.0 <= s <= _MAX_SPEED_M_S:
            f["wind_from_deg"] = d % 360.0
            f["wind_speed_m_s"] = s
        else:
            self._counts[1] += 1
            return
        if -_MAX_SPEED_M_S <= z <= _MAX_SPEED_M_S:
            f["wind_vertical_m_s"] = z
        else:
            self._counts[1] += 1

    def _sys_status(self, msg: Any, rx: float) -> None:
        f = self._f
        bad = False
        pct = msg.battery_remaining
        if pct == -1:
            f["battery_remaining_pct"] = None
        elif 0 <= pct <= 100:
            f["battery_remaining_pct"] = pct
        else:
            bad = True
        mv = msg.voltage_battery
        f["voltage_v"] = None if mv == _UINT16_MAX else mv * 1e-3
        ca = msg.current_battery
        f["current_a"] = None if ca == -1 else ca * 0.01
        if bad:
            self._counts[1] += 1

    def _gps_raw_int(self, msg: Any, rx: float) -> None:
        f = self._f
        fix = msg.fix_type
        if 0 <= fix <= 8:
            f["gps_fix_type"] = fix
        else:
            self._counts[1] += 1
        sats = msg.satellites_visible
        f["satellites"] = None if sats == 255 else sats

    def _system_time(self, msg: Any, rx: float) -> None:
        f = self._f
        f["time_boot_s"] = msg.time_boot_ms * 1e-3
        usec = msg.time_unix_usec
        if usec == 0:
            f["utc_s"] = None
            f["utc_rx_s"] = None
        else:
            f["utc_s"] = usec * 1e-6
            f["utc_rx_s"] = rx

    def _nav_controller_output(self, msg: Any, rx: float) -> None:
        f = self._f
        f["nav_bearing_deg"] = float(msg.nav_bearing % 360)
        f["target_bearing_deg"] = float(msg.target_bearing % 360)
        f["wp_dist_m"] = float(msg.wp_dist)
        x = msg.xtrack_error
        if -1e7 <= x <= 1e7:
            f["xtrack_error_m"] = x
        else:
            self._counts[1] += 1

    def _mission_current(self, msg: Any, rx: float) -> None:
        f = self._f
        f["mission_current_seq"] = msg.seq
        total = getattr(msg, "total", _UINT16_MAX)
        f["mission_total"] = None if total == _UINT16_MAX else total
        state = getattr(msg, "mission_state", 0)
        f["mission_state"] = state or None

    def _mission_item_reached(self, msg: Any, rx: float) -> None:
        seq = msg.seq
        self._reached.add(seq)
        self._f["last_reached"] = seq

    def _home_position(self, msg: Any, rx: float) -> None:
        lat_i = msg.latitude
        lon_i = msg.longitude
        if -900_000_000 <= lat_i <= 900_000_000 and -1_800_000_000 <= lon_i <= 1_800_000_000:
            self._f["home"] = HomePosition(lat_i * 1e-7, lon_i * 1e-7, msg.altitude * 1e-3)
        else:
            self._counts[1] += 1

    def _statustext(self, msg: Any, rx: float) -> None:
        text = msg.text
        if isinstance(text, bytes):
            text = text.decode("utf-8", errors="replace")
        text = text.rstrip("\x00")
        severity = msg.severity
        text_id = getattr(msg, "id", 0)
        if text_id == 0:
            self._flush_text(rx)
            self._texts.append(StatusText(severity, text, rx))
            return
        chunk_seq = getattr(msg, "chunk_seq", 0)
        pending = self._text_parts
        if pending is not None and pending[0] != text_id:
            self._flush_text(rx)
            pending = None
        if pending is None:
            pending = (text_id, severity, 0, [])
        pid, psev, expected, parts = pending
        if chunk_seq != expected:
            parts.append("...")  # a lost chunk
        parts.append(text)
        self._text_parts = (pid, psev, chunk_seq + 1, parts)
        if len(text) < STATUSTEXT_CHUNK_LEN:
            self._flush_text(rx)

    def _flush_text(self, rx: float) -> None:
        pending = self._text_parts
        if pending is not None:
            self._text_parts = None
            self._texts.append(StatusText(pending[1], "".join(pending[3]), rx))
