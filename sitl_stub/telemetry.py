"""What a simulated vehicle sends: its messages, their default rates and their content.

The field values of each message come from the autopilot's state, the clock and the stored
mission (:class:`TelemetryMessages`, mixed into :class:`~sitl_stub.vehicle.Vehicle`), in the
order of the pymavlink constructor; :mod:`sitl_stub.wire` frames them. What ArduPlane puts
in each field is noted where the stub follows it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_stub.autopilot import Autopilot, Mode
from sitl_stub.clock import SimClock
from sitl_stub.mission_server import MissionServer
from sitl_stub.wind_estimate import WindEstimateError
from sitl_stub.wire import MessageSpec, spec_for

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
    "TERRAIN_REPORT": 0.0,  # 1 Hz on a vehicle flying over terrain (Vehicle sets it)
}
TERRAIN_REPORT_INTERVAL_S = 1.0
TERRAIN_SPACING_M = 100
"""TERRAIN_REPORT.spacing: ArduPilot's TERRAIN_SPACING default (its grid, in metres)."""

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
    # ArduPlane's EXTRA3 has MSG_TERRAIN (TERRAIN_REQUEST and TERRAIN_REPORT) when terrain is on.
    mavlink2.MAV_DATA_STREAM_EXTRA3: ("SYSTEM_TIME", "WIND", "TERRAIN_REPORT"),
}
STREAM_GROUPS[mavlink2.MAV_DATA_STREAM_ALL] = tuple(
    name for names in STREAM_GROUPS.values() for name in names
)


AUTO_LIKE_MODES = frozenset({"AUTO", "RTL", "LOITER", "GUIDED", "CIRCLE", "TAKEOFF"})


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
_MAV_STATE_EMERGENCY = mavlink2.MAV_STATE_EMERGENCY
_MODE_AUTO = int(Mode.AUTO)
_TWO_PI = 2.0 * math.pi


# Framing of the messages a vehicle sends as streams or on request (see sitl_stub.wire).
SPECS: dict[str, MessageSpec] = {name: spec_for(name) for name in DEFAULT_INTERVALS_S}
MSG_ID_TO_NAME: dict[int, str] = {spec.msg_id: name for name, spec in SPECS.items()}


class TelemetryMessages:
    """The content of every message in :data:`SPECS`, for the vehicle that mixes it in."""

    system_id: int
    autopilot: Autopilot
    clock: SimClock
    mission: MissionServer
    utc_offset_s: float | None
    wind_error: WindEstimateError | None

    def _message_builders(self) -> dict[str, Callable[[], tuple[Any, ...]]]:
        """Field values of each message, in the order of its pymavlink constructor."""
        return {
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
            "TERRAIN_REPORT": self._terrain_report,
        }

    def _heartbeat(self) -> tuple[Any, ...]:
        ap = self.autopilot
        mode = int(ap.mode)
        base = _MODE_BASE_FLAGS[mode]
        if ap.armed:
            base |= _ARMED
            status = _MAV_STATE_ACTIVE
        else:
            status = _MAV_STATE_STANDBY
        if ap.crash_detected:
            # ArduPlane/GCS_Mavlink.cpp vehicle_system_status: crash_state.is_crashed.
            status = _MAV_STATE_EMERGENCY
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
            # ArduPlane sends airspeed_error * 100 (cm/s where MAVLink says m/s: "incorrect
            # units; see PR#7933", ArduPlane/GCS_Mavlink.cpp send_nav_controller_output).
            n.aspd_error_m_s * 100.0,
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

    def _terrain_report(self) -> tuple[Any, ...]:
        """As libraries/AP_Terrain/TerrainGCS.cpp send_terrain_report: terrain_height is the
        terrain AMSL under the vehicle, current_height the vehicle's height above it (its
        altitude above home plus the terrain at home minus the terrain here); spacing 0 means
        no terrain data (a vehicle over flat ground); pending and loaded (ArduPilot's counts of
        4x4 grid blocks) are 0: the stub's terrain is not kept in those blocks."""
        ap = self.autopilot
        s = ap.state
        lat, lon = round(s.lat_deg * 1e7), round(s.lon_deg * 1e7)
        if ap.terrain is None:
            return (lat, lon, 0, 0.0, 0.0, 0, 0)
        here = ap.ground_alt_m
        # (altitude above home) + (terrain at home) - (terrain here); home is on the terrain.
        current = s.alt_m - here
        return (lat, lon, TERRAIN_SPACING_M, here, current, 0, 0)

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
