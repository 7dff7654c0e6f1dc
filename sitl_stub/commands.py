"""COMMAND_LONG / COMMAND_INT on a simulated vehicle: arming, modes, mission, streams.

Each supported command is answered with a COMMAND_ACK to the asking link (unsupported ones
with MAV_RESULT_UNSUPPORTED and counted); a non-finite param1..4 is DENIED, except for
DO_REPOSITION, where NaN means "unchanged" as in MAVLink. The handlers turn commands into
:class:`~sitl_stub.autopilot.Autopilot` calls and stream settings.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_stub.autopilot import Autopilot, Mode
from sitl_stub.mission_server import LinkId
from sitl_stub.telemetry import DEFAULT_INTERVALS_S

FORCE_MAGIC = 21196.0
_AMSL_FRAMES = (mavlink2.MAV_FRAME_GLOBAL, mavlink2.MAV_FRAME_GLOBAL_INT)
_ABOVE_HOME_FRAMES = (
    mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
    mavlink2.MAV_FRAME_GLOBAL_TERRAIN_ALT,
    mavlink2.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
)

CommandHandler = Callable[[Any, list[float], LinkId], int]


def _ts(msg: Any) -> tuple[int, int]:
    return msg.get_srcSystem(), msg.get_srcComponent()


class CommandHandlers:
    """MAV_CMD_* handlers, for the vehicle that mixes it in."""

    autopilot: Autopilot
    counters: dict[str, int]
    intervals_s: dict[str, float]
    _by_id: dict[int, str]
    _commands: dict[int, CommandHandler]  # the vehicle keeps _command_handlers() here

    if TYPE_CHECKING:

        def emit(self, msg: Any, link: LinkId | None = None) -> None: ...

        def emit_named(self, name: str, link: LinkId | None = None) -> None: ...

        def statustext(self, severity: int, text: str, link: LinkId | None = None) -> None: ...

        def set_interval(self, name: str, interval_s: float) -> None: ...

    def _command_handlers(self) -> dict[int, CommandHandler]:
        return {
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
            mavlink2.MAV_CMD_DO_CHANGE_ALTITUDE: self._cmd_change_altitude,
        }

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

    def _cmd_change_altitude(self, msg: Any, p: list[float], link: LinkId) -> int:
        """param1 the altitude (m), param2 its MAV_FRAME: AMSL for GLOBAL(_INT), above home
        for RELATIVE_ALT and TERRAIN_ALT (the stub's frames), DENIED for any other, as
        ArduPlane's mavlink_coordinate_frame_to_location_alt_frame refuses it
        (ArduPlane/GCS_Mavlink.cpp handle_command_int_DO_CHANGE_ALTITUDE)."""
        frame = int(p[1])
        if frame in _AMSL_FRAMES:
            alt_m = p[0]
        elif frame in _ABOVE_HOME_FRAMES:
            alt_m = self.autopilot.home[2] + p[0]
        else:
            return int(mavlink2.MAV_RESULT_DENIED)
        return self._result(self.autopilot.change_altitude(alt_m))

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
