"""The service's vehicle ids, and the live vehicles registered with ``POST /v1/vehicles`` kept
in the store so that they outlive the service process.

Every vehicle the service shows has an API id (``v1``, ``v2``, ...), never given twice: a
registered vehicle's, kept with its connection, the system id asked for and whether it was
registered with a signing key (the key itself is kept for the link only, in the fleet); a
bundled simulator vehicle's, for as long as its simulator runs (not kept). A service started
again reads the kept registrations (:meth:`Registry.load`): the same ids for the same
connections, the next id after the highest kept. It opens their links again in the background
(:meth:`Registry.reopen`), trying every :data:`REOPEN_RETRY_S` until the vehicle answers; one
registered with a signing key waits for the key (``POST /v1/vehicles`` again with it).
"""

from __future__ import annotations

import asyncio
import logging
import re
from collections.abc import Iterable
from typing import Any

from gcs.errors import GcsError
from gcs.service.fleet import Fleet
from gcs.store.repository import Registration, Store

__all__ = ["REOPEN_RETRY_S", "Registry"]

log = logging.getLogger(__name__)

REOPEN_RETRY_S = 3.0
"""How long (wall s) a kept vehicle's link that heard no vehicle within the fleet's wait
(:attr:`Fleet.wait_s`; it tries to connect again within it, every 5 s at most) stays closed
before it is opened again."""

_ID = re.compile(r"v([0-9]+)")


class Registry:
    """The API ids of the vehicles the service shows, and the registrations kept in the store
    (see the module); reopens the links of kept vehicles in the background."""

    def __init__(self, store: Store, fleet: Fleet, *, retry_s: float = REOPEN_RETRY_S) -> None:
        self.store = store
        self.fleet = fleet
        self.retry_s = retry_s
        self.ids: dict[str, str] = {}
        """API id -> connection, in the order the ids were given."""
        self.kept: dict[str, Registration] = {}
        """Connection -> its registration, as the store keeps it."""
        self.last_word: dict[str, dict[str, Any]] = {}
        """Connection -> the vehicle's view as a flight's worker last told it (its last word
        while the service has no link of its own to it)."""
        self._numbered = 0
        self._keeping = asyncio.Lock()
        self._reopening: dict[str, asyncio.Task[None]] = {}
        self._closed = False

    def load(self) -> list[Registration]:
        """Take the registrations an earlier service process kept (their ids and
        connections); the next id given follows the highest kept. Returns them."""
        kept = sorted(self.store.registered_vehicles(), key=lambda r: _number(r.id))
        for reg in kept:
            self.kept[reg.connection] = reg
            self.ids[reg.id] = reg.connection
            self._numbered = max(self._numbered, _number(reg.id))
        return kept

    # -- ids ------------------------------------------------------------------------------------

    def id_of(self, connection: str) -> str | None:
        return next((vid for vid, conn in self.ids.items() if conn == connection), None)

    def name(self, connection: str) -> str:
        """The API id of the vehicle at ``connection`` (a new one the first time: ids are
        never given twice, even once a vehicle has gone)."""
        vid = self.id_of(connection)
        if vid is None:
            self._numbered += 1
            vid = f"v{self._numbered}"
            self.ids[vid] = connection
        return vid

    def forget(self, connections: Iterable[str]) -> None:
        """These vehicles are no longer the service's (bundled simulator vehicles gone with
        their simulator); kept registrations stay."""
        gone = set(connections) - set(self.kept)
        self.ids = {vid: conn for vid, conn in self.ids.items() if conn not in gone}

    # -- kept registrations ---------------------------------------------------------------------

    async def keep(self, connection: str, system_id: int | None, *, signed: bool) -> str:
        """Keep the registration of the vehicle at ``connection`` (its link open, its
        HEARTBEAT heard); returns its id (the one it already had, if any).

        Raises
        ------
        StoreError
            The store did not keep it (a new id given for it is taken back).
        """
        known = self.id_of(connection) is not None
        vid = self.name(connection)
        async with self._keeping:  # one write at a time: a second of the same id updates
            try:
                reg = await asyncio.to_thread(
                    self.store.register_vehicle, vid, connection, system_id=system_id, signed=signed
                )
            except BaseException:
                if not known:
                    del self.ids[vid]
                raise
        self.kept[connection] = reg
        return vid

    def key_needed(self, connection: str) -> bool:
        """Registered with a signing key that this process does not have (it is not kept)."""
        reg = self.kept.get(connection)
        return reg is not None and reg.signed and connection not in self.fleet.signing

    def reopen(self, connection: str) -> None:
        """Open the link to the kept vehicle at ``connection`` in the background, again every
        :data:`REOPEN_RETRY_S` until it answers (nothing for a vehicle not kept, one already
        held, or one whose signing key is needed; nothing once closed)."""
        if (
            self._closed
            or connection not in self.kept
            or connection in self._reopening
            or self.fleet.held(connection) is not None
            or self.key_needed(connection)
        ):
            return
        task = asyncio.get_running_loop().create_task(self._reach(self.kept[connection]))
        self._reopening[connection] = task
        task.add_done_callback(lambda t: self._done(connection, t))

    def _done(self, connection: str, task: asyncio.Task[None]) -> None:
        if self._reopening.get(connection) is task:
            del self._reopening[connection]

    def reopening(self, connection: str) -> bool:
        return connection in self._reopening

    async def _reach(self, reg: Registration) -> None:
        while True:
            try:
                await self.fleet.vehicle(reg.connection, reg.system_id)
            except ValueError as err:  # accepted when it was registered: not expected
                log.error("vehicle %s (%s): not reopened: %s", reg.id, reg.connection, err)
                return
            except (GcsError, TimeoutError, OSError) as err:
                log.info("vehicle %s (%s): %s; tried again in %g s",
                         reg.id, reg.connection, err, self.retry_s)  # fmt: skip
            else:
                log.info("vehicle %s (%s): its link is open again", reg.id, reg.connection)
                return
            await asyncio.sleep(self.retry_s)

    async def stop_reopening(self, connection: str) -> None:
        """Stop opening the link to ``connection`` in the background (its attempt's link
        closed before this returns)."""
        task = self._reopening.pop(connection, None)
        if task is not None:
            task.cancel()
            await asyncio.wait([task])

    async def close(self) -> None:
        """Stop every reopening (their links closed)."""
        self._closed = True
        tasks = list(self._reopening.values())
        self._reopening.clear()
        for task in tasks:
            task.cancel()
        if tasks:
            await asyncio.wait(tasks)


def _number(vehicle_id: str) -> int:
    """The number of an API id (``v12`` -> 12; 0 for an id not of that form)."""
    m = _ID.fullmatch(vehicle_id)
    return int(m.group(1)) if m else 0
