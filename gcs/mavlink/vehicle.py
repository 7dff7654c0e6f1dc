"""One vehicle on a link: its live telemetry state and the operations addressed to it.

A :class:`Vehicle` attaches a :class:`~gcs.mavlink.telemetry.TelemetryReducer` to the link (so its
state is always current) and forwards missions and commands to ``gcs.mavlink.mission_client`` and
``gcs.mavlink.commands`` with its system id. Commands of the same kind to the same vehicle are
serialised: two identical COMMAND_LONGs in flight cannot be told apart by their ACKs.
"""

from __future__ import annotations

import asyncio
from collections.abc import Sequence
from typing import Any

from gcs.mavlink import commands, mission_client
from gcs.mavlink.dialect import mavlink2
from gcs.mavlink.link import Link
from gcs.mavlink.telemetry import TelemetryReducer, VehicleState
from planner.mission import MissionItem


class Vehicle:
    """Vehicle ``system_id`` (autopilot component ``component_id``) reached over ``link``."""

    def __init__(self, link: Link, system_id: int, component_id: int = 1) -> None:
        self.link = link
        self.system_id = system_id
        self.component_id = component_id
        self.telemetry = TelemetryReducer(system_id, component_id)
        self._detach = link.add_listener(self.telemetry.update)
        self._command_locks: dict[int, asyncio.Lock] = {}

    def close(self) -> None:
        """Stop following the vehicle's telemetry (the link stays open)."""
        self._detach()

    @property
    def state(self) -> VehicleState:
        return self.telemetry.state

    @property
    def autopilot(self) -> int | None:
        peer = self.link.vehicles.get(self.system_id)
        return None if peer is None else peer.autopilot

    # -- missions ------------------------------------------------------------------------

    async def upload_mission(self, items: Sequence[MissionItem], **kwargs: Any) -> None:
        await mission_client.upload_mission(
            self.link, self.system_id, items, target_component=self.component_id, **kwargs
        )

    async def download_mission(self, **kwargs: Any) -> list[MissionItem]:
        return await mission_client.download_mission(
            self.link, self.system_id, target_component=self.component_id, **kwargs
        )

    async def mission_difference(self, items: Sequence[MissionItem], **kwargs: Any) -> int | None:
        """Download the vehicle's mission: the index of the first item of ``items`` it does not
        hold as its autopilot stores it, or None when it holds exactly ``items``."""
        got = await self.download_mission(**kwargs)
        return mission_client.held_difference(self.link, self.system_id, items, got)

    async def clear_mission(self, **kwargs: Any) -> None:
        await mission_client.clear_mission(
            self.link, self.system_id, target_component=self.component_id, **kwargs
        )

    async def set_current_item(self, seq: int, **kwargs: Any) -> None:
        await mission_client.set_current_item(
            self.link, self.system_id, seq, target_component=self.component_id, **kwargs
        )

    # -- commands ------------------------------------------------------------------------

    def _lock(self, command: int) -> asyncio.Lock:
        return self._command_locks.setdefault(command, asyncio.Lock())

    async def arm(self, *, force: bool = False, **options: Any) -> None:
        """Arm; ``options``: ``timeout_s``, ``retries`` (see :mod:`gcs.mavlink.commands`)."""
        async with self._lock(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM):
            await commands.arm(
                self.link,
                self.system_id,
                force=force,
                target_component=self.component_id,
                **options,
            )

    async def disarm(self, *, force: bool = False) -> None:
        async with self._lock(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM):
            await commands.disarm(
                self.link, self.system_id, force=force, target_component=self.component_id
            )

    async def set_mode(self, mode: str, **options: Any) -> None:
        async with self._lock(mavlink2.MAV_CMD_DO_SET_MODE):
            await commands.set_mode(
                self.link,
                self.system_id,
                mode,
                autopilot=self.autopilot,
                target_component=self.component_id,
                **options,
            )

    async def start_mission(self, first: int = 0, last: int = 0) -> None:
        async with self._lock(mavlink2.MAV_CMD_MISSION_START):
            await commands.start_mission(
                self.link, self.system_id, first, last, target_component=self.component_id
            )

    async def change_altitude(
        self, alt_m: float, *, above_home: bool = False, **options: Any
    ) -> None:
        """The altitude of the waypoint flown to now (AMSL, or above home)."""
        async with self._lock(mavlink2.MAV_CMD_DO_CHANGE_ALTITUDE):
            await commands.change_altitude(
                self.link,
                self.system_id,
                alt_m,
                above_home=above_home,
                target_component=self.component_id,
                **options,
            )

    async def change_speed(
        self, speed_m_s: float, *, airspeed: bool = True, **options: Any
    ) -> None:
        async with self._lock(mavlink2.MAV_CMD_DO_CHANGE_SPEED):
            await commands.change_speed(
                self.link,
                self.system_id,
                speed_m_s,
                airspeed=airspeed,
                target_component=self.component_id,
                **options,
            )
