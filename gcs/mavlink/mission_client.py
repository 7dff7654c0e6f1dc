"""Mission transfers over a :class:`gcs.mavlink.link.Link`: the thin asyncio runner.

Each function builds one sans-IO transfer from :mod:`gcs.mavlink.mission_protocol`, subscribes
to the target's replies before sending anything, feeds every reply and every timer tick into it
and sends what it returns; it returns the result or raises a
:class:`gcs.mavlink.mission_errors.MissionError` subclass. Nothing waits without a bound:
besides the transfer's own timeouts and retries, a watchdog ends a transfer that has not moved
(no new step and no progress) for longer than the transfer's own limits allow.

Transfers with one vehicle over one link run one at a time (a later call waits for the
earlier one): two transfers would each take the other's MISSION_REQUESTs and ACKs.

Items are :class:`planner.mission.MissionItem`. For the flown mission (type 0) ArduPilot
keeps home at item 0: upload a home or placeholder item 0 (``compile_mission`` does), and
expect a download to give the vehicle's home there.
"""

from __future__ import annotations

import asyncio
import contextlib
import weakref
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, Final

from gcs.mavlink.mission_errors import MissionMismatch, MissionTimeout
from gcs.mavlink.mission_protocol import Clear, Download, SetCurrent, Transfer, Upload
from gcs.mavlink.retry import DEFAULT_POLICY, RetryPolicy, remember_rtt, rtt_hint_s
from planner.mission import (
    Autopilot,
    MissionItem,
    command_name,
    first_difference,
    stored_item,
)

if TYPE_CHECKING:
    from gcs.mavlink.link import Link

__all__ = [
    "DEFAULT_RETRIES",
    "DEFAULT_TIMEOUT_S",
    "DEFAULT_WINDOW",
    "OnTransfer",
    "Progress",
    "clear_mission",
    "download_mission",
    "run_transfer",
    "set_current_item",
    "upload_mission",
]

DEFAULT_TIMEOUT_S: Final = 1.5
DEFAULT_RETRIES: Final = 5
"""The MAVLink mission service's fixed timeout and retry count: what ``timeout_s=`` and
``retries=`` gave by default before the adaptive policy (:mod:`gcs.mavlink.retry`) replaced them."""
DEFAULT_WINDOW: Final = 8
"""Item requests outstanding in a download, and items sent ahead of the requests in an upload,
with a vehicle that answers any request and takes items in order ahead of its requests."""

Progress = Callable[[int, int], None]
"""Called with (done, total) items whenever a transfer moves on."""
OnTransfer = Callable[[Transfer], None]
"""Called with each transfer as it starts (an upload, then its verify download): its
``progress`` and ``counters`` can be read while it runs."""

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
    longest_wait_s = transfer.timeout_s or transfer.policy.max_rto_s
    return transfer.stall_limit_s + 2.0 * longest_wait_s


class _Driver:
    """Feeds one transfer from the link's reader callback and keeps its timers."""

    def __init__(self, link: Link, transfer: Transfer, progress: Progress | None) -> None:
        self.link = link
        self.transfer = transfer
        self.progress = progress
        self.loop = asyncio.get_running_loop()
        self.finished = asyncio.Event()
        self.state = (transfer.step, transfer.progress)
        self.moved_s = self.loop.time()

    def _send(self, outgoing: list[Any], now: float) -> None:
        for out in outgoing:
            self.link.send(out)
        new_state = (self.transfer.step, self.transfer.progress)
        if new_state != self.state:
            if self.progress is not None and new_state[1] != self.state[1]:
                self.progress(*new_state[1])
            self.state, self.moved_s = new_state, now
        if self.transfer.done:
            self.finished.set()

    def on_message(self, msg: Any, _rx_s: float) -> None:
        t = self.transfer
        if t.done or msg.get_srcSystem() != t.target_system:
            return
        now = self.loop.time()
        if msg.get_type() not in t.message_types:
            t.heard(now)  # a heartbeat or telemetry: the vehicle is there
            return
        self._send(t.handle(msg, now), now)

    async def run(self) -> None:
        t, loop = self.transfer, self.loop
        self._send(t.start(loop.time()), loop.time())
        watchdog_s = _watchdog_s(t)
        while not t.done:
            now = loop.time()
            deadline = t.next_deadline()
            wake_s = self.moved_s + watchdog_s if deadline is None else deadline
            wake_s = min(wake_s, self.moved_s + watchdog_s)
            if wake_s > now:
                # Replies are handled in on_message; wake only for a timer or the end.
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(wake_s - now):
                        await self.finished.wait()
                continue
            self._send(t.tick(now), now)
            await asyncio.sleep(0)  # never spin: a tick that left its deadline due yields
            if not t.done and now - self.moved_s >= watchdog_s:
                raise MissionTimeout(
                    f"{t.describe()} timed out: no progress for {watchdog_s:.3g} s",
                    vehicle=t.target_system,
                    mission_type=t.mission_type,
                    operation=t.operation,
                )


async def run_transfer(
    link: Link,
    transfer: Transfer,
    *,
    progress: Progress | None = None,
    on_transfer: OnTransfer | None = None,
) -> None:
    """Run ``transfer`` over ``link`` to its end; raises its typed error if it failed.

    Replies are handled in the link's reader callback, as they are parsed, and the answers go
    out at once: an exchange costs no task switch. The task here only keeps the timers.
    """
    async with _lock(link, transfer.target_system):
        if on_transfer is not None:
            on_transfer(transfer)
        driver = _Driver(link, transfer, progress)
        remove = link.add_listener(driver.on_message)
        try:
            await driver.run()
        finally:
            remove()
            remember_rtt(link, transfer.target_system, transfer.rtt)
            # Cancelled from outside, or the watchdog fired: tell the vehicle.
            for out in transfer.cancel(driver.loop.time()):
                link.send(out)
    err = transfer.error()
    if err is not None:
        raise err


def _options(
    link: Link,
    target_system: int,
    target_component: int,
    timeout_s: float | None,
    retries: int | None,
    policy: RetryPolicy | None = None,
    within_s: float | None = None,
) -> dict[str, Any]:
    """The keyword arguments every transfer takes: its target, timers and our own ids.

    The last transfer's round trip with this vehicle, else the link's TIMESYNC round trip,
    seeds the adaptive timeout.
    """
    return {
        "target_system": target_system,
        "target_component": target_component,
        "timeout_s": timeout_s,
        "retries": retries,
        "own_system": getattr(link, "system_id", None),
        "own_component": getattr(link, "component_id", None),
        "policy": policy or DEFAULT_POLICY,
        "rtt_hint_s": rtt_hint_s(link, target_system),
        "within_s": within_s,
    }


def _autopilot_of(link: Link, target_system: int) -> Autopilot:
    """The vehicle's autopilot from its HEARTBEAT on the link (UNKNOWN before one)."""
    peer = getattr(link, "vehicles", {}).get(target_system)
    return Autopilot.from_heartbeat(None if peer is None else int(peer.autopilot))


def _answers_any_request(link: Link, target_system: int) -> bool:
    """A vehicle known not to be PX4 (ArduPilot, the stub) takes requests and items ahead."""
    return _autopilot_of(link, target_system) not in (Autopilot.PX4, Autopilot.UNKNOWN)


async def upload_mission(
    link: Link,
    target_system: int,
    items: Sequence[MissionItem],
    *,
    mission_type: int = 0,
    target_component: int = 1,
    timeout_s: float | None = None,
    retries: int | None = None,
    verify: bool = False,
    progress: Progress | None = None,
    policy: RetryPolicy | None = None,
    within_s: float | None = None,
    autopilot: Autopilot | None = None,
    window: int | None = None,
    on_transfer: OnTransfer | None = None,
) -> None:
    """Upload ``items`` (seq = index, all of ``mission_type``) to vehicle ``target_system``.

    Item 0 of the flown mission (type 0) is home on ArduPilot: send a home or placeholder
    item there. No items clears the mission type (MISSION_COUNT 0). With ``verify=True`` the
    items are downloaded again and compared with what the vehicle should hold: the items as
    ``autopilot`` stores them (:func:`planner.mission.stored_item`: ArduPilot keeps altitudes
    in centimetres, its own frames and only some params; default: from the vehicle's
    HEARTBEAT). Item 0 of type 0 and the ``current`` flags are not compared (the vehicle sets
    them); a difference raises :class:`MissionMismatch` naming the first differing item.

    Timeouts: by default each resend waits a timeout that follows the measured round trip,
    and the upload fails only when the vehicle has been silent for ``policy.silence_s`` or the
    upload has not advanced for ``policy.stall_s`` (:mod:`gcs.mavlink.retry`). ``timeout_s`` fixes
    the resend timeout instead; ``retries`` limits the resends of one exchange. ``within_s``
    bounds the upload itself: a transfer still going then is cancelled (``MissionTimeout``)
    and the vehicle keeps the mission it had. ``window``: items sent ahead of the vehicle's
    requests, in order (default: :data:`DEFAULT_WINDOW` to a vehicle known not to be PX4,
    else 1: each item when it is asked for). The verify download runs with the same
    ``policy`` and the time left of ``within_s``.

    Raises
    ------
    MissionInputError
        Items that cannot be sent (seq not the index, another mission type, int out of range).
    MissionError
        A subclass per MAV_MISSION_RESULT the vehicle answered (e.g. MissionInvalidItem naming
        the item), MissionTimeout, MissionProtocolError or MissionMismatch.
    """
    opts = _options(link, target_system, target_component, timeout_s, retries, policy, within_s)
    ahead = _answers_any_request(link, target_system)
    if window is None:
        window = DEFAULT_WINDOW if ahead else 1
    upload = Upload(items, mission_type=mission_type, send_ahead=ahead, window=window, **opts)
    started_s = asyncio.get_running_loop().time()
    await run_transfer(link, upload, progress=progress, on_transfer=on_transfer)
    if not verify:
        return
    left_s = None
    if within_s is not None:
        # What is left of the bound (at least a moment: a verify that cannot run times out).
        left_s = max(1e-3, within_s - (asyncio.get_running_loop().time() - started_s))
    got = await download_mission(
        link,
        target_system,
        mission_type=mission_type,
        target_component=target_component,
        timeout_s=timeout_s,
        retries=retries,
        policy=policy,
        within_s=left_s,
        on_transfer=on_transfer,
    )
    if autopilot is None:
        autopilot = _autopilot_of(link, target_system)
    _check_same(upload, list(items), got, autopilot)


def held_difference(
    link: Link, target_system: int, sent: Sequence[MissionItem], got: Sequence[MissionItem]
) -> int | None:
    """Index of the first item of ``sent`` that the vehicle's downloaded mission ``got`` does
    not hold in its autopilot's stored form (item 0, home, is the vehicle's own); None: the
    vehicle holds ``sent``."""
    return first_difference(
        sent, got, autopilot=_autopilot_of(link, target_system), compare_home=False
    )


def _check_same(
    upload: Upload, sent: list[MissionItem], got: list[MissionItem], autopilot: Autopilot
) -> None:
    """Raise MissionMismatch unless ``got`` is ``sent`` as ``autopilot`` stores it."""
    home_is_vehicles = upload.mission_type == 0
    if home_is_vehicles and not sent and len(got) == 1:
        return  # an empty mission reads back as home alone
    first = first_difference(sent, got, autopilot=autopilot, compare_home=not home_is_vehicles)
    if first is None:
        return
    where = upload.describe()
    if len(sent) != len(got):
        msg = f"{where} verification failed: sent {len(sent)} items, read back {len(got)}"
        msg += f"; first difference at item {first}"
    else:
        msg = (
            f"{where} verification failed at item {first}: sent {_show(sent[first])}, "
            f"read back {_show(got[first])} ({autopilot.value} stores it as "
            f"{_show(stored_item(sent[first], autopilot))})"
        )
    raise MissionMismatch(
        msg,
        vehicle=upload.target_system,
        seq=first,
        mission_type=upload.mission_type,
        operation="upload",
    )


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
    timeout_s: float | None = None,
    retries: int | None = None,
    progress: Progress | None = None,
    policy: RetryPolicy | None = None,
    within_s: float | None = None,
    window: int | None = None,
    on_transfer: OnTransfer | None = None,
) -> list[MissionItem]:
    """The vehicle's items of ``mission_type``, as received (type 0: item 0 is its home).

    Timeouts as :func:`upload_mission`. ``window``: item requests outstanding at once
    (default: :data:`DEFAULT_WINDOW` for a vehicle known not to be PX4, else 1, in order).
    """
    opts = _options(link, target_system, target_component, timeout_s, retries, policy, within_s)
    if window is None:
        window = DEFAULT_WINDOW if _answers_any_request(link, target_system) else 1
    download = Download(mission_type=mission_type, window=window, **opts)
    await run_transfer(link, download, progress=progress, on_transfer=on_transfer)
    return list(download.items)


async def clear_mission(
    link: Link,
    target_system: int,
    *,
    mission_type: int = 0,
    target_component: int = 1,
    timeout_s: float | None = None,
    retries: int | None = None,
    policy: RetryPolicy | None = None,
) -> None:
    """Delete the vehicle's items of ``mission_type`` (255: every type) with CLEAR_ALL."""
    opts = _options(link, target_system, target_component, timeout_s, retries, policy)
    clear = Clear(mission_type=mission_type, **opts)
    await run_transfer(link, clear)


async def set_current_item(
    link: Link,
    target_system: int,
    seq: int,
    *,
    target_component: int = 1,
    timeout_s: float | None = None,
    retries: int | None = None,
    policy: RetryPolicy | None = None,
) -> None:
    """Make ``seq`` the current mission item (MISSION_SET_CURRENT, confirmed by
    MISSION_CURRENT); a vehicle that refuses times out naming the item it still reports."""
    opts = _options(link, target_system, target_component, timeout_s, retries, policy)
    set_current = SetCurrent(seq, **opts)
    await run_transfer(link, set_current)
