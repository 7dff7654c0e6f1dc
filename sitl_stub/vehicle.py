"""One simulated vehicle's MAVLink endpoint: what ArduPlane looks like on the wire.

The endpoint is sans-IO. The server feeds it decoded messages (``handle``), simulated steps
(``step``) and wall-clock ticks (``tick_wall``); it answers through the ``send`` callback
with packed MAVLink 2 bytes addressed to one link or to all (``None``).

Stream intervals are in SIMULATED time (as ArduPilot SITL with a speed-up): a 1 Hz
SYSTEM_TIME at 100x is 100 messages per wall second. Streams are per vehicle and go to every
connected link (ArduPilot keeps SRx rates per serial port).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_stub.autopilot import Autopilot, CurrentChanged, ItemReached, Mode, Text
from sitl_stub.clock import SimClock
from sitl_stub.items import MissionItem
from sitl_stub.link import FaultyLink
from sitl_stub.mission_server import LinkId, MissionServer, MissionStored, addressed_to
from sitl_stub.model import AirframeParams, FlightState, crossing_time
from sitl_stub.wind_estimate import WindEstimateError
from sitl_stub.wire import MessageSpec, Packer, spec_for

log = logging.getLogger(__name__)

SendBytes = Callable[[LinkId | None, bytes], None]

COMPONENT_ID = 1
FORCE_MAGIC = 21196.0
# ArduPlane 4.5.7, official release.
FLIGHT_SW_VERSION = (4 << 24) | (5 << 16) | (7 << 8) | 255
CAPABILITIES = (
    mavlink2.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
    | mavlink2.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mavlink2.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mavlink2.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mavlink2.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
    | mavlink2.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | mavlink2.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
    | mavlink2.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY
)
SENSORS = (
    mavlink2.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | mavlink2.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mavlink2.MAV_SYS_STATUS_SENSOR_3D_MAG
    | mavlink2.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | mavlink2.MAV_SYS_STATUS_SENSOR_DIFFERENTIAL_PRESSURE
    | mavlink2.MAV_SYS_STATUS_SENSOR_GPS
    | mavlink2.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
    | mavlink2.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
    | mavlink2.MAV_SYS_STATUS_SENSOR_YAW_POSITION
    | mavlink2.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
    | mavlink2.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    | mavlink2.MAV_SYS_STATUS_AHRS
    | mavlink2.MAV_SYS_STATUS_PREARM_CHECK
)

# Default stream intervals, simulated seconds (0 = off).
DEFAULT_INTERVALS_S: dict[str, float] = {
    "HEARTBEAT": 1.0,
    "GLOBAL_POSITION_INT": 0.5,
    "VFR_HUD": 0.5,
    "ATTITUDE": 0.5,
    "SYS_STATUS": 1.0,
    "GPS_RAW_INT": 1.0,
    "SYSTEM_TIME": 1.0,
    "WIND": 1.0,
    "NAV_CONTROLLER_OUTPUT": 1.0,
    "MISSION_CURRENT": 1.0,
    "HOME_POSITION": 0.0,
    "AUTOPILOT_VERSION": 0.0,
}

# REQUEST_DATA_STREAM groups, as ArduPilot's SRx_ parameters group messages.
STREAM_GROUPS: dict[int, tuple[str, ...]] = {
    mavlink2.MAV_DATA_STREAM_EXTENDED_STATUS: (
        "SYS_STATUS",
        "GPS_RAW_INT",
        "MISSION_CURRENT",
        "NAV_CONTROLLER_OUTPUT",
    ),
    mavlink2.MAV_DATA_STREAM_POSITION: ("GLOBAL_POSITION_INT",),
    mavlink2.MAV_DATA_STREAM_EXTRA1: ("ATTITUDE",),
    mavlink2.MAV_DATA_STREAM_EXTRA2: ("VFR_HUD",),
    mavlink2.MAV_DATA_STREAM_EXTRA3: ("SYSTEM_TIME", "WIND"),
}
STREAM_GROUPS[mavlink2.MAV_DATA_STREAM_ALL] = tuple(
    name for names in STREAM_GROUPS.values() for name in names
)


@dataclass(frozen=True, slots=True)
class ParamSpec:
    """One parameter: ArduPlane name, AirframeParams field, MAVLink type, range."""

    name: str
    field: str | None
    mav_type: int
    minimum: float
    maximum: float


PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("AIRSPEED_CRUISE", "airspeed_cruise_m_s", mavlink2.MAV_PARAM_TYPE_REAL32, 5, 100),
    ParamSpec("AIRSPEED_MAX", "airspeed_max_m_s", mavlink2.MAV_PARAM_TYPE_REAL32, 5, 100),
    ParamSpec("AIRSPEED_MIN", "airspeed_min_m_s", mavlink2.MAV_PARAM_TYPE_REAL32, 5, 100),
    ParamSpec("SYSID_THISMAV", None, mavlink2.MAV_PARAM_TYPE_INT8, 1, 255),
    ParamSpec("WP_LOITER_RAD", "loiter_radius_m", mavlink2.MAV_PARAM_TYPE_REAL32, -32767, 32767),
    ParamSpec("WP_RADIUS", "wp_radius_m", mavlink2.MAV_PARAM_TYPE_REAL32, 1, 32767),
)
PARAM_INDEX = {p.name: i for i, p in enumerate(PARAMS)}

AUTO_LIKE_MODES = frozenset({"AUTO", "RTL", "LOITER", "GUIDED", "CIRCLE", "TAKEOFF"})

# Framing of the messages a vehicle sends as streams or on request (see sitl_stub.wire).
SPECS: dict[str, MessageSpec] = {name: spec_for(name) for name in DEFAULT_INTERVALS_S}
MSG_ID_TO_NAME: dict[int, str] = {spec.msg_id: name for name, spec in SPECS.items()}


def _base_mode(mode: Mode) -> int:
    """HEARTBEAT base_mode flags of a mode, disarmed."""
    base = mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    if mode.name == "MANUAL":
        base |= mavlink2.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
    elif mode.name in AUTO_LIKE_MODES:
        base |= mavlink2.MAV_MODE_FLAG_GUIDED_ENABLED | mavlink2.MAV_MODE_FLAG_STABILIZE_ENABLED
        if mode.name == "AUTO":
            base |= mavlink2.MAV_MODE_FLAG_AUTO_ENABLED
    else:
        base |= mavlink2.MAV_MODE_FLAG_STABILIZE_ENABLED
    return int(base)


_MODE_BASE_FLAGS = {int(mode): _base_mode(mode) for mode in Mode}
_ARMED = mavlink2.MAV_MODE_FLAG_SAFETY_ARMED
_MAV_STATE_ACTIVE = mavlink2.MAV_STATE_ACTIVE
_MAV_STATE_STANDBY = mavlink2.MAV_STATE_STANDBY
_MODE_AUTO = int(Mode.AUTO)
_TWO_PI = 2.0 * math.pi


def _ts(msg: Any) -> tuple[int, int]:
    return msg.get_srcSystem(), msg.get_srcComponent()


@dataclass(slots=True)
class Watch:
    """A point whose crossing time is wanted (callback gets simulated seconds)."""

    lat_deg: float
    lon_deg: float
    radius_m: float
    callback: Callable[[float], None]


class Vehicle:
    """The MAVLink endpoint of one simulated ArduPlane."""

    def __init__(
        self,
        *,
        system_id: int,
        autopilot: Autopilot,
        clock: SimClock,
        link: FaultyLink,
        send: SendBytes | None = None,
        mission_timeout_s: float = 1.5,
        legacy_mission_requests: bool = False,
        ardupilot_mission_storage: bool = True,
        utc_offset_s: float | None = 0.0,
        wind_error: WindEstimateError | None = None,
    ) -> None:
        self.system_id = system_id
        # This vehicle's clock error against the true simulated UTC; None: it has no UTC
        # (SYSTEM_TIME.time_unix_usec = 0, as an autopilot without GPS time).
        self.utc_offset_s = utc_offset_s
        # WIND reports the true wind plus this error (None: the true wind).
        self.wind_error = wind_error
        self.component_id = COMPONENT_ID
        self.autopilot = autopilot
        self.clock = clock
        self.link = link
        self._send: SendBytes = send or (lambda _link, _data: None)
        # One sequence counter for everything this vehicle sends (see docs/sitl_stub.md).
        self._packer = Packer(system_id, COMPONENT_ID)
        self.mission = MissionServer(
            system_id=system_id,
            component_id=COMPONENT_ID,
            timeout_s=mission_timeout_s,
            legacy_requests=legacy_mission_requests,
            ardupilot_storage=ardupilot_mission_storage,
            current_nav_index=lambda: self.autopilot.current_nav_index,
        )
        self._home_src: tuple[float, float, float] | None = None
        self._sync_home()
        # Change with set_interval (it keeps the schedule below in step).
        self.intervals_s = dict(DEFAULT_INTERVALS_S)
        self._next_due_s = {name: 0.0 for name in self.intervals_s}
        # Earliest next-due time over all streams: most steps send nothing and stop there.
        self._streams_due_s = 0.0
        self._watches: list[Watch] = []
        self.crossings: list[tuple[float, float, float, float]] = []
        self.counters: dict[str, int] = {
            "received": 0,
            "bad_data": 0,
            "handler_errors": 0,
            "unsupported_commands": 0,
            "sent": 0,
        }
        self._last_wall_s = 0.0
        self._statustext_id = 0
        # Field values of each message, in the order of its pymavlink constructor.
        self._builders: dict[str, Callable[[], tuple[Any, ...]]] = {
            "HEARTBEAT": self._heartbeat,
            "GLOBAL_POSITION_INT": self._global_position_int,
            "VFR_HUD": self._vfr_hud,
            "ATTITUDE": self._attitude,
            "SYS_STATUS": self._sys_status,
            "GPS_RAW_INT": self._gps_raw_int,
            "SYSTEM_TIME": self._system_time,
            "WIND": self._wind,
            "NAV_CONTROLLER_OUTPUT": self._nav_controller_output,
            "MISSION_CURRENT": self._mission_current,
            "HOME_POSITION": self._home_position,
            "AUTOPILOT_VERSION": self._autopilot_version,
        }
        self._by_id = MSG_ID_TO_NAME
        self._stream_table = [
            (name, SPECS[name], self._builders[name]) for name in self.intervals_s
        ]
        self._commands: dict[int, Callable[[Any, list[float], LinkId], int]] = {
            mavlink2.MAV_CMD_COMPONENT_ARM_DISARM: self._cmd_arm,
            mavlink2.MAV_CMD_DO_SET_MODE: self._cmd_set_mode,
            mavlink2.MAV_CMD_MISSION_START: self._cmd_mission_start,
            mavlink2.MAV_CMD_DO_CHANGE_SPEED: self._cmd_change_speed,
            mavlink2.MAV_CMD_DO_SET_MISSION_CURRENT: self._cmd_set_mission_current,
            mavlink2.MAV_CMD_REQUEST_MESSAGE: self._cmd_request_message,
            mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL: self._cmd_set_message_interval,
            mavlink2.MAV_CMD_GET_MESSAGE_INTERVAL: self._cmd_get_message_interval,
            mavlink2.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: self._cmd_autopilot_capabilities,
            mavlink2.MAV_CMD_GET_HOME_POSITION: self._cmd_get_home,
            mavlink2.MAV_CMD_NAV_RETURN_TO_LAUNCH: self._cmd_rtl,
            mavlink2.MAV_CMD_NAV_LOITER_UNLIM: self._cmd_loiter,
            mavlink2.MAV_CMD_DO_REPOSITION: self._cmd_reposition,
        }

    # -- wiring ------------------------------------------------------------------------

    def set_sender(self, send: SendBytes) -> None:
        self._send = send

    @property
    def true_state(self) -> FlightState:
        """The simulated truth (not telemetry)."""
        return self.autopilot.state

    def watch_crossing(
        self, lat_deg: float, lon_deg: float, radius_m: float, callback: Callable[[float], None]
    ) -> Watch:
        """Call ``callback(sim_time_s)`` once, when the vehicle first comes within radius."""
        w = Watch(lat_deg, lon_deg, radius_m, callback)
        self._watches.append(w)
        return w

    def unwatch(self, watch: Watch) -> None:
        if watch in self._watches:
            self._watches.remove(watch)

    def clear_watches(self) -> None:
        self._watches.clear()

    # -- output ------------------------------------------------------------------------

    def emit(self, msg: Any, link: LinkId | None = None) -> None:
        """Send a pymavlink message object to ``link`` (None: every link)."""
        self.counters["sent"] += 1
        self._send(link, self._packer.pack_message(msg))

    def emit_named(self, name: str, link: LinkId | None = None) -> None:
        """Build and send one of the stream messages (``"HEARTBEAT"`` ...) now."""
        self.counters["sent"] += 1
        self._send(link, self._packer.pack(SPECS[name], self._builders[name]()))

    def message(self, name: str) -> Any:
        """The current content of a stream message as a pymavlink object (not sent)."""
        return SPECS[name].message(self._builders[name]())

    def statustext(self, severity: int, text: str, link: LinkId | None = None) -> None:
        data = text.encode("utf-8", errors="replace")
        if len(data) <= 50:
            self.emit(mavlink2.MAVLink_statustext_message(severity, data), link)
            return
        self._statustext_id = self._statustext_id % 65535 + 1
        for chunk_seq, start in enumerate(range(0, len(data), 50)):
            part = data[start : start + 50]
            self.emit(
                mavlink2.MAVLink_statustext_message(severity, part, self._statustext_id, chunk_seq),
                link,
            )

    # -- simulation ----------------------------------------------------------------------

    def step(self, dt_s: float) -> None:
        """Advance the autopilot by ``dt_s`` simulated seconds and send what falls due."""
        prev = self.autopilot.state
        events = self.autopilot.step(dt_s)
        new = self.autopilot.state
        for ev in events:
            if isinstance(ev, ItemReached):
                self.emit(mavlink2.MAVLink_mission_item_reached_message(ev.seq))
            elif isinstance(ev, CurrentChanged):
                self.emit_named("MISSION_CURRENT")
            elif isinstance(ev, Text):
                self.statustext(int(ev.severity), ev.text)
        if self._watches:
            self._check_watches(prev, new)
        if self.autopilot.home is not self._home_src:
            self._sync_home()
        if self.clock.sim_time_s + 1e-9 >= self._streams_due_s:
            self._send_streams()

    def _check_watches(self, prev: FlightState, new: FlightState) -> None:
        for w in list(self._watches):
            t = crossing_time(prev, new, w.lat_deg, w.lon_deg, w.radius_m)
            if t is not None:
                self._watches.remove(w)
                self.crossings.append((t, w.lat_deg, w.lon_deg, w.radius_m))
                w.callback(t)

    def _send_streams(self) -> None:
        now = self.clock.sim_time_s
        next_due = self._next_due_s
        intervals = self.intervals_s
        pack = self._packer.pack
        send = self._send
        earliest = math.inf
        for name, spec, build in self._stream_table:
            interval = intervals[name]
            if interval <= 0:
                continue
            due = next_due[name]
            if now + 1e-9 >= due:
                self.counters["sent"] += 1
                send(None, pack(spec, build()))
                nxt = due + interval
                due = nxt if nxt > now else now + interval
                next_due[name] = due
            if due < earliest:
                earliest = due
        self._streams_due_s = earliest

    def tick_wall(self, wall_s: float) -> None:
        """Protocol timers (wall time)."""
        self._last_wall_s = wall_s
        if self.mission.next_deadline() is not None:
            self._apply(self.mission.tick(wall_s))

    def _sync_home(self) -> None:
        self._home_src = self.autopilot.home
        lat, lon, alt = self._home_src
        home = self.mission.home
        x, y = round(lat * 1e7), round(lon * 1e7)
        if home.x != x or home.y != y or home.z != alt:
            self.mission.home = MissionItem(
                seq=0,
                frame=mavlink2.MAV_FRAME_GLOBAL,
                command=mavlink2.MAV_CMD_NAV_WAYPOINT,
                x=x,
                y=y,
                z=float(alt),
            )

    # -- input ---------------------------------------------------------------------------

    def note_bad_data(self, n: int = 1) -> None:
        self.counters["bad_data"] += n

    def handle(self, msg: Any, link: LinkId, wall_s: float) -> None:
        """Process one decoded message from ``link``. Never raises."""
        self._last_wall_s = wall_s
        mtype = msg.get_type()
        if mtype == "BAD_DATA":
            self.counters["bad_data"] += 1
            return
        self.counters["received"] += 1
        try:
            self._dispatch(mtype, msg, link, wall_s)
        except Exception:  # a malformed or unexpected message must not take the link down
            self.counters["handler_errors"] += 1
            log.exception("vehicle %d: error handling %s", self.system_id, mtype)

    def _dispatch(self, mtype: str, msg: Any, link: LinkId, wall_s: float) -> None:
        if self.mission.handles(mtype):
            self._apply(self.mission.handle(msg, link, wall_s))
            return
        if mtype in ("HEARTBEAT", "RADIO_STATUS"):
            return
        if mtype == "COMMAND_LONG":
            if addressed_to(msg, self.system_id, self.component_id):
                p = [msg.param1, msg.param2, msg.param3, msg.param4]
                p += [msg.param5, msg.param6, msg.param7]
                self._command(msg, p, link, is_int=False)
        elif mtype == "COMMAND_INT":
            if addressed_to(msg, self.system_id, self.component_id):
                p = [msg.param1, msg.param2, msg.param3, msg.param4]
                p += [msg.x * 1e-7, msg.y * 1e-7, msg.z]
                self._command(msg, p, link, is_int=True)
        elif mtype == "SET_MODE":
            if msg.target_system == self.system_id:
                ok = self._set_mode(msg.custom_mode)
                self._ack(msg, mavlink2.MAVLINK_MSG_ID_SET_MODE, ok, link)
        elif mtype == "MISSION_SET_CURRENT":
            ok = addressed_to(msg, self.system_id, self.component_id)
            if ok and self.autopilot.set_current(int(msg.seq)):
                self.emit_named("MISSION_CURRENT")
        elif mtype == "REQUEST_DATA_STREAM":
            if addressed_to(msg, self.system_id, self.component_id):
                self._request_data_stream(msg)
        elif mtype.startswith("PARAM_"):
            self._param(mtype, msg, link)
        elif mtype == "TIMESYNC" and msg.tc1 == 0:
            now_ns = int(self.clock.sim_time_s * 1e9)
            self.emit(mavlink2.MAVLink_timesync_message(now_ns, msg.ts1), link)

    def _apply(self, reaction: Any) -> None:
        for send in reaction.sends:
            self.emit(send.msg, send.link)
        for ev in reaction.events:
            if isinstance(ev, MissionStored) and ev.mission_type == 0:
                self.autopilot.replace_mission(ev.items)

    # -- commands ------------------------------------------------------------------------

    def _ack(self, msg: Any, command: int, result: int | bool, link: LinkId) -> None:
        if isinstance(result, bool):
            result = mavlink2.MAV_RESULT_ACCEPTED if result else mavlink2.MAV_RESULT_FAILED
        src, comp = _ts(msg)
        self.emit(mavlink2.MAVLink_command_ack_message(command, result, 0, 0, src, comp), link)

    def _command(self, msg: Any, p: list[float], link: LinkId, *, is_int: bool) -> None:
        handler = self._commands.get(int(msg.command))
        if handler is None:
            self.counters["unsupported_commands"] += 1
            self._ack(msg, msg.command, mavlink2.MAV_RESULT_UNSUPPORTED, link)
            return
        if not all(math.isfinite(v) for v in p[:4]) and msg.command not in (
            mavlink2.MAV_CMD_DO_REPOSITION,
        ):
            self._ack(msg, msg.command, mavlink2.MAV_RESULT_DENIED, link)
            return
        result = handler(msg, p, link)
        self._ack(msg, msg.command, result, link)

    def _cmd_arm(self, msg: Any, p: list[float], link: LinkId) -> int:
        force = p[1] == FORCE_MAGIC
        if p[0] == 1.0:
            ok, reason = self.autopilot.arm(force=force)
            verb = "Arm"
        elif p[0] == 0.0:
            ok, reason = self.autopilot.disarm(force=force)
            verb = "Disarm"
        else:
            return int(mavlink2.MAV_RESULT_DENIED)
        if not ok:
            self.statustext(mavlink2.MAV_SEVERITY_CRITICAL, f"{verb}: {reason}", link)
            return int(mavlink2.MAV_RESULT_FAILED)
        return int(mavlink2.MAV_RESULT_ACCEPTED)

    def _set_mode(self, custom_mode: int) -> bool:
        try:
            mode = Mode(int(custom_mode))
        except ValueError:
            return False
        return self.autopilot.set_mode(mode)

    def _cmd_set_mode(self, msg: Any, p: list[float], link: LinkId) -> int:
        if not int(p[0]) & mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return int(mavlink2.MAV_RESULT_DENIED)
        return self._result(self._set_mode(int(p[1])))

    def _cmd_mission_start(self, msg: Any, p: list[float], link: LinkId) -> int:
        return self._result(self.autopilot.start_mission(int(p[0]), int(p[1])))

    def _cmd_change_speed(self, msg: Any, p: list[float], link: LinkId) -> int:
        return self._result(self.autopilot.change_speed(int(p[0]), p[1], p[2]))

    def _cmd_set_mission_current(self, msg: Any, p: list[float], link: LinkId) -> int:
        ok = self.autopilot.set_current(int(p[0]))
        if ok:
            self.emit_named("MISSION_CURRENT")
        return self._result(ok)

    def _cmd_request_message(self, msg: Any, p: list[float], link: LinkId) -> int:
        name = self._by_id.get(int(p[0]))
        if name is None:
            return int(mavlink2.MAV_RESULT_FAILED)
        self.emit_named(name, link)
        return int(mavlink2.MAV_RESULT_ACCEPTED)

    def _cmd_set_message_interval(self, msg: Any, p: list[float], link: LinkId) -> int:
        name = self._by_id.get(int(p[0]))
        if name is None:
            return int(mavlink2.MAV_RESULT_FAILED)
        interval_us = p[1]
        if interval_us == 0:
            self.set_interval(name, DEFAULT_INTERVALS_S[name])
        elif interval_us < 0:
            self.set_interval(name, 0.0)
        else:
            self.set_interval(name, interval_us / 1e6)
        return int(mavlink2.MAV_RESULT_ACCEPTED)

    def _cmd_get_message_interval(self, msg: Any, p: list[float], link: LinkId) -> int:
        name = self._by_id.get(int(p[0]))
        if name is None:
            return int(mavlink2.MAV_RESULT_FAILED)
        interval = self.intervals_s[name]
        us = int(interval * 1e6) if interval > 0 else -1
        self.emit(mavlink2.MAVLink_message_interval_message(int(p[0]), us), link)
        return int(mavlink2.MAV_RESULT_ACCEPTED)

    def _cmd_autopilot_capabilities(self, msg: Any, p: list[float], link: LinkId) -> int:
        self.emit_named("AUTOPILOT_VERSION", link)
        return int(mavlink2.MAV_RESULT_ACCEPTED)

    def _cmd_get_home(self, msg: Any, p: list[float], link: LinkId) -> int:
        self.emit_named("HOME_POSITION", link)
        return int(mavlink2.MAV_RESULT_ACCEPTED)

    def _cmd_rtl(self, msg: Any, p: list[float], link: LinkId) -> int:
        return self._result(self.autopilot.set_mode(Mode.RTL))

    def _cmd_loiter(self, msg: Any, p: list[float], link: LinkId) -> int:
        return self._result(self.autopilot.set_mode(Mode.LOITER))

    def _cmd_reposition(self, msg: Any, p: list[float], link: LinkId) -> int:
        lat, lon, alt = p[4], p[5], p[6]
        if not (math.isfinite(lat) and math.isfinite(lon) and abs(lat) <= 90 and abs(lon) <= 180):
            return int(mavlink2.MAV_RESULT_DENIED)
        if not self.autopilot.armed:
            return int(mavlink2.MAV_RESULT_FAILED)
        change = int(p[1]) & mavlink2.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE
        if self.autopilot.mode != Mode.GUIDED and (
            not change or not self.autopilot.set_mode(Mode.GUIDED)
        ):
            return int(mavlink2.MAV_RESULT_FAILED)
        frame = int(getattr(msg, "frame", mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT))
        if not math.isfinite(alt):
            alt_amsl = self.autopilot.state.alt_m
        elif frame in (mavlink2.MAV_FRAME_GLOBAL, mavlink2.MAV_FRAME_GLOBAL_INT):
            alt_amsl = alt
        else:
            alt_amsl = alt + self.autopilot.home[2]
        return self._result(self.autopilot.set_guided_target(lat, lon, alt_amsl))

    @staticmethod
    def _result(ok: bool) -> int:
        return int(mavlink2.MAV_RESULT_ACCEPTED if ok else mavlink2.MAV_RESULT_FAILED)

    # -- streams -------------------------------------------------------------------------

    def set_interval(self, name: str, interval_s: float) -> None:
        """Set a stream's interval in simulated seconds (0 = off)."""
        if name not in self.intervals_s:
            raise KeyError(name)
        self.intervals_s[name] = max(0.0, interval_s)
        self._next_due_s[name] = self.clock.sim_time_s
        self._streams_due_s = min(self._streams_due_s, self.clock.sim_time_s)

    def _request_data_stream(self, msg: Any) -> None:
        names = STREAM_GROUPS.get(int(msg.req_stream_id))
        if names is None:
            return
        rate_hz = int(msg.req_message_rate)
        interval = 1.0 / rate_hz if msg.start_stop and rate_hz > 0 else 0.0
        for name in names:
            self.set_interval(name, interval)

    # -- parameters ----------------------------------------------------------------------

    def param_value(self, name: str) -> float:
        spec = PARAMS[PARAM_INDEX[name]]
        if spec.field is None:
            return float(self.system_id)
        return float(getattr(self.autopilot.params, spec.field))

    def _param_msg(self, index: int) -> Any:
        spec = PARAMS[index]
        return mavlink2.MAVLink_param_value_message(
            spec.name.encode(), self.param_value(spec.name), spec.mav_type, len(PARAMS), index
        )

    def _param(self, mtype: str, msg: Any, link: LinkId) -> None:
        if not addressed_to(msg, self.system_id, self.component_id):
            return
        if mtype == "PARAM_REQUEST_LIST":
            for i in range(len(PARAMS)):
                self.emit(self._param_msg(i), link)
        elif mtype == "PARAM_REQUEST_READ":
            idx = int(msg.param_index)
            if idx < 0:
                idx = PARAM_INDEX.get(str(msg.param_id), -1)
            if 0 <= idx < len(PARAMS):
                self.emit(self._param_msg(idx), link)
        elif mtype == "PARAM_SET":
            name = str(msg.param_id)
            found = PARAM_INDEX.get(name)
            if found is None:
                self.statustext(mavlink2.MAV_SEVERITY_WARNING, f"Unknown parameter {name}", link)
                return
            idx = found
            spec = PARAMS[idx]
            value = float(msg.param_value)
            if spec.field is not None:
                if not (math.isfinite(value) and spec.minimum <= value <= spec.maximum):
                    self.statustext(
                        mavlink2.MAV_SEVERITY_WARNING, f"{name} {value:g} out of range", link
                    )
                else:
                    self._set_param_field(spec.field, value, name)
            # Broadcast, as ArduPilot does, so every GCS sees the new value.
            self.emit(self._param_msg(idx))

    def _set_param_field(self, field: str, value: float, name: str) -> None:
        params: AirframeParams = self.autopilot.params
        try:
            changes: dict[str, Any] = {field: value}
            new = replace(params, **changes)
            self.autopilot.set_params(new)
        except (ValueError, TypeError) as err:
            self.statustext(mavlink2.MAV_SEVERITY_WARNING, f"{name}: {err}")

    # -- message builders: field values in pymavlink constructor order --------------------

    def _heartbeat(self) -> tuple[Any, ...]:
        ap = self.autopilot
        mode = int(ap.mode)
        base = _MODE_BASE_FLAGS[mode]
        if ap.armed:
            base |= _ARMED
            status = _MAV_STATE_ACTIVE
        else:
            status = _MAV_STATE_STANDBY
        return (
            mavlink2.MAV_TYPE_FIXED_WING,
            mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA,
            base,
            mode,
            status,
            3,
        )

    def _global_position_int(self) -> tuple[Any, ...]:
        s = self.autopilot.state
        home_alt = self.autopilot.home[2]
        return (
            self.clock.time_boot_ms,
            round(s.lat_deg * 1e7),
            round(s.lon_deg * 1e7),
            round(s.alt_m * 1000),
            round((s.alt_m - home_alt) * 1000),
            _i16(s.vel_north_m_s * 100),
            _i16(s.vel_east_m_s * 100),
            _i16(-s.climb_rate_m_s * 100),
            round(math.degrees(s.heading_rad) * 100) % 36000,
        )

    def _vfr_hud(self) -> tuple[Any, ...]:
        s = self.autopilot.state
        gs = math.hypot(s.vel_north_m_s, s.vel_east_m_s)
        throttle = 0 if (s.on_ground and not self.autopilot.armed) else 50
        # ArduPlane reports its airspeed sensor's equivalent airspeed (GCS_Mavlink.cpp,
        # GCS_MAVLINK_Plane::vfr_hud_airspeed): what the autopilot believes, bias included.
        return (
            self.autopilot.measured_eas_m_s,
            gs,
            round(math.degrees(s.heading_rad)) % 360,
            throttle,
            s.alt_m,
            s.climb_rate_m_s,
        )

    def _attitude(self) -> tuple[Any, ...]:
        s = self.autopilot.state
        yaw = math.remainder(s.heading_rad, _TWO_PI)
        return (self.clock.time_boot_ms, s.roll_rad, s.pitch_rad, yaw, 0.0, 0.0, 0.0)

    def _sys_status(self) -> tuple[Any, ...]:
        return (SENSORS, SENSORS, SENSORS, 100, 12600, 1000, 100, 0, 0, 0, 0, 0, 0)

    def _gps_raw_int(self) -> tuple[Any, ...]:
        s = self.autopilot.state
        gs = math.hypot(s.vel_north_m_s, s.vel_east_m_s)
        cog = math.degrees(math.atan2(s.vel_east_m_s, s.vel_north_m_s)) % 360.0
        return (
            int(self.clock.sim_time_s * 1e6),
            mavlink2.GPS_FIX_TYPE_3D_FIX,
            round(s.lat_deg * 1e7),
            round(s.lon_deg * 1e7),
            round(s.alt_m * 1000),
            121,
            200,
            min(65534, round(gs * 100)),
            round(cog * 100) % 36000,
            10,
        )

    @property
    def utc_s(self) -> float | None:
        """The UTC this vehicle reports (true simulated UTC + its offset), None without UTC."""
        if self.utc_offset_s is None:
            return None
        return self.clock.utc_s + self.utc_offset_s

    def _system_time(self) -> tuple[Any, ...]:
        utc = self.utc_s
        return (0 if utc is None else round(utc * 1e6), self.clock.time_boot_ms)

    def _wind(self) -> tuple[Any, ...]:
        s = self.autopilot.state
        north, east = s.wind_north_m_s, s.wind_east_m_s
        if self.wind_error is not None:
            err_n, err_e = self.wind_error.north_east_m_s(s.time_s)
            north += err_n
            east += err_e
        speed = math.hypot(north, east)
        direction = math.degrees(math.atan2(-east, -north)) % 360.0
        return (direction, speed, 0.0)

    def _nav_controller_output(self) -> tuple[Any, ...]:
        n = self.autopilot.nav
        return (
            n.nav_roll_deg,
            n.nav_pitch_deg,
            _i16(n.nav_bearing_deg),
            _i16(n.target_bearing_deg),
            max(0, min(65535, round(n.wp_dist_m))),
            n.alt_error_m,
            n.aspd_error_m_s,
            n.xtrack_error_m,
        )

    def _mission_current(self) -> tuple[Any, ...]:
        ap = self.autopilot
        total = max(0, self.mission.count() - 1)
        auto = ap.mode == _MODE_AUTO
        if total == 0:
            state = mavlink2.MISSION_STATE_NO_MISSION
        elif auto and ap.armed:
            state = mavlink2.MISSION_STATE_ACTIVE
        else:
            state = mavlink2.MISSION_STATE_NOT_STARTED
        return (int(ap.current_seq), total, state, 1 if auto else 2)

    def _home_position(self) -> tuple[Any, ...]:
        lat, lon, alt = self.autopilot.home
        return (
            round(lat * 1e7),
            round(lon * 1e7),
            round(alt * 1000),
            0.0,
            0.0,
            0.0,
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            0.0,
            0.0,
            int((self.utc_s or 0.0) * 1e6),
        )

    def _autopilot_version(self) -> tuple[Any, ...]:
        return (
            CAPABILITIES,
            FLIGHT_SW_VERSION,
            0,
            0,
            0,
            [0] * 8,
            [0] * 8,
            [0] * 8,
            0,
            0,
            self.system_id,
        )


def _i16(v: float) -> int:
    return max(-32768, min(32767, round(v)))
