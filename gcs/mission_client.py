"""Mission transfers over a :class:`gcs.link.Link`: the thin asyncio runner.

Each function builds one sans-IO transfer from :mod:`gcs.mission_protocol`, subscribes to
the target's replies before sending anything, feeds every reply and every timer tick into
it and sends what it returns; it returns the result or raises a
:class:`gcs.mission_errors.MissionError` subclass. Nothing waits without a bound: besides the
transfer's own timeouts and retries, a watchdog ends a transfer that has not moved (no new
step and no progress) for longer than the transfer's own limits allow.

Transfers with one vehicle over one link run one at a time (a later call waits for the
earlier one): two transfers would each take the other's MISSION_REQUESTs and ACKs.

Items are :class:`planner.mission.MissionItem`. For the flown mission (type 0) ArduPilot
keeps home at item 0: upload a home or placeholder item 0 (``compile_mission`` does), and
expect a download to give the vehicle's home there.
"""

from __future__ import annotations

import asyncio
import weakref
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any, Final

from gcs.mission_errors import MissionMismatch, MissionTimeout
from gcs.mission_protocol import Clear, Download, SetCurrent, Transfer, Upload
from planner.mission import MissionItem, command_name, items_equal

if TYPE_CHECKING:
    from gcs.link import Link, Subscription

__all__ = [
    "DEFAULT_RETRIES",
    "DEFAULT_TIMEOUT_S",
    "Progress",
    "clear_mission",
    "download_mission",
    "run_transfer",
    "set_current_item",
    "upload_mission",
]

DEFAULT_TIMEOUT_S: Final = 1.5
DEFAULT_RETRIES: Final = 5

Progress = Callable[[int, int], None]
"""Called with (done, total) items whenever a transfer moves on."""

# One lock per (link, vehicle): transfers with one vehicle on one link take turns.
_locks: weakref.WeakKeyDictionary[Any, dict[int, asyncio.Lock]] = weakref.WeakKeyDictionary()


def _lock(link: Link, target_system: int) -> asyncio.Lock:
    per_link = _locks.setdefault(link, {})
    lock = per_link.get(target_system)
    if lock is None:
        lock = per_link[target_system] = asyncio.Lock()
    return lock


def _watchdog_s(transfer: Transfer) -> float:
    """Longest time a correct transfer can go without a new step or progress, plus margin."""
    return 4.0 * (transfer.retries + 1) * transfer.timeout_s + 2.0 * transfer.timeout_s


async def run_transfer(link: Link, transfer: Transfer, *, progress: Progress | None = None) -> None:
    """Run ``transfer`` over ``link`` to its end; raises its typed error if it failed."""
    loop = asyncio.get_running_loop()
    async with _lock(link, transfer.target_system):
        with link.subscribe(types=transfer.message_types, system_id=transfer.target_system) as sub:
            try:
                await _drive(link, transfer, sub, progress)
            finally:
                # Cancelled from outside, or the watchdog fired: tell the vehicle.
                for out in transfer.cancel(loop.time()):
                    link.send(out)
    err = transfer.error()
    if err is not None:
        raise err


async def _drive(
    link: Link, transfer: Transfer, sub: Subscription, progress: Progress | None
) -> None:
    loop = asyncio.get_running_loop()
    for out in transfer.start(loop.time()):
        link.send(out)
    watchdog_s = _watchdog_s(transfer)
    moved_s = loop.time()
    state = (transfer.step, transfer.progress)
    while not transfer.done:
        now = loop.time()
        deadline = transfer.next_deadline()
        wait_s = watchdog_s if deadline is None else max(0.0, deadline - now)
        wait_s = min(wait_s, max(0.0, moved_s + watchdog_s - now))
        msg = await sub.get(timeout_s=wait_s)
        now = loop.time()
        outgoing = transfer.handle(msg, now) if msg is not None else []
        outgoing += transfer.tick(now)
        for out in outgoing:
            link.send(out)
        new_state = (transfer.step, transfer.progress)
        if new_state != state:
            if progress is not None and new_state[1] != state[1]:
                progress(*new_state[1])
            state, moved_s = new_state, now
        elif not transfer.done and now - moved_s >= watchdog_s:
            raise MissionTimeout(
                f"{transfer.describe()} timed out: no progress for {watchdog_s:.3g} s",
                vehicle=transfer.target_system,
                mission_type=transfer.mission_type,
                operation=transfer.operation,
            )


def _own_system(link: Link) -> int | None:
    return getattr(link, "system_id", None)


def _own_component(link: Link) -> int | None:
    return getattr(link, "component_id", None)


async def upload_mission(
    link: Link,
    target_system: int,
    items: Sequence[MissionItem],
    *,
    mission_type: int = 0,
    target_component: int = 1,
    timeout_s: float = DEFAULT_TIMEOUT_S,
    retries: int = DEFAULT_RETRIES,
    verify: bool = False,
    progress: Progress | None = None,
) -> None:
    """Upload ``items`` (seq = index, all of ``mission_type``) to vehicle ``target_system``.

    Item 0 of the flown mission (type 0) is home on ArduPilot: send a home or placeholder
    item there. No items clears the mission type (MISSION_COUNT 0). With ``verify=True`` the
    items are downloaded again and compared with :func:`planner.mission.items_equal` (item 0
    of type 0 and the ``current`` flags are not compared: the vehicle sets them); a difference
    raises :class:`MissionMismatch` naming the first differing item.

    Raises
    ------
    MissionInputError
        Items that cannot be sent (seq not the index, another mission type, int out of range).
    MissionError
        A subclass per MAV_MISSION_RESULT the vehicle answered (e.g. MissionInvalidItem naming
        the item), MissionTimeout, MissionProtocolError or MissionMismatch.
    """
    upload = Upload(
        items,
        target_system=target_system,
        target_component=target_component,
        mission_type=mission_type,
        timeout_s=timeout_s,
        retries=retries,
        own_system=_own_system(link),
        own_component=_own_component(link),
    )
    await run_transfer(link, upload, progress=progress)
    if not verify:
        return
    got = await download_mission(
        link,
        target_system,
        mission_type=mission_type,
        target_component=target_component,
        timeout_s=timeout_s,
        retries=retries,
    )
    _check_same(upload, list(items), got)


def _check_same(upload: Upload, sent: list[MissionItem], got: list[MissionItem]) -> None:
    def norm(items: list[MissionItem]) -> list[MissionItem]:
        return [replace(it, current=0) for it in items]

    home_is_vehicles = upload.mission_type == 0
    a, b = norm(sent), norm(got)
    if items_equal(a, b, compare_home=not home_is_vehicles):
        return
    where = upload.describe()
    if home_is_vehicles and not sent and len(got) == 1:
        return  # an empty mission reads back as home alone
    if len(a) != len(b):
        first = next(
            (k for k in range(min(len(a), len(b))) if not _same(a, b, k, home_is_vehicles)),
            min(len(a), len(b)),
        )
        msg = f"{where} verification failed: sent {len(a)} items, read back {len(b)}"
        msg += f"; first difference at item {first}"
    else:
        first = next(k for k in range(len(a)) if not _same(a, b, k, home_is_vehicles))
        msg = (
            f"{where} verification failed at item {first}: sent {_show(a[first])}, "
            f"read back {_show(b[first])}"
        )
    raise MissionMismatch(
        msg,
        vehicle=upload.target_system,
        seq=first,
        mission_type=upload.mission_type,
        operation="upload",
    )


def _same(a: list[MissionItem], b: list[MissionItem], k: int, skip_home: bool) -> bool:
    return (k == 0 and skip_home) or items_equal([a[k]], [b[k]])


def _show(it: MissionItem) -> str:
    return (
        f"{command_name(it.command)} frame {it.frame} params "
        f"({it.param1:g}, {it.param2:g}, {it.param3:g}, {it.param4:g}) "
        f"x {it.x} y {it.y} z {it.z:g}"
    )


async def download_mission(
    link: Link,
    target_system: int,
    *,
    mission_type: int = 0,
    target_component: int = 1,
    timeout_s: float = DEFAULT_TIMEOUT_S,
    retries: int = DEFAULT_RETRIES,
    progress: Progress | None = None,
) -> list[MissionItem]:
    """The vehicle's items of ``mission_type``, as received (type 0: item 0 is its home)."""
    download = Download(
        target_system=target_system,
        target_component=target_component,
        mission_type=mission_type,
        timeout_s=timeout_s,
        retries=retries,
        own_system=_own_system(link),
        own_component=_own_component(link),
    )
    await run_transfer(link, download, progress=progress)
    return list(download.items)


async def clear_mission(
    link: Link,
    target_system: int,
    *,
    mission_type: int = 0,
    target_component: int = 1,
    timeout_s: float = DEFAULT_TIMEOUT_S,
    retries: int = DEFAULT_RETRIES,
) -> None:
    """Delete the vehicle's items of ``mission_type`` (255: every type) with CLEAR_ALL."""
    clear = Clear(
        target_system=target_system,
        target_component=target_component,
        mission_type=mission_type,
        timeout_s=timeout_s,
        retries=retries,
        own_system=_own_system(link),
        own_component=_own_component(link),
    )
    await run_transfer(link, clear)


async def set_current_item(
    link: Link,
    target_system: int,
    seq: int,
    *,
    target_component: int = 1,
    timeout_s: float = DEFAULT_TIMEOUT_S,
    retries: int = DEFAULT_RETRIES,
) -> None:
    """Make ``seq`` the current mission item (MISSION_SET_CURRENT, confirmed by
    MISSION_CURRENT); a vehicle that refuses times out naming the item it still reports."""
    set_current = SetCurrent(
        seq,
        target_system=target_system,
        target_component=target_component,
        timeout_s=timeout_s,
        retries=retries,
        own_system=_own_system(link),
        own_component=_own_component(link),
    )
    await run_transfer(link, set_current)
