"""The vehicle's parameters: a small ArduPlane set over PARAM_REQUEST_LIST / _READ / _SET.

Each parameter is a field of the autopilot's :class:`~sitl_stub.model.AirframeParams`
(SYSID_THISMAV is the system id, read-only here). A PARAM_SET is answered with the value,
broadcast as ArduPilot does so every GCS sees it; a value outside the range changes nothing
and gets a STATUSTEXT warning, as does an unknown name (with no value then).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_stub.autopilot import Autopilot
from sitl_stub.mission_server import LinkId, addressed_to
from sitl_stub.model import AirframeParams


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


class ParameterHandlers:
    """PARAM_* messages, for the vehicle that mixes it in."""

    system_id: int
    component_id: int
    autopilot: Autopilot

    if TYPE_CHECKING:

        def emit(self, msg: Any, link: LinkId | None = None) -> None: ...

        def statustext(self, severity: int, text: str, link: LinkId | None = None) -> None: ...

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
