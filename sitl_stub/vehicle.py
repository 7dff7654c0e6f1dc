"""One simulated vehicle's MAVLink endpoint: what ArduPlane looks like on the wire.

The endpoint is sans-IO. The server feeds it decoded messages (``handle``), simulated steps
(``step``) and wall-clock ticks (``tick_wall``); it answers through the ``send`` callback
with packed MAVLink 2 bytes addressed to one link or to all (``None``).

Stream intervals are in SIMULATED time (as ArduPilot SITL with a speed-up): a 1 Hz
SYSTEM_TIME at 100x is 100 messages per wall second. Streams are per vehicle and go to every
connected link (ArduPilot keeps SRx rates per serial port).

What goes in each message is :mod:`sitl_stub.telemetry`; commands are
:mod:`sitl_stub.commands`, parameters :mod:`sitl_stub.params` (the three are mixed into
:class:`Vehicle`); this module routes messages in and out, runs the streams and the mission
protocol's timers, and watches for goal crossings.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_stub.autopilot import Autopilot, CurrentChanged, ItemReached, Text
from sitl_stub.clock import SimClock
from sitl_stub.commands import CommandHandlers
from sitl_stub.items import MissionItem
from sitl_stub.link import FaultyLink
from sitl_stub.mission_server import LinkId, MissionServer, MissionStored, addressed_to
from sitl_stub.model import FlightState, crossing_time
from sitl_stub.params import ParameterHandlers
from sitl_stub.telemetry import (
    DEFAULT_INTERVALS_S,
    MSG_ID_TO_NAME,
    SPECS,
    STREAM_GROUPS,
    TERRAIN_REPORT_INTERVAL_S,
    TelemetryMessages,
)
from sitl_stub.wind_estimate import WindEstimateError
from sitl_stub.wire import Packer

log = logging.getLogger(__name__)

SendBytes = Callable[[LinkId | None, bytes], None]

COMPONENT_ID = 1


@dataclass(slots=True)
class Watch:
    """A point whose crossing time is wanted (callback gets simulated seconds)."""

    lat_deg: float
    lon_deg: float
    radius_m: float
    callback: Callable[[float], None]


class Vehicle(TelemetryMessages, CommandHandlers, ParameterHandlers):
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
        if autopilot.terrain is not None:
            self.intervals_s["TERRAIN_REPORT"] = TERRAIN_REPORT_INTERVAL_S
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
        self._builders = self._message_builders()
        self._by_id = MSG_ID_TO_NAME
        self._stream_table = [
            (name, SPECS[name], self._builders[name]) for name in self.intervals_s
        ]
        self._commands = self._command_handlers()

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
        autopilot = self.autopilot
        prev = autopilot.state
        events = autopilot.step(dt_s)
        for ev in events:
            if isinstance(ev, ItemReached):
                self.emit(mavlink2.MAVLink_mission_item_reached_message(ev.seq))
            elif isinstance(ev, CurrentChanged):
                self.emit_named("MISSION_CURRENT")
            elif isinstance(ev, Text):
                self.statustext(int(ev.severity), ev.text)
        if self._watches:
            self._check_watches(prev, autopilot.state)
        if autopilot.home is not self._home_src:
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
            if name == "TERRAIN_REPORT" and self.autopilot.terrain is None:
                continue  # as ArduPlane with TERRAIN_ENABLE 0: no terrain, no report
            self.set_interval(name, interval)
