"""ArduPlane-like autopilot logic over the point-mass model: modes, mission execution, L1 nav.

Interface notes:

- ``set_guided_target(lat_deg, lon_deg, alt_m) -> bool``: ``alt_m`` is AMSL; returns False
  (target ignored) unless the mode is GUIDED, as ArduPlane's guided request handler.
- ``change_speed``: an airspeed outside [airspeed_min_m_s, airspeed_max_m_s] is REFUSED
  (returns False, nothing changes), as ArduPlane's ``do_change_speed`` does, instead of being
  clamped. -1 means "no change" (accepted), -2 "back to cruise" (accepted).
- Events produced by calls made between steps (``set_mode``, ``set_current``,
  ``start_mission``, ``replace_mission``, ``change_speed`` ...) are returned by the next
  ``step`` call, before the events of that step.
- ``ItemReached`` is also emitted for DO items (e.g. DO_CHANGE_SPEED) when they run, as
  ArduPlane sends MISSION_ITEM_REACHED for every command it verifies in AUTO; ``ItemReached(0)``
  is emitted when GUIDED reaches its target (ArduPlane does the same). NAV_LAND is never
  "reached" (ArduPlane never verifies a landing complete; the vehicle lands and disarms).
- At mission end (last item done, no land) the mode changes to RTL with "Mission complete,
  changing mode to RTL", which is what ArduPlane does (``exit_mission_callback``), not loiter at
  the last waypoint.
- ``Autopilot.guided_target`` gives the GUIDED point; ``SIMULATED_MODES`` the modes flown.

Behaviour modelled on ArduPlane 4.x (``commands_logic.cpp``, ``AP_Mission``, ``AP_L1_Control``):

- Airspeeds (AIRSPEED_*, DO_CHANGE_SPEED, TECS_LAND_ARSPD) are equivalent airspeed; the model
  flies true airspeed EAS x EAS2TAS(altitude) x (1 + ``speed_bias``) (``sitl_stub.atmosphere``).

- Start: on the ground at home, disarmed in MANUAL; or, with ``airborne_alt_m``, already
  flying: armed, over home at that altitude at the cruise airspeed, in LOITER circling there.
- Mission: item 0 is home and never flown. AUTO starts at item 1 (or resumes at the
  interrupted item) with the leg from where the aircraft is (ArduPlane/mode_auto.cpp
  ``_enter``, AP_Mission ``start_or_resume``). DO commands between two NAV commands run when
  the mission advances past them (i.e. when the previous NAV item is reached); DO_LAND_START
  is a marker (no-op) and unsupported DO commands are no-ops (DO_JUMP is not followed);
  unsupported NAV commands are skipped.
- NAV_WAYPOINT: L1 navigation (:mod:`sitl_stub.l1`) along prev -> next (the first leg of a
  mission, and the leg after a takeoff, straight at the waypoint from where the aircraft is,
  as ArduPlane does without cross-tracking); reached within
  ``turn_distance(wp_radius, next_turn_angle)`` (param2 > 0 overrides; param3 pass-by > 0 sets
  it to 0) or when past the finish line. Pass-by offsetting of the point is not modelled.
- NAV_TAKEOFF (ArduPlane/takeoff.cpp, commands_logic.cpp verify_takeoff): ground roll on the
  heading it had when the roll began, at full throttle; rotate at the rotate speed; climb at
  ``takeoff_climb_rate_m_s`` (9 m/s, ArduPlane SITL's full-throttle climb-out, above
  TECS_CLMB_MAX) holding that ground course; done when altitude >= target (param7), then the
  next leg starts from where the aircraft is (next_WP_loc = prev_WP_loc = current_loc).
- NAV_LOITER_TURNS / TIME / UNLIM: approach on the leg line while farther than 3 radii, then
  L1 loiter (radius |param3|, 0 -> WP_LOITER_RAD; param3 < 0 counter-clockwise). Turns are
  counted from when the aircraft is on the circle; afterwards the aircraft keeps circling until
  its ground course points at the next NAV location (+-10 deg, widened 10 deg per extra circle),
  as ArduPlane does; param4 (xtrack from exit point) is honoured.
- NAV_LAND: glide slope from the previous waypoint, flare at ``land_flare_alt_m``, touchdown,
  roll-out, disarm after ``land_disarm_delay_s``.
- Altitude in AUTO slews linearly between waypoints (above 20 m or when descending; a
  feed-forward climb rate follows the slope); RTL/GUIDED climb at once and glide down.
- Frames: GLOBAL(_INT) is AMSL; every other frame (RELATIVE_ALT, TERRAIN_ALT ...) is taken as
  relative to home (TERRAIN_ALT is not flown above the terrain). Lat/lon 0,0 means "here".
- Ground: flat at home altitude, or with ``terrain`` (:class:`Ground`, e.g.
  :class:`sitl_stub.terrain.GridTerrain`) the terrain's elevation under the aircraft, looked up
  every physics step, moved by what it misses the home altitude by at home (home is on the
  ground); on the ground the wheels follow it, and their vertical speed up a slope is the climb
  a takeoff starts from.
- Crash: an armed aircraft in the air that reaches the ground other than by landing (NAV_LAND),
  or goes below it (flown into rising terrain), is wrecked where it hit: on the ground, still,
  never moving again, armed refused. ``CRASH_DETECT_DELAY_S`` later it says
  "Crash detected" (MAV_SEVERITY_EMERGENCY) and disarms, as ArduPlane's crash detection with
  CRASH_DETECT=1 (disarm) does (ArduPlane/is_flying.cpp, ``crash_detection_update``; there only
  in AUTO, here in every mode), and its HEARTBEAT says MAV_STATE_EMERGENCY from then on
  (ArduPlane/GCS_Mavlink.cpp ``vehicle_system_status``: ``crash_state.is_crashed``).
- Modes: AUTO, RTL (home at ALT_HOLD_RTL, then loiter), LOITER (circle here), GUIDED (circle
  the guided point, or here), CIRCLE (bank = roll limit / 3), TAKEOFF (climb to
  ``takeoff_mode_alt_m``, then loiter there); MANUAL, STABILIZE, FBWA, FBWB, CRUISE fly wings
  level holding altitude at cruise airspeed (no pilot input). TRAINING, ACRO, AUTOTUNE are
  refused. Home is fixed at construction (not reset on arming). A mode change resets a
  DO_CHANGE_SPEED airspeed, as ArduPlane. On the ground the aircraft only moves in an AUTO
  takeoff or TAKEOFF mode.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from sitl_stub import model
from sitl_stub.atmosphere import eas2tas
from sitl_stub.items import MissionItem
from sitl_stub.l1 import clamp, l1_loiter, l1_waypoint, wrap_pi
from sitl_stub.model import GRAVITY_M_S2, AirframeParams, FlightState, Wind

_TWO_PI = 2.0 * math.pi

_CMD_WAYPOINT = int(mav.MAV_CMD_NAV_WAYPOINT)
_CMD_LOITER_UNLIM = int(mav.MAV_CMD_NAV_LOITER_UNLIM)
_CMD_LOITER_TURNS = int(mav.MAV_CMD_NAV_LOITER_TURNS)
_CMD_LOITER_TIME = int(mav.MAV_CMD_NAV_LOITER_TIME)
_CMD_RTL = int(mav.MAV_CMD_NAV_RETURN_TO_LAUNCH)
_CMD_LAND = int(mav.MAV_CMD_NAV_LAND)
_CMD_TAKEOFF = int(mav.MAV_CMD_NAV_TAKEOFF)
_CMD_CHANGE_SPEED = int(mav.MAV_CMD_DO_CHANGE_SPEED)
_CMD_JUMP = int(mav.MAV_CMD_DO_JUMP)
_CMD_LAND_START = int(mav.MAV_CMD_DO_LAND_START)
_CMD_NAV_LAST = int(mav.MAV_CMD_NAV_LAST)
_AMSL_FRAMES = frozenset({int(mav.MAV_FRAME_GLOBAL), int(mav.MAV_FRAME_GLOBAL_INT)})

SEVERITY_EMERGENCY = int(mav.MAV_SEVERITY_EMERGENCY)
SEVERITY_WARNING = int(mav.MAV_SEVERITY_WARNING)
SEVERITY_NOTICE = int(mav.MAV_SEVERITY_NOTICE)
SEVERITY_INFO = int(mav.MAV_SEVERITY_INFO)

_CMD_NAMES = {
    _CMD_WAYPOINT: "WP",
    _CMD_LOITER_UNLIM: "LoitUnlim",
    _CMD_LOITER_TURNS: "LoitTurns",
    _CMD_LOITER_TIME: "LoitTime",
    _CMD_RTL: "RTL",
    _CMD_LAND: "Land",
    _CMD_TAKEOFF: "Takeoff",
    _CMD_CHANGE_SPEED: "ChangeSpeed",
    _CMD_JUMP: "Jump",
    _CMD_LAND_START: "LandStart",
}


class Mode(enum.IntEnum):
    """ArduPlane custom_mode numbers."""

    MANUAL = 0
    CIRCLE = 1
    STABILIZE = 2
    TRAINING = 3
    ACRO = 4
    FBWA = 5
    FBWB = 6
    CRUISE = 7
    AUTOTUNE = 8
    AUTO = 10
    RTL = 11
    LOITER = 12
    TAKEOFF = 13
    GUIDED = 15


SIMULATED_MODES = frozenset(
    {
        Mode.MANUAL,
        Mode.CIRCLE,
        Mode.STABILIZE,
        Mode.FBWA,
        Mode.FBWB,
        Mode.CRUISE,
        Mode.AUTO,
        Mode.RTL,
        Mode.LOITER,
        Mode.TAKEOFF,
        Mode.GUIDED,
    }
)
_LEVEL_MODES = frozenset({Mode.MANUAL, Mode.STABILIZE, Mode.FBWA, Mode.FBWB, Mode.CRUISE})


@dataclass(frozen=True, slots=True)
class ItemReached:
    seq: int


@dataclass(frozen=True, slots=True)
class CurrentChanged:
    seq: int


@dataclass(frozen=True, slots=True)
class Text:
    severity: int  # MAV_SEVERITY_*
    text: str


Event = ItemReached | CurrentChanged | Text


@dataclass(frozen=True, slots=True)
class NavStatus:
    """What NAV_CONTROLLER_OUTPUT reports."""

    nav_roll_deg: float
    nav_pitch_deg: float
    nav_bearing_deg: float
    target_bearing_deg: float
    wp_dist_m: float
    alt_error_m: float
    aspd_error_m_s: float
    xtrack_error_m: float


# Internal state codes: plain ints, as enum attribute look-ups cost ~0.1 us each in the step.
_NAV_IDLE, _NAV_TAKEOFF, _NAV_WAYPOINT, _NAV_LOITER, _NAV_LAND, _NAV_LEVEL, _NAV_CIRCLE = range(7)
_LOITER_UNLIM, _LOITER_TURNS, _LOITER_TIME, _LOITER_RTL = range(4)  # RTL: NAV_RETURN_TO_LAUNCH
_LAND_APPROACH, _LAND_FLARE, _LAND_GROUND = range(3)
_MISSION_STOPPED, _MISSION_RUNNING, _MISSION_COMPLETE = range(3)
_AUTO = Mode.AUTO
_GUIDED = Mode.GUIDED
_TAKEOFF_MODE = Mode.TAKEOFF


Point = tuple[float, float, float]  # lat_deg, lon_deg, alt_m AMSL

CRASH_DETECT_DELAY_S = 3.5
"""From impact to "Crash detected": ArduPlane's is_flying() probability, low-passed at 5 Hz
(0.85 per update), falls below 0.1 about 3 s after the aircraft stops, then
CRASH_DETECTION_DELAY_MS (500 ms) of debounce (ArduPlane/is_flying.cpp)."""
CRASH_TEXT = "Crash detected"
"""ArduPlane's STATUSTEXT (MAV_SEVERITY_EMERGENCY) when CRASH_DETECT disarms it."""


class Ground(Protocol):
    """Terrain elevation AMSL (m) at a point (:class:`sitl_stub.terrain.GridTerrain`)."""

    def elevation_m(self, lat_deg: float, lon_deg: float) -> float: ...


class Autopilot:
    """One simulated ArduPlane: call ``step(dt_s)`` on the simulated clock."""

    def __init__(
        self,
        *,
        params: AirframeParams,
        home_lat_deg: float,
        home_lon_deg: float,
        home_alt_m: float,
        heading_deg: float = 0.0,
        airborne_alt_m: float | None = None,
        wind: Wind = Wind(0.0, 0.0, 0.0),  # noqa: B008 - frozen value
        rng: np.random.Generator,
        time_s: float = 0.0,
        terrain: Ground | None = None,
    ) -> None:
        """On the ground at home, disarmed in MANUAL; with ``airborne_alt_m`` (AMSL) flying
        over home at that altitude instead (see :meth:`_start_airborne`)."""
        self._params = params
        self._wind = wind
        self._home: Point = (home_lat_deg, home_lon_deg, home_alt_m)
        self._terrain = terrain
        # Home is on the ground: the terrain is moved by what it misses home's altitude by
        # (grid interpolation, a rounded --home; more than metres is a wrong home).
        self._ground_offset_m = 0.0
        if terrain is not None:
            self._ground_offset_m = home_alt_m - terrain.elevation_m(home_lat_deg, home_lon_deg)
        self._ground_m = home_alt_m
        self._crash_s: float | None = None  # when it hit the ground (simulated s)
        self._crash_detected = False
        self._prng = model.NormalStream(rng)
        self._state = FlightState(
            time_s=time_s,
            lat_deg=home_lat_deg,
            lon_deg=home_lon_deg,
            alt_m=home_alt_m,
            airspeed_m_s=0.0,
            heading_rad=math.radians(heading_deg) % _TWO_PI,
            wind_north_m_s=wind.north_m_s,
            wind_east_m_s=wind.east_m_s,
            on_ground=True,
        )
        self._mode = Mode.MANUAL
        self._armed = False
        self._mission: tuple[MissionItem, ...] = ()
        self._current_seq = 0
        self._mission_state = _MISSION_STOPPED
        self._pending: list[Event] = []
        self._new_airspeed_m_s = -1.0
        self._target_airspeed_m_s = params.airspeed_cruise_m_s
        self._eas2tas = 1.0  # at the current altitude (1 when airspeeds are flown as TAS)
        self._tas_scale = 1.0  # true airspeed per unit of demanded EAS (EAS2TAS x (1 + bias))
        self._update_tas_scale()
        self._guided_target: Point | None = None
        # navigation targets
        self._nav = _NAV_IDLE
        self._prev_wp: Point = self._home
        self._next_wp: Point = self._home
        self._next_wp_crosstrack = False
        self._crosstrack = False
        self._alt_slew = False
        self._hold_alt_m = home_alt_m
        self._next_turn_angle_deg = 90.0
        self._acceptance_m = -1.0  # < 0: use turn distance
        # takeoff
        self._takeoff_alt_m = home_alt_m
        self._takeoff_heading_rad: float | None = None
        # loiter
        self._loiter_kind = _LOITER_UNLIM
        self._loiter_radius_m = abs(params.loiter_radius_m)
        self._loiter_dir = -1 if params.loiter_radius_m < 0 else 1
        self._loiter_xtrack = False
        self._loiter_target_s = 0.0  # turns (rad) or seconds
        self._loiter_primary = True
        self._loiter_start_s: float | None = None
        self._loiter_sum_rad = 0.0
        self._loiter_summing = False
        self._loiter_old_bearing = 0.0
        self._on_circle = False
        self._guided_reached = False
        # landing
        self._land_stage = _LAND_APPROACH
        self._touchdown_s = 0.0
        self._scales_for: FlightState | None = None
        self._scales_kn_ke = (1.0, 1.0)
        # NAV_CONTROLLER_OUTPUT
        self._nav_roll = 0.0
        self._nav_pitch = 0.0
        self._nav_bearing = 0.0
        self._target_bearing = 0.0
        self._wp_dist = 0.0
        self._alt_error = 0.0
        self._xtrack = 0.0
        # Arms from disarmed; changes into AUTO from another mode.
        self.counters: dict[str, int] = {"arms": 0, "auto_mode_changes": 0}
        if airborne_alt_m is not None:
            self._start_airborne(airborne_alt_m)

    def _start_airborne(self, alt_m: float) -> None:
        """Already flying when the ground station takes over: armed, over home at ``alt_m``
        AMSL on the start heading, wings level at the cruise airspeed (true airspeed from
        the EAS), in LOITER circling that point at WP_LOITER_RAD, as an ArduPlane switched
        to LOITER in flight (ArduPlane/mode_loiter.cpp: ``do_loiter_at_location`` here)."""
        st = self._state
        self._state = replace(st, alt_m=alt_m, on_ground=False)
        self._update_tas_scale()
        tas = self._params.airspeed_cruise_m_s * self._tas_scale
        self._state = replace(
            self._state,
            airspeed_m_s=tas,
            vel_north_m_s=tas * math.cos(st.heading_rad) + st.wind_north_m_s,
            vel_east_m_s=tas * math.sin(st.heading_rad) + st.wind_east_m_s,
        )
        self._armed = True  # not counted in "arms": no one armed it
        self._enter_mode(Mode.LOITER, self._pending)

    # ------------------------------------------------------------------ properties
    @property
    def state(self) -> FlightState:
        return self._state

    @property
    def mode(self) -> Mode:
        return self._mode

    @property
    def terrain(self) -> Ground | None:
        """The terrain it flies over (None: flat at home altitude)."""
        return self._terrain

    @property
    def ground_alt_m(self) -> float:
        """The ground elevation AMSL under the aircraft at its last step."""
        return self._ground_m

    @property
    def crash_time_s(self) -> float | None:
        """When it hit the ground outside a landing (simulated s), None if it has not."""
        return self._crash_s

    @property
    def crash_detected(self) -> bool:
        """It has said "Crash detected" (HEARTBEAT MAV_STATE_EMERGENCY from then on)."""
        return self._crash_detected

    @property
    def armed(self) -> bool:
        return self._armed

    @property
    def params(self) -> AirframeParams:
        return self._params

    def set_params(self, params: AirframeParams) -> None:
        self._params = params

    @property
    def wind(self) -> Wind:
        return self._wind

    def set_wind(self, wind: Wind) -> None:
        self._wind = wind

    @property
    def home(self) -> tuple[float, float, float]:
        return self._home

    @property
    def mission(self) -> tuple[MissionItem, ...]:
        return self._mission

    @property
    def current_seq(self) -> int:
        return self._current_seq

    @property
    def eas2tas(self) -> float:
        """True/equivalent airspeed ratio at the aircraft's altitude (ISA; 1 if flown as TAS)."""
        return self._eas2tas

    @property
    def eas_m_s(self) -> float:
        """The aircraft's true equivalent airspeed."""
        return self._state.airspeed_m_s / self._eas2tas

    @property
    def measured_eas_m_s(self) -> float:
        """The equivalent airspeed the autopilot believes (its sensor, with the speed bias)."""
        return self._state.airspeed_m_s / self._tas_scale

    def _update_tas_scale(self) -> None:
        p = self._params
        self._eas2tas = eas2tas(self._state.alt_m) if p.equivalent_airspeed else 1.0
        self._tas_scale = self._eas2tas * (1.0 + p.speed_bias)

    @property
    def current_nav_index(self) -> int | None:
        """The index of the NAV command being flown in a running AUTO mission, else None."""
        return self._current_seq if self._mission_state == _MISSION_RUNNING else None

    @property
    def target_airspeed_m_s(self) -> float:
        return self._target_airspeed_m_s

    @property
    def nav(self) -> NavStatus:
        return NavStatus(
            nav_roll_deg=math.degrees(self._nav_roll),
            nav_pitch_deg=math.degrees(self._nav_pitch),
            nav_bearing_deg=math.degrees(self._nav_bearing) % 360.0,
            target_bearing_deg=math.degrees(self._target_bearing) % 360.0,
            wp_dist_m=self._wp_dist,
            alt_error_m=self._alt_error,
            aspd_error_m_s=self._target_airspeed_m_s - self.measured_eas_m_s,
            xtrack_error_m=self._xtrack,
        )

    @property
    def guided_target(self) -> tuple[float, float, float] | None:
        return self._guided_target

    # ------------------------------------------------------------------ commands
    def arm(self, force: bool = False) -> tuple[bool, str]:
        """Arm (re-arming an armed vehicle succeeds, as on ArduPilot); a wreck is refused."""
        if self._crash_s is not None:
            return False, "Arm refused: the aircraft crashed"
        if not self._armed:
            self.counters["arms"] += 1
        self._armed = True
        return True, ""

    def disarm(self, force: bool = False) -> tuple[bool, str]:
        """Disarm; refused while flying unless forced (then the aircraft glides down)."""
        if self._armed and not self._state.on_ground and not force:
            return False, "Disarm refused: vehicle is flying (use force)"
        self._armed = False
        return True, ""

    def set_mode(self, mode: Mode) -> bool:
        """Change mode; False for modes not simulated. Re-selecting the current mode is a no-op."""
        try:
            mode = Mode(mode)
        except ValueError:
            return False
        if mode not in SIMULATED_MODES:
            return False
        if mode == self._mode:
            return True
        self._enter_mode(mode, self._pending)
        return True

    def set_guided_target(self, lat_deg: float, lon_deg: float, alt_m: float) -> bool:
        """Set the GUIDED loiter point (alt_m AMSL); False unless in GUIDED mode."""
        if self._mode != _GUIDED:
            return False
        self._guided_target = (lat_deg, lon_deg, alt_m)
        self._start_guided()
        return True

    def replace_mission(self, items: Sequence[MissionItem]) -> None:
        """Install a newly uploaded mission; AUTO continues at the same index (clamped).

        The current NAV item restarts only if its content changed (the leg start is kept).
        """
        old = self._mission
        self._mission = tuple(items)
        n = len(self._mission)
        cur = self._current_seq
        if self._mode == _AUTO and self._mission_state == _MISSION_RUNNING:
            if n <= 1:
                self._mission_complete(self._pending)
                return
            new_cur = min(max(cur, 1), n - 1)
            if new_cur == cur and cur < len(old) and _same_item(old[cur], self._mission[cur]):
                if self._nav == _NAV_WAYPOINT:
                    self._setup_turn_angle(cur)
                return
            self._advance_nav(new_cur, self._pending, keep_prev=True)
        else:
            new_cur = min(cur, max(n - 1, 0))
            if self._mission_state == _MISSION_COMPLETE:
                self._mission_state = _MISSION_STOPPED
            self._set_current_seq(new_cur, self._pending)

    def set_current(self, seq: int) -> bool:
        """MISSION_SET_CURRENT / DO_SET_MISSION_CURRENT; 0 means 1. False if out of range."""
        n = len(self._mission)
        if n <= 1 or seq < 0 or seq >= n:
            return False
        seq = max(seq, 1)
        if self._mode == _AUTO and self._mission_state == _MISSION_RUNNING:
            self._advance_nav(seq, self._pending)
        else:
            self._mission_state = _MISSION_STOPPED
            self._set_current_seq(seq, self._pending)
        return True

    def start_mission(self, first: int = 0, last: int = 0) -> bool:
        """MAV_CMD_MISSION_START: AUTO from item max(first, 1); ``last`` is ignored."""
        n = len(self._mission)
        start = max(first, 1)
        if n <= 1 or start >= n:
            return False
        if self._mode != _AUTO:
            self._enter_mode(Mode.AUTO, self._pending, start_at=start)
        else:
            self._prev_wp = self._next_wp = self._here()
            self._next_wp_crosstrack = False
            self._advance_nav(start, self._pending)
        return True

    def change_speed(self, speed_type: int, speed_m_s: float, throttle_pct: float = -1) -> bool:
        """DO_CHANGE_SPEED as a command: accepted only in AUTO or GUIDED."""
        if self._mode not in (_AUTO, _GUIDED):
            return False
        return self._do_change_speed(speed_type, speed_m_s, throttle_pct, self._pending)

    def change_altitude(self, alt_amsl_m: float) -> bool:
        """MAV_CMD_DO_CHANGE_ALTITUDE as ArduPlane takes it, in any mode: the waypoint flown
        to now (``next_WP_loc``) gets ``alt_amsl_m``, gone to at once rather than along the
        leg's slope (``reset_offset_altitude``); the next waypoint brings the mission's
        altitude back (ArduPlane/GCS_Mavlink.cpp, handle_command_int_DO_CHANGE_ALTITUDE and
        handle_change_alt_request). Holding (LOITER, RTL's circle) it is the held altitude."""
        if not math.isfinite(alt_amsl_m):
            return False
        nw = self._next_wp
        self._next_wp = (nw[0], nw[1], alt_amsl_m)
        self._alt_slew = False
        if self._nav >= _NAV_LEVEL or self._nav == _NAV_IDLE:
            self._hold_alt_m = alt_amsl_m
        return True

    # ------------------------------------------------------------------ stepping
    def step(self, dt_s: float) -> list[Event]:
        """Advance by dt_s simulated seconds; returns the events in the order they happened."""
        events = self._pending
        self._pending = []
        if dt_s <= 0.0:
            return events
        n = math.ceil(dt_s / self._params.max_substep_s - 1e-9)
        if n <= 1:
            self._substep(dt_s, events)  # the usual case: one physics step, one sub-step
            return events
        h = dt_s / n
        for _ in range(n):
            self._substep(h, events)
        return events

    def _fly(
        self,
        st: FlightState,
        airspeed_m_s: float,
        bank_rad: float,
        climb_m_s: float,
        ground_m: float,
        motor: bool,
        dt_s: float,
        climb_max_m_s: float = 0.0,
    ) -> FlightState:
        """The airframe flown one sub-step from ``st`` (:func:`model.step_scalar`) with these
        controls, in this vehicle's wind and airspeed error."""
        return model.step_scalar(
            st, airspeed_m_s, bank_rad, climb_m_s, ground_m, motor, self._params, self._wind,
            dt_s, self._prng, self._tas_scale, climb_max_m_s, m_per_deg=self._scales(),
        )  # fmt: skip

    def _substep(self, dt_s: float, events: list[Event]) -> None:
        st = self._state
        if self._crash_s is not None:
            self._wreck(st, dt_s, events)
            return
        p = self._params
        if self._terrain is not None:
            self._ground_m = (
                self._terrain.elevation_m(st.lat_deg, st.lon_deg) + self._ground_offset_m
            )
        ground = self._ground_m
        self._update_tas_scale()
        scale = self._tas_scale
        if not self._armed:
            self._nav_roll = 0.0
            self._target_airspeed_m_s = p.airspeed_cruise_m_s
            self._state = self._fly(
                st, p.airspeed_cruise_m_s * scale, 0.0, 0.0, ground, False, dt_s
            )
            self._roll_on_terrain(st, dt_s)
            return
        mode = self._mode
        if mode == _AUTO and self._mission_state == _MISSION_RUNNING:
            self._verify_nav(st, events)
            mode = self._mode  # mission end may have switched to RTL
        if st.on_ground and self._nav != _NAV_TAKEOFF and self._nav != _NAV_LAND:
            # Throttle suppressed on the ground outside a takeoff.
            self._state = self._fly(st, 0.0, 0.0, 0.0, ground, False, dt_s)
            self._roll_on_terrain(st, dt_s)
            return
        if (
            mode == _TAKEOFF_MODE
            and self._nav == _NAV_TAKEOFF
            and not st.on_ground
            and st.alt_m >= self._takeoff_alt_m
        ):
            rel = st.alt_m - self._home[2]
            events.append(Text(SEVERITY_INFO, f"Takeoff complete at {rel:.2f}m"))
            self._start_loiter_here()
        eas, bank, climb, motor = self._guidance(st, mode)
        climb_max = p.takeoff_climb_rate_m_s if self._nav == _NAV_TAKEOFF else 0.0
        self._state = new = self._fly(st, eas * scale, bank, climb, ground, motor, dt_s, climb_max)
        if not st.on_ground and (new.alt_m < ground or (new.on_ground and self._nav != _NAV_LAND)):
            self._crash(ground)
            return
        self._roll_on_terrain(st, dt_s)
        if self._nav == _NAV_LAND:
            self._after_land_step(st, events)
        elif mode == _GUIDED and not self._guided_reached and self._loiter_start_s is not None:
            self._guided_reached = True
            events.append(ItemReached(0))

    def _roll_on_terrain(self, prev: FlightState, dt_s: float) -> None:
        """On the ground over terrain, the wheels are on the ground where the step ended, and
        roll up or down it: that vertical speed is the climb a takeoff starts from (else the
        first metres after lift-off up a slope would be below it)."""
        st = self._state
        if self._terrain is None or not st.on_ground:
            return
        if st.lat_deg == prev.lat_deg and st.lon_deg == prev.lon_deg:
            return
        ground = self._terrain.elevation_m(st.lat_deg, st.lon_deg) + self._ground_offset_m
        # Down a slope the wheels are held on the ground until the wing lifts: a lift-off
        # starts level there, not sinking with the slope it rolled down.
        climb = max((ground - prev.alt_m) / dt_s, 0.0)
        self._state = replace(st, alt_m=ground, climb_rate_m_s=climb)

    def _crash(self, ground_m: float) -> None:
        """Flown into the ground: wrecked where it hit, on the ground and still."""
        st = self._state
        self._crash_s = st.time_s
        self._nav_roll = 0.0
        self._state = replace(
            st,
            alt_m=ground_m,
            airspeed_m_s=0.0,
            roll_rad=0.0,
            pitch_rad=0.0,
            climb_rate_m_s=0.0,
            vel_north_m_s=0.0,
            vel_east_m_s=0.0,
            on_ground=True,
        )

    def _wreck(self, st: FlightState, dt_s: float, events: list[Event]) -> None:
        """A wreck only ages; its crash is detected (said, and disarmed) after the delay."""
        self._state = replace(st, time_s=st.time_s + dt_s)
        assert self._crash_s is not None
        if not self._crash_detected and st.time_s + dt_s >= self._crash_s + CRASH_DETECT_DELAY_S:
            self._crash_detected = True
            self._armed = False
            events.append(Text(SEVERITY_EMERGENCY, CRASH_TEXT))

    # ------------------------------------------------------------------ guidance
    def _guidance(self, st: FlightState, mode: Mode) -> tuple[float, float, float, bool]:
        """Navigation and altitude/speed demands: (EAS, bank, climb rate, motor on)."""
        p = self._params
        kn, ke = self._scales()
        nav = self._nav
        tas = self._airspeed_target(st, mode)
        climb_ff = 0.0
        motor = True
        nw = self._next_wp
        bn = (nw[0] - st.lat_deg) * kn
        be = (nw[1] - st.lon_deg) * ke
        self._wp_dist = math.hypot(bn, be)
        self._target_bearing = math.atan2(be, bn)
        self._xtrack = 0.0
        target_alt = nw[2]

        if nav == _NAV_TAKEOFF:
            if self._takeoff_heading_rad is None:
                self._takeoff_heading_rad = st.heading_rad
            err = wrap_pi(self._takeoff_heading_rad - st.course_rad)
            bank = clamp(1.5 * err, -p.max_bank_rad / 3.0, p.max_bank_rad / 3.0)
            self._nav_bearing = self._takeoff_heading_rad
            self._target_bearing = self._takeoff_heading_rad
            self._wp_dist = 0.0
            climb = p.takeoff_climb_rate_m_s
            target_alt = self._takeoff_alt_m
            self._nav_roll = bank
            self._alt_error = target_alt - st.alt_m
            self._nav_pitch = math.atan2(climb, max(st.airspeed_m_s, 1.0))
            self._target_airspeed_m_s = tas
            return tas, bank, climb, True
        if nav >= _NAV_LEVEL or nav == _NAV_IDLE:
            bank = p.max_bank_rad / 3.0 if nav == _NAV_CIRCLE else 0.0
            target_alt = self._hold_alt_m
            self._wp_dist = 0.0
            self._nav_bearing = st.heading_rad
            self._target_bearing = st.heading_rad
        else:
            pw = self._prev_wp
            an = (pw[0] - st.lat_deg) * kn
            ae = (pw[1] - st.lon_deg) * ke
            vn = st.vel_north_m_s
            ve = st.vel_east_m_s
            if nav == _NAV_LOITER:
                lat_acc = self._loiter_nav(st, an, ae, bn, be)
            elif nav == _NAV_LAND and self._land_stage != _LAND_APPROACH:
                # Flare / roll-out: hold the approach course.
                leg = math.atan2(be - ae, bn - an) if math.hypot(bn - an, be - ae) > 1 else 0.0
                err = wrap_pi(leg - st.course_rad)
                lat_acc = GRAVITY_M_S2 * math.tan(clamp(1.5 * err, -0.2, 0.2))
                self._nav_bearing = leg
            else:
                tn, te = bn, be
                fn, fe = an, ae  # where the tracked line starts
                if nav == _NAV_LAND:
                    # Track the approach line beyond the touchdown point.
                    d = math.hypot(bn - an, be - ae)
                    if d > 1.0:
                        tn = bn + (bn - an) / d * 5000.0
                        te = be + (be - ae) / d * 5000.0
                elif not self._crosstrack:
                    # The first leg of a mission (or after a takeoff) is flown straight at
                    # the waypoint from where the aircraft is, not along the line from where
                    # the leg began: ArduPlane/commands_logic.cpp verify_nav_wp,
                    # update_waypoint(current_loc, next_WP_loc) unless auto_state.crosstrack.
                    fn = fe = 0.0
                lat_acc, self._nav_bearing, self._xtrack = l1_waypoint(
                    fn, fe, tn, te, vn, ve, st.heading_rad, p.l1_period_s, p.l1_damping
                )
            bank = math.atan(lat_acc / GRAVITY_M_S2)
            # Altitude: linear slew along the leg, with the slope as feed-forward.
            on_circle_target = nav == _NAV_LOITER and self._loiter_start_s is not None
            if self._alt_slew and not on_circle_target:
                ln = bn - an
                le = be - ae
                leg2 = ln * ln + le * le
                if leg2 > 1.0:
                    prop = (-an * ln - ae * le) / leg2
                    dz = nw[2] - pw[2]
                    if prop <= 0.0:
                        target_alt = pw[2]
                    elif prop >= 1.0:
                        target_alt = nw[2]
                    else:
                        target_alt = pw[2] + dz * prop
                        climb_ff = dz * (vn * ln + ve * le) / leg2
            if nav == _NAV_LAND and self._land_stage != _LAND_APPROACH:
                climb_ff = -p.land_flare_sink_m_s
                target_alt = st.alt_m
                motor = self._land_stage == _LAND_FLARE
        # The limits written out (not clamp()/max() calls): this runs every physics step.
        max_bank = p.max_bank_rad
        bank = -max_bank if bank < -max_bank else max_bank if bank > max_bank else bank
        climb = climb_ff + (target_alt - st.alt_m) / p.alt_time_constant_s
        self._nav_roll = bank
        self._alt_error = target_alt - st.alt_m
        sink_max = p.sink_rate_max_m_s
        climb_max = p.climb_rate_max_m_s
        airspeed = st.airspeed_m_s
        self._nav_pitch = math.atan2(
            -sink_max if climb < -sink_max else climb_max if climb > climb_max else climb,
            1.0 if airspeed < 1.0 else airspeed,
        )
        self._target_airspeed_m_s = tas
        return tas, bank, climb, motor

    def _airspeed_target(self, st: FlightState, mode: Mode) -> float:
        """The demanded equivalent airspeed (what the autopilot's sensor should read)."""
        p = self._params
        if self._nav == _NAV_LAND:
            tas = p.land_airspeed_m_s
        elif mode in (_AUTO, _GUIDED) and self._new_airspeed_m_s > 0.0:
            tas = self._new_airspeed_m_s
        else:
            tas = p.airspeed_cruise_m_s
        if p.min_groundspeed_m_s > 0.0 and not st.on_ground:
            fwd = st.vel_north_m_s * math.cos(st.heading_rad) + st.vel_east_m_s * math.sin(
                st.heading_rad
            )
            under = p.min_groundspeed_m_s - fwd
            if under > 0.0:
                tas = max(tas, (st.airspeed_m_s + under) / self._tas_scale)
        return clamp(tas, p.airspeed_min_m_s, p.airspeed_max_m_s)

    def _loiter_nav(self, st: FlightState, an: float, ae: float, cn: float, ce: float) -> float:
        """update_loiter + loiter_angle_update; returns the lateral acceleration demand."""
        p = self._params
        r = self._loiter_radius_m
        vn = st.vel_north_m_s
        ve = st.vel_east_m_s
        if self._loiter_start_s is None and self._crosstrack and self._wp_dist > 3.0 * r:
            lat_acc, self._nav_bearing, self._xtrack = l1_waypoint(
                an, ae, cn, ce, vn, ve, st.heading_rad, p.l1_period_s, p.l1_damping
            )
            self._on_circle = False
        else:
            lat_acc, self._nav_bearing, self._on_circle = l1_loiter(
                cn, ce, r, self._loiter_dir, vn, ve, st.heading_rad, p.l1_period_s, p.l1_damping
            )
            self._xtrack = self._wp_dist - r
        if self._loiter_start_s is None:
            ln = cn - an
            le = ce - ae
            leg2 = ln * ln + le * le
            prop = 1.0 if leg2 < 0.001 else (-an * ln - ae * le) / leg2
            if self._on_circle or prop > 1.0:
                self._loiter_start_s = st.time_s
        # Angle flown around the centre, summed from when first on the circle.
        bearing = self._target_bearing
        if not self._loiter_summing:
            if self._on_circle:
                self._loiter_summing = True
                self._loiter_sum_rad = 1e-6
        else:
            self._loiter_sum_rad += wrap_pi(bearing - self._loiter_old_bearing) * self._loiter_dir
        self._loiter_old_bearing = bearing
        return lat_acc

    # ------------------------------------------------------------------ mission logic
    def _here(self) -> Point:
        return (self._state.lat_deg, self._state.lon_deg, self._state.alt_m)

    def _item_point(self, item: MissionItem) -> Point:
        alt = item.z if item.frame in _AMSL_FRAMES else self._home[2] + item.z
        if item.x == 0 and item.y == 0:
            here = self._here()
            return (here[0], here[1], here[2] if item.z == 0.0 else alt)
        return (item.lat_deg, item.lon_deg, alt)

    def _set_current_seq(self, seq: int, events: list[Event]) -> None:
        if seq != self._current_seq:
            self._current_seq = seq
            events.append(CurrentChanged(seq))

    def _enter_mode(self, mode: Mode, events: list[Event], start_at: int | None = None) -> None:
        was_auto = self._mode == _AUTO
        if mode == _AUTO and not was_auto:
            self.counters["auto_mode_changes"] += 1
        self._mode = mode
        self._new_airspeed_m_s = -1.0
        if was_auto and self._mission_state == _MISSION_RUNNING:
            self._mission_state = _MISSION_STOPPED
        here = self._here()
        self._loiter_reset()
        if mode == _AUTO:
            self._prev_wp = self._next_wp = here
            self._next_wp_crosstrack = False
            n = len(self._mission)
            if start_at is not None:
                first = start_at
            elif self._mission_state == _MISSION_COMPLETE or self._current_seq < 1:
                first = 1
            else:
                first = self._current_seq
            self._mission_state = _MISSION_RUNNING
            if first >= n:
                self._mission_complete(events)
            else:
                self._advance_nav(first, events)
        elif mode == Mode.RTL:
            self._start_rtl()
        elif mode == Mode.LOITER:
            self._start_loiter_here()
        elif mode == _GUIDED:
            self._guided_target = None
            self._start_guided()
        elif mode == _TAKEOFF_MODE:
            self._nav = _NAV_TAKEOFF
            self._takeoff_alt_m = self._home[2] + self._params.takeoff_mode_alt_m
            self._takeoff_heading_rad = None if self._state.on_ground else self._state.heading_rad
        elif mode == Mode.CIRCLE:
            self._nav = _NAV_CIRCLE
            self._hold_alt_m = here[2]
        else:
            self._nav = _NAV_LEVEL
            self._hold_alt_m = here[2]

    def _loiter_reset(self) -> None:
        self._loiter_start_s = None
        self._loiter_sum_rad = 0.0
        self._loiter_summing = False
        self._loiter_primary = True
        self._on_circle = False

    def _set_loiter_radius(self, radius_param: float) -> None:
        if abs(radius_param) > 1.0:
            self._loiter_radius_m = abs(radius_param)
            self._loiter_dir = -1 if radius_param < 0 else 1
        else:
            lr = self._params.loiter_radius_m
            self._loiter_radius_m = abs(lr) if abs(lr) > 1.0 else 60.0
            self._loiter_dir = -1 if lr < 0 else 1

    def _start_rtl(self) -> None:
        h = self._home
        rtl = self._params.rtl_altitude_m
        alt = self._state.alt_m if rtl < 0 else h[2] + rtl
        self._prev_wp = self._here()
        self._next_wp = (h[0], h[1], alt)
        self._crosstrack = False
        self._next_wp_crosstrack = True
        self._alt_slew = self._state.alt_m > alt
        self._nav = _NAV_LOITER
        self._loiter_kind = _LOITER_UNLIM
        self._set_loiter_radius(0.0)
        self._loiter_reset()

    def _start_loiter_here(self) -> None:
        here = self._here()
        self._prev_wp = self._next_wp = here
        self._crosstrack = False
        self._alt_slew = False
        self._nav = _NAV_LOITER
        self._loiter_kind = _LOITER_UNLIM
        self._set_loiter_radius(0.0)
        self._loiter_reset()

    def _start_guided(self) -> None:
        target = self._guided_target or self._here()
        self._prev_wp = self._here()
        self._next_wp = target
        self._crosstrack = False
        self._alt_slew = self._state.alt_m > target[2]
        self._nav = _NAV_LOITER
        self._loiter_kind = _LOITER_UNLIM
        self._set_loiter_radius(0.0)
        self._loiter_reset()
        self._guided_reached = self._guided_target is None

    def _set_next_wp(self, point: Point) -> None:
        """ArduPlane set_next_WP: new leg from the old target (or from here)."""
        st = self._state
        if self._next_wp_crosstrack:
            self._prev_wp = self._next_wp
            self._crosstrack = True
        else:
            self._prev_wp = self._here()
            self._next_wp_crosstrack = True
            self._crosstrack = False
        self._next_wp = point
        if self._line_proportion(self._prev_wp, point) >= 1.0:
            self._prev_wp = self._here()
        rel = st.alt_m - self._home[2]
        self._alt_slew = rel > 20.0 or st.alt_m > point[2]
        self._loiter_reset()

    def _line_proportion(self, a: Point, b: Point) -> float:
        """Location::line_path_proportion: how far along a->b the vehicle is (1 = at b)."""
        st = self._state
        kn, ke = self._scales()
        an = (a[0] - st.lat_deg) * kn
        ae = (a[1] - st.lon_deg) * ke
        ln = (b[0] - a[0]) * kn
        le = (b[1] - a[1]) * ke
        d2 = ln * ln + le * le
        if d2 < 0.001:
            return 1.0
        return (-an * ln - ae * le) / d2

    def _next_nav_index(self, after: int) -> int | None:
        for i in range(after + 1, len(self._mission)):
            if self._mission[i].command <= _CMD_NAV_LAST:
                return i
        return None

    def _setup_turn_angle(self, seq: int) -> None:
        nxt = self._next_nav_index(seq)
        self._next_turn_angle_deg = 90.0
        if nxt is None:
            return
        item = self._mission[nxt]
        if item.x == 0 and item.y == 0:
            return
        a, b = self._prev_wp, self._next_wp
        c = self._item_point(item)
        leg = _bearing(a, b)
        nxt_leg = _bearing(b, c)
        self._next_turn_angle_deg = math.degrees(wrap_pi(nxt_leg - leg))

    def _advance_nav(self, start: int, events: list[Event], keep_prev: bool = False) -> None:
        """AP_Mission::advance_current_nav_cmd: run DO items up to the next NAV item, start it."""
        i = start
        n = len(self._mission)
        while i < n:
            item = self._mission[i]
            if item.command <= _CMD_NAV_LAST:
                if self._start_nav(i, item, events, keep_prev):
                    self._set_current_seq(i, events)
                    return
            else:
                self._run_do(i, item, events)
            i += 1
        self._mission_complete(events)

    def _mission_complete(self, events: list[Event]) -> None:
        self._mission_state = _MISSION_COMPLETE
        if self._mode == _AUTO:
            events.append(Text(SEVERITY_INFO, "Mission complete, changing mode to RTL"))
            self._enter_mode(Mode.RTL, events)
            self._mission_state = _MISSION_COMPLETE

    def _run_do(self, seq: int, item: MissionItem, events: list[Event]) -> None:
        events.append(Text(SEVERITY_INFO, f"Mission: {seq} {_CMD_NAMES.get(item.command, '?')}"))
        if item.command == _CMD_CHANGE_SPEED:
            self._do_change_speed(int(item.param1), item.param2, item.param3, events)
        events.append(ItemReached(seq))

    def _do_change_speed(
        self, speed_type: int, speed_m_s: float, throttle_pct: float, events: list[Event]
    ) -> bool:
        p = self._params
        if speed_type == 0:
            if speed_m_s == -2.0:
                self._new_airspeed_m_s = -1.0
                return True
            if speed_m_s == -1.0:
                return True
            # ArduPlane compares in float (ArduPlane/commands_logic.cpp do_change_speed:
            # ``speed_target_ms >= aparm.airspeed_min.get() && <= aparm.airspeed_max.get()``)
            # and its AIRSPEED_* are REAL32 parameters: a limit such as 29.2 is met by the
            # command that asks for it, which arrives as the same float32.
            if _f32(p.airspeed_min_m_s) <= _f32(speed_m_s) <= _f32(p.airspeed_max_m_s):
                self._new_airspeed_m_s = speed_m_s
                events.append(Text(SEVERITY_INFO, f"Set airspeed {int(speed_m_s)} m/s"))
                return True
        elif speed_type == 1:
            if speed_m_s == -1.0:
                return True
            if speed_m_s == -2.0:
                speed_m_s = 0.0
            if speed_m_s >= 0.0:
                self._params = replace(p, min_groundspeed_m_s=speed_m_s)
                events.append(Text(SEVERITY_INFO, f"Set groundspeed {int(speed_m_s)}"))
                return True
        return 0.0 < throttle_pct <= 100.0 and speed_m_s == -1.0

    def _start_nav(self, seq: int, item: MissionItem, events: list[Event], keep_prev: bool) -> bool:
        cmd = item.command
        if cmd not in _CMD_NAMES or cmd in (_CMD_CHANGE_SPEED, _CMD_JUMP, _CMD_LAND_START):
            events.append(Text(SEVERITY_WARNING, f"Skipping unsupported nav command #{cmd}"))
            return False
        events.append(Text(SEVERITY_INFO, f"Mission: {seq} {_CMD_NAMES[cmd]}"))
        st = self._state
        self._acceptance_m = -1.0
        if cmd == _CMD_TAKEOFF:
            self._nav = _NAV_TAKEOFF
            self._prev_wp = self._next_wp = self._here()
            self._takeoff_alt_m = self._home[2] + item.z
            if item.frame in _AMSL_FRAMES:
                self._takeoff_alt_m = item.z
            self._takeoff_heading_rad = None if st.on_ground else st.heading_rad
            return True
        if cmd == _CMD_RTL:
            h = self._home
            rtl = self._params.rtl_altitude_m
            point = (h[0], h[1], st.alt_m if rtl < 0 else h[2] + rtl)
        else:
            point = self._item_point(item)
        if keep_prev:
            self._next_wp = point
            self._loiter_reset()
        else:
            self._set_next_wp(point)
        self._setup_turn_angle(seq)
        if cmd == _CMD_WAYPOINT:
            self._nav = _NAV_WAYPOINT
            if item.param2 > 0.0:
                self._acceptance_m = item.param2
            elif item.param3 > 0.0:
                self._acceptance_m = 0.0
        elif cmd == _CMD_LAND:
            self._nav = _NAV_LAND
            self._land_stage = _LAND_APPROACH
            self._alt_slew = True
        else:
            self._nav = _NAV_LOITER
            self._loiter_xtrack = item.param4 > 0.0
            if cmd == _CMD_LOITER_TURNS:
                self._loiter_kind = _LOITER_TURNS
                self._loiter_target_s = max(item.param1, 0.0) * _TWO_PI
            elif cmd == _CMD_LOITER_TIME:
                self._loiter_kind = _LOITER_TIME
                self._loiter_target_s = max(item.param1, 0.0)
            elif cmd == _CMD_RTL:
                self._loiter_kind = _LOITER_RTL
            else:
                self._loiter_kind = _LOITER_UNLIM
            self._set_loiter_radius(0.0 if cmd == _CMD_RTL else item.param3)
        return True

    def _verify_nav(self, st: FlightState, events: list[Event]) -> None:
        """Check the current NAV item; on completion report it and advance."""
        nav = self._nav
        seq = self._current_seq
        done = False
        if nav == _NAV_TAKEOFF:
            if not st.on_ground and st.alt_m >= self._takeoff_alt_m:
                rel = st.alt_m - self._home[2]
                events.append(Text(SEVERITY_INFO, f"Takeoff complete at {rel:.2f}m"))
                self._prev_wp = self._next_wp = self._here()
                # verify_takeoff: "don't cross-track on completion of takeoff".
                self._next_wp_crosstrack = False
                done = True
        elif nav == _NAV_WAYPOINT:
            dist = self._dist_to(self._next_wp)
            acc = self._acceptance_m
            if acc < 0.0:
                gs = st.groundspeed_m_s
                l1 = 0.3183099 * self._params.l1_damping * self._params.l1_period_s * gs
                acc = min(self._params.wp_radius_m, l1)
                turn = abs(self._next_turn_angle_deg)
                if turn < 90.0:
                    acc *= turn / 90.0
            if dist <= acc:
                events.append(Text(SEVERITY_INFO, f"Reached waypoint #{seq} dist {int(dist)}m"))
                done = True
            elif self._line_proportion(self._prev_wp, self._next_wp) >= 1.0:
                events.append(Text(SEVERITY_INFO, f"Passed waypoint #{seq} dist {int(dist)}m"))
                done = True
        elif nav == _NAV_LOITER:
            done = self._verify_loiter(st, seq, events)
        if done:
            events.append(ItemReached(seq))
            self._advance_nav(seq + 1, events)

    def _verify_loiter(self, st: FlightState, seq: int, events: list[Event]) -> bool:
        kind = self._loiter_kind
        if kind == _LOITER_UNLIM:
            return False
        if kind == _LOITER_RTL:
            if self._dist_to(self._next_wp) <= self._params.wp_radius_m or self._on_circle:
                events.append(Text(SEVERITY_INFO, "Reached RTL location"))
                return True
            return False
        if self._loiter_primary:
            if kind == _LOITER_TURNS:
                primary_done = self._loiter_sum_rad > self._loiter_target_s
            else:
                if self._loiter_start_s is None:
                    return False
                primary_done = st.time_s - self._loiter_start_s > self._loiter_target_s
            if not primary_done:
                return False
            self._loiter_primary = False
            self._loiter_sum_rad = 1e-6
        if self._loiter_heading_ok(st, seq):
            msg = "Loiter orbit complete" if kind == _LOITER_TURNS else "Loiter time complete"
            events.append(Text(SEVERITY_INFO, msg))
            return True
        return False

    def _loiter_heading_ok(self, st: FlightState, seq: int) -> bool:
        """verify_loiter_heading: leave when the ground course points at the next NAV point."""
        nxt = self._next_nav_index(seq)
        if nxt is None:
            return True
        item = self._mission[nxt]
        target = self._item_point(item)
        if _distance(self._next_wp, target) < abs(self._params.loiter_radius_m):
            return True
        if item.command == _CMD_RTL:
            target = self._home
        bearing = _bearing(self._here(), target)
        err = abs(wrap_pi(bearing - st.course_rad))
        extra = 10.0 * math.floor(self._loiter_sum_rad / _TWO_PI)
        if err <= math.radians(10.0 + extra):
            if self._loiter_xtrack:
                self._next_wp = self._here()
            return True
        return False

    def _dist_to(self, point: Point) -> float:
        st = self._state
        kn, ke = self._scales()
        return math.hypot((point[0] - st.lat_deg) * kn, (point[1] - st.lon_deg) * ke)

    def _scales(self) -> tuple[float, float]:
        """Metres per degree of latitude / longitude at the vehicle (cached per state; the
        physics step moves the vehicle with them too)."""
        st = self._state
        if self._scales_for is not st:
            self._scales_kn_ke = model.metres_per_degree(st.lat_deg, st.alt_m)
            self._scales_for = st
        return self._scales_kn_ke

    def _after_land_step(self, prev: FlightState, events: list[Event]) -> None:
        st = self._state
        p = self._params
        if self._land_stage == _LAND_APPROACH:
            height = st.alt_m - max(self._next_wp[2], self._home[2])
            sink = max(-st.climb_rate_m_s, 0.0)
            if not st.on_ground and (height <= p.land_flare_alt_m or height <= 2.0 * sink):
                self._land_stage = _LAND_FLARE
                events.append(Text(SEVERITY_INFO, f"Flare {height:.1f}m sink={sink:.2f}"))
        if self._land_stage != _LAND_GROUND and st.on_ground and not prev.on_ground:
            self._land_stage = _LAND_GROUND
            self._touchdown_s = st.time_s
            events.append(Text(SEVERITY_INFO, "Landed"))
        elif (
            self._land_stage == _LAND_GROUND
            and p.land_disarm_delay_s > 0.0
            and st.time_s - self._touchdown_s >= p.land_disarm_delay_s
        ):
            self._armed = False
            events.append(Text(SEVERITY_INFO, "Throttle disarmed"))


def _same_item(a: MissionItem, b: MissionItem) -> bool:
    return (a.frame, a.command, a.param1, a.param2, a.param3, a.param4, a.x, a.y, a.z) == (
        b.frame,
        b.command,
        b.param1,
        b.param2,
        b.param3,
        b.param4,
        b.x,
        b.y,
        b.z,
    )


def _distance(a: Point, b: Point) -> float:
    n, e = model.offset_ne_m(a[0], a[1], 0.0, b[0], b[1])
    return math.hypot(n, e)


def _bearing(a: Point, b: Point) -> float:
    n, e = model.offset_ne_m(a[0], a[1], 0.0, b[0], b[1])
    return math.atan2(e, n)


def _f32(x: float) -> float:
    """``x`` as the float32 a MAVLink field or a REAL32 parameter holds."""
    return float(np.float32(x))
