"""MAVLink commands: a sans-IO command transaction, its asyncio runner and helpers.

The transaction (:class:`CommandTransaction`) follows the MAVLink command protocol as MAVSDK's
``MavlinkCommandSender`` does: send COMMAND_LONG (or COMMAND_INT), wait for the COMMAND_ACK of
that command from the target, resend on timeout (COMMAND_LONG with ``confirmation`` + 1).
When to resend and when to give up is the mission transfers' policy (:mod:`gcs.mavlink.retry`): by
default the resend timeout follows the measured round trip (an ACK to a command sent once is a
sample), and the command fails when nothing has been heard from the vehicle for
``policy.silence_s`` or no answer came for ``policy.stall_s``, not after a count of resends.
``timeout_s`` fixes the timeout and ``retries`` bounds the resends (the MAVLink service's
1.5 s and 5 when both are given). ``MAV_RESULT_IN_PROGRESS`` stops the resends and pushes the
deadline out by ``in_progress_timeout_s`` on every progress report; the final ACK ends it. If
progress reports stop, the transaction times out without resending (a resend could restart a
long-running operation). It is driven by ``start``/``handle``/``heard``/``tick`` with the
caller's clock and returns the messages to send: no sockets, no clock, no asyncio.

:func:`command_long` / :func:`command_int` run a transaction over a :class:`gcs.mavlink.link.Link`
and return a :class:`CommandAck` or raise a :class:`CommandError` subclass.
"""

from __future__ import annotations

import asyncio
import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from gcs.errors import GcsError
from gcs.mavlink.modes import AUTOPILOT_PX4, mode_number, px4_main_sub
from gcs.mavlink.retry import DEFAULT_POLICY, RetryPolicy, RttEstimator, remember_rtt, rtt_hint_s

if TYPE_CHECKING:
    from gcs.mavlink.link import Link

DEFAULT_TIMEOUT_S: Final = 1.5
DEFAULT_RETRIES: Final = 5
"""The MAVLink command service's fixed timeout and resend count: what ``timeout_s=`` and
``retries=`` gave by default before the adaptive policy (:mod:`gcs.mavlink.retry`) replaced them."""
DEFAULT_IN_PROGRESS_TIMEOUT_S: Final = 5.0
FORCE_ARM_MAGIC: Final = 21196.0  # ArduPilot/PX4: param2 of ARM_DISARM bypasses checks

MAV_RESULT_ACCEPTED: Final = int(mavlink2.MAV_RESULT_ACCEPTED)
MAV_RESULT_TEMPORARILY_REJECTED: Final = int(mavlink2.MAV_RESULT_TEMPORARILY_REJECTED)
MAV_RESULT_DENIED: Final = int(mavlink2.MAV_RESULT_DENIED)
MAV_RESULT_UNSUPPORTED: Final = int(mavlink2.MAV_RESULT_UNSUPPORTED)
MAV_RESULT_FAILED: Final = int(mavlink2.MAV_RESULT_FAILED)
MAV_RESULT_IN_PROGRESS: Final = int(mavlink2.MAV_RESULT_IN_PROGRESS)
# common.xml values this pymavlink's ardupilotmega dialect may lack.
MAV_RESULT_CANCELLED: Final = 6
MAV_RESULT_COMMAND_LONG_ONLY: Final = 7
MAV_RESULT_COMMAND_INT_ONLY: Final = 8
MAV_RESULT_COMMAND_UNSUPPORTED_MAV_FRAME: Final = 9

_RESULT_NAMES: Final[dict[int, str]] = {
    **{k: e.name for k, e in mavlink2.enums["MAV_RESULT"].items() if not e.name.endswith("END")},
    MAV_RESULT_CANCELLED: "MAV_RESULT_CANCELLED",
    MAV_RESULT_COMMAND_LONG_ONLY: "MAV_RESULT_COMMAND_LONG_ONLY",
    MAV_RESULT_COMMAND_INT_ONLY: "MAV_RESULT_COMMAND_INT_ONLY",
    MAV_RESULT_COMMAND_UNSUPPORTED_MAV_FRAME: "MAV_RESULT_COMMAND_UNSUPPORTED_MAV_FRAME",
}
_MESSAGE_IDS: Final[dict[str, int]] = {
    cls.msgname: int(msg_id) for msg_id, cls in mavlink2.mavlink_map.items()
}


def command_name(command: int) -> str:
    """``MAV_CMD_...`` name of a command number (``MAV_CMD(n)`` if the dialect lacks it)."""
    entry = mavlink2.enums["MAV_CMD"].get(command)
    return entry.name if entry is not None else f"MAV_CMD({command})"


def result_name(result: int | None) -> str:
    """``MAV_RESULT_...`` name of a result (``timeout`` for None)."""
    if result is None:
        return "timeout"
    return _RESULT_NAMES.get(result, f"MAV_RESULT({result})")


# -- errors ------------------------------------------------------------------------------


class CommandError(GcsError):
    """A command that did not end in MAV_RESULT_ACCEPTED."""

    def __init__(
        self,
        message: str,
        *,
        command: int,
        result: int | None,
        vehicle: int,
        ack: CommandAck | None = None,
    ) -> None:
        super().__init__(message)
        self.command = command
        self.result = result
        self.vehicle = vehicle
        self.ack = ack


class CommandDenied(CommandError):
    """MAV_RESULT_DENIED: the command is valid but not allowed (bad parameters, state)."""


class CommandFailed(CommandError):
    """MAV_RESULT_FAILED (or an unknown result code): the command was tried and failed."""


class CommandUnsupported(CommandError):
    """MAV_RESULT_UNSUPPORTED (or the LONG-only / INT-only / frame variants)."""


class CommandTemporarilyRejected(CommandError):
    """MAV_RESULT_TEMPORARILY_REJECTED: try again later."""


class CommandCancelled(CommandError):
    """MAV_RESULT_CANCELLED: a long-running command was cancelled."""


class CommandTimeout(CommandError, TimeoutError):
    """No final COMMAND_ACK after every retry (or progress reports stopped)."""


_ERROR_BY_RESULT: Final[dict[int, type[CommandError]]] = {
    MAV_RESULT_DENIED: CommandDenied,
    MAV_RESULT_FAILED: CommandFailed,
    MAV_RESULT_UNSUPPORTED: CommandUnsupported,
    MAV_RESULT_COMMAND_LONG_ONLY: CommandUnsupported,
    MAV_RESULT_COMMAND_INT_ONLY: CommandUnsupported,
    MAV_RESULT_COMMAND_UNSUPPORTED_MAV_FRAME: CommandUnsupported,
    MAV_RESULT_TEMPORARILY_REJECTED: CommandTemporarilyRejected,
    MAV_RESULT_CANCELLED: CommandCancelled,
}


# -- values --------------------------------------------------------------------------------


class Step(enum.Enum):
    """Where a transaction is."""

    IDLE = "idle"
    AWAITING_ACK = "awaiting_ack"
    IN_PROGRESS = "in_progress"
    DONE = "done"


class Result(enum.Enum):
    """How a transaction ended (None while it runs)."""

    SUCCESS = "success"
    TEMPORARILY_REJECTED = "temporarily_rejected"
    DENIED = "denied"
    UNSUPPORTED = "unsupported"
    FAILED = "failed"
    CANCELLED = "cancelled"
    TIMEOUT = "timeout"


_RESULT_BY_MAV: Final[dict[int, Result]] = {
    MAV_RESULT_ACCEPTED: Result.SUCCESS,
    MAV_RESULT_TEMPORARILY_REJECTED: Result.TEMPORARILY_REJECTED,
    MAV_RESULT_DENIED: Result.DENIED,
    MAV_RESULT_UNSUPPORTED: Result.UNSUPPORTED,
    MAV_RESULT_COMMAND_LONG_ONLY: Result.UNSUPPORTED,
    MAV_RESULT_COMMAND_INT_ONLY: Result.UNSUPPORTED,
    MAV_RESULT_COMMAND_UNSUPPORTED_MAV_FRAME: Result.UNSUPPORTED,
    MAV_RESULT_FAILED: Result.FAILED,
    MAV_RESULT_CANCELLED: Result.CANCELLED,
}


@dataclass(frozen=True, slots=True)
class CommandAck:
    """The final COMMAND_ACK of a command (or the last one seen before a timeout)."""

    command: int
    result: int
    progress: int | None  # 0..100 from IN_PROGRESS acks; None if unknown (255) or none seen
    result_param2: int
    vehicle: int  # system id the ACK came from
    component: int
    attempts: int  # how many times the command was sent

    @property
    def result_name(self) -> str:
        return result_name(self.result)

    @property
    def command_name(self) -> str:
        return command_name(self.command)


@dataclass(frozen=True, slots=True)
class IntPosition:
    """COMMAND_INT's position fields: frame, x/y (lat/lon * 1e7 in global frames), z."""

    frame: int
    x: int = 0
    y: int = 0
    z: float = 0.0


# -- the sans-IO transaction -------------------------------------------------------------


class CommandTransaction:
    """One command and its acknowledgement, as a sans-IO state machine.

    ``start(now_s)`` returns the first message to send; ``handle(msg, now_s)`` takes every
    received message (non-matching ones are ignored); ``heard(now_s)`` says something else
    arrived from the vehicle (it is there); ``tick(now_s)`` handles deadlines and returns
    resends. ``done``, ``result``, ``ack`` and ``progress`` tell how it went; ``deadline_s``
    is when ``tick`` next has work to do.

    ``timeout_s`` None: resend after the adaptive timeout (``rtt_hint_s`` seeds it);
    ``retries`` None: fail after ``policy.silence_s`` without hearing the vehicle or
    ``policy.stall_s`` without an answer, else after ``retries`` resends.
    """

    def __init__(
        self,
        target_system: int,
        command: int,
        params: Sequence[float] = (),
        *,
        target_component: int = 1,
        position: IntPosition | None = None,
        own_system: int | None = None,
        own_component: int | None = None,
        timeout_s: float | None = None,
        retries: int | None = None,
        in_progress_timeout_s: float = DEFAULT_IN_PROGRESS_TIMEOUT_S,
        policy: RetryPolicy = DEFAULT_POLICY,
        rtt_hint_s: float | None = None,
    ) -> None:
        n_params = 4 if position is not None else 7
        if len(params) > n_params:
            kind = "COMMAND_INT" if position is not None else "COMMAND_LONG"
            raise ValueError(f"{kind} takes at most {n_params} params, got {len(params)}")
        if timeout_s is not None and not (math.isfinite(timeout_s) and timeout_s > 0):
            raise ValueError(f"timeout_s must be a positive number of seconds, got {timeout_s!r}")
        if not (math.isfinite(in_progress_timeout_s) and in_progress_timeout_s > 0):
            raise ValueError(
                f"in_progress_timeout_s must be a positive number, got {in_progress_timeout_s!r}"
            )
        if retries is not None and retries < 0:
            raise ValueError(f"retries must be >= 0, got {retries}")
        if not (0 <= target_system <= 255 and 0 <= target_component <= 255):
            raise ValueError(f"target {target_system}/{target_component} outside 0..255")
        self.target_system = target_system
        self.target_component = target_component
        self.command = command
        self.params: tuple[float, ...] = tuple(float(p) for p in params) + (0.0,) * (
            n_params - len(params)
        )
        self.position = position
        self.own_system = own_system
        self.own_component = own_component
        self.timeout_s = timeout_s
        """A fixed resend timeout (None: adaptive, from the measured round trip)."""
        self.retries = retries
        """Resends before giving up (None: the policy's silence and stall bounds decide)."""
        self.in_progress_timeout_s = in_progress_timeout_s
        self.policy = policy
        self.rtt = RttEstimator(policy, rtt_hint_s)
        self.step = Step.IDLE
        self.result: Result | None = None
        self.ack: CommandAck | None = None
        self.progress: int | None = None
        self.attempts = 0
        self.deadline_s = math.inf
        self.started_s: float | None = None
        self.finished_s: float | None = None
        self.timed_out_because = ""
        """Why a timeout ended it (the silence or stall bound; empty for the others)."""
        self._sent_s = 0.0  # the last send
        self._resend_s = math.inf  # when the next resend is due
        self._last_heard_s = 0.0

    # -- driving ---------------------------------------------------------------------------

    @property
    def done(self) -> bool:
        return self.step is Step.DONE

    def start(self, now_s: float) -> list[Any]:
        """Begin: the first COMMAND_LONG / COMMAND_INT to send."""
        if self.step is not Step.IDLE:
            raise RuntimeError("transaction already started")
        self.started_s = self._last_heard_s = now_s
        self.step = Step.AWAITING_ACK
        return [self._send(now_s)]

    def heard(self, now_s: float) -> None:
        """Something (a heartbeat, telemetry) arrived from the vehicle: it is there."""
        self._last_heard_s = max(self._last_heard_s, now_s)
        if self.step is Step.AWAITING_ACK:
            self._set_deadline()

    def handle(self, msg: Any, now_s: float) -> list[Any]:
        """Take a received message; a matching COMMAND_ACK advances the transaction."""
        if self.step is Step.IDLE or self.step is Step.DONE:
            return []
        if not self._is_our_ack(msg):
            if self.target_system in (0, msg.get_srcSystem()):
                self.heard(now_s)
            return []
        self._last_heard_s = now_s
        result = int(msg.result)
        self.ack = self._make_ack(msg)
        if self.attempts == 1 and self.step is Step.AWAITING_ACK:
            self.rtt.sample(now_s - self._sent_s)  # sent once: the ACK answers that copy
        if result == MAV_RESULT_IN_PROGRESS:
            self.progress = self.ack.progress
            self.step = Step.IN_PROGRESS
            self.deadline_s = now_s + self.in_progress_timeout_s
            return []
        self.result = _RESULT_BY_MAV.get(result, Result.FAILED)
        self._finish(now_s)
        return []

    def tick(self, now_s: float) -> list[Any]:
        """Handle an expired deadline: resend, or time out (progress reports stopped, the
        last retry, or the policy's silence or stall bound)."""
        if self.step is Step.IDLE or self.step is Step.DONE or now_s < self.deadline_s:
            return []
        if self.step is Step.IN_PROGRESS:
            return self._time_out(now_s, "")
        if self.retries is None:
            assert self.started_s is not None
            silent_s = now_s - self._last_heard_s
            if silent_s >= self.policy.silence_s:
                return self._time_out(now_s, f"nothing heard from the vehicle for {silent_s:.1f} s")
            if now_s - self.started_s >= self.policy.stall_s:
                return self._time_out(
                    now_s,
                    f"no answer for {now_s - self.started_s:.1f} s though the vehicle is heard",
                )
        elif self.attempts > self.retries:
            return self._time_out(now_s, "")
        if now_s < self._resend_s:
            self._set_deadline()
            return []
        return [self._send(now_s)]

    @property
    def timeout_now_s(self) -> float:
        """The resend timeout in force (fixed, or adaptive from the round trips so far)."""
        return self.timeout_s if self.timeout_s is not None else self.rtt.rto_s

    # -- outcome ----------------------------------------------------------------------------

    def error(self) -> CommandError | None:
        """The typed error of a finished, unsuccessful transaction (None on success)."""
        if not self.done:
            raise RuntimeError("transaction still running")
        if self.result is Result.SUCCESS:
            return None
        cmd = command_name(self.command)
        who = f"vehicle {self.target_system}"
        if self.result is Result.TIMEOUT:
            waited = "" if self.elapsed_s is None else f" in {self.elapsed_s:.1f} s"
            if self.ack is not None and self.ack.result == MAV_RESULT_IN_PROGRESS:
                pct = "" if self.progress is None else f" at {self.progress}%"
                text = f"{who}: {cmd} stopped reporting progress{pct} (timeout{waited})"
            else:
                text = f"{who}: {cmd} not acknowledged after {self.attempts} attempts{waited}"
                if self.timed_out_because:
                    text += f" ({self.timed_out_because})"
            return CommandTimeout(
                text, command=self.command, result=None, vehicle=self.target_system, ack=self.ack
            )
        assert self.ack is not None
        cls = _ERROR_BY_RESULT.get(self.ack.result, CommandFailed)
        return cls(
            f"{who}: {cmd} rejected with {result_name(self.ack.result)}",
            command=self.command,
            result=self.ack.result,
            vehicle=self.target_system,
            ack=self.ack,
        )

    @property
    def elapsed_s(self) -> float | None:
        """Seconds from start to the end (None while running)."""
        if self.started_s is None or self.finished_s is None:
            return None
        return self.finished_s - self.started_s

    # -- internals ------------------------------------------------------------------------

    def _finish(self, now_s: float) -> None:
        self.step = Step.DONE
        self.deadline_s = math.inf
        self.finished_s = now_s

    def _time_out(self, now_s: float, why: str) -> list[Any]:
        self.result = Result.TIMEOUT
        self.timed_out_because = why
        self._finish(now_s)
        return []

    def _set_deadline(self) -> None:
        """The next of: the resend, and (without a retry count) the silence and stall bounds."""
        t = self._resend_s
        if self.retries is None and self.started_s is not None:
            p = self.policy
            t = min(t, self._last_heard_s + p.silence_s, self.started_s + p.stall_s)
        self.deadline_s = t

    def _send(self, now_s: float) -> Any:
        confirmation = min(self.attempts, 255)
        resends = self.attempts
        self.attempts += 1
        self._sent_s = now_s
        if self.timeout_s is not None:
            wait_s = self.timeout_s
        else:
            wait_s = self.rtt.wait_s(resends, now_s - self._last_heard_s)
        self._resend_s = now_s + wait_s
        self._set_deadline()
        p = self.params
        pos = self.position
        if pos is None:
            return mavlink2.MAVLink_command_long_message(
                self.target_system,
                self.target_component,
                self.command,
                confirmation,
                *p,
            )
        return mavlink2.MAVLink_command_int_message(
            self.target_system,
            self.target_component,
            pos.frame,
            self.command,
            0,
            0,
            *p,
            pos.x,
            pos.y,
            pos.z,
        )

    def _is_our_ack(self, msg: Any) -> bool:
        if msg.get_type() != "COMMAND_ACK" or int(msg.command) != self.command:
            return False
        if self.target_system != 0 and msg.get_srcSystem() != self.target_system:
            return False
        if self.target_component != 0 and msg.get_srcComponent() != self.target_component:
            return False
        # MAVLink 1 ACKs have no target fields (0 = for everyone).
        ts = int(getattr(msg, "target_system", 0) or 0)
        tc = int(getattr(msg, "target_component", 0) or 0)
        if ts and self.own_system is not None and ts != self.own_system:
            return False
        return not (tc and self.own_component is not None and tc != self.own_component)

    def _make_ack(self, msg: Any) -> CommandAck:
        progress = int(getattr(msg, "progress", 255))
        return CommandAck(
            command=self.command,
            result=int(msg.result),
            progress=progress if 0 <= progress <= 100 else self.progress,
            result_param2=int(getattr(msg, "result_param2", 0) or 0),
            vehicle=msg.get_srcSystem(),
            component=msg.get_srcComponent(),
            attempts=self.attempts,
        )


# -- asyncio runner --------------------------------------------------------------------------


async def run_transaction(link: Link, tx: CommandTransaction) -> CommandAck:
    """Run ``tx`` over ``link``: the final ACK, or the typed error raised.

    Subscribes before sending; every wait is bounded by the transaction's own deadline.
    Anything else heard from the vehicle meanwhile tells the transaction it is there.
    """
    loop = asyncio.get_running_loop()
    system_filter = tx.target_system if tx.target_system != 0 else None

    def on_message(msg: Any, _rx_s: float) -> None:
        if system_filter in (None, msg.get_srcSystem()):
            tx.heard(loop.time())

    remove = link.add_listener(on_message)
    try:
        with link.subscribe(types={"COMMAND_ACK"}, system_id=system_filter) as sub:
            for out in tx.start(loop.time()):
                link.send(out)
            while not tx.done:
                wait_s = max(0.0, tx.deadline_s - loop.time())
                msg = await sub.get(timeout_s=wait_s)
                now = loop.time()
                outgoing = tx.handle(msg, now) if msg is not None else []
                outgoing += tx.tick(now)
                for out in outgoing:
                    link.send(out)
    finally:
        remove()
        if system_filter is not None:
            remember_rtt(link, system_filter, tx.rtt)
    err = tx.error()
    if err is not None:
        raise err
    assert tx.ack is not None
    return tx.ack


def _own_ids(link: Link) -> tuple[int | None, int | None]:
    return getattr(link, "system_id", None), getattr(link, "component_id", None)


async def command_long(
    link: Link,
    target_system: int,
    command: int,
    params: Sequence[float] = (0.0,) * 7,
    *,
    target_component: int = 1,
    timeout_s: float | None = None,
    retries: int | None = None,
    in_progress_timeout_s: float = DEFAULT_IN_PROGRESS_TIMEOUT_S,
    policy: RetryPolicy | None = None,
) -> CommandAck:
    """Send COMMAND_LONG and wait for its final ACK; raises a CommandError subclass.

    Timeouts as :class:`CommandTransaction` (default: adaptive, :mod:`gcs.mavlink.retry`)."""
    return await _send(
        link, target_system, command, params, None, target_component, timeout_s, retries,
        in_progress_timeout_s, policy,
    )  # fmt: skip


async def command_int(
    link: Link,
    target_system: int,
    command: int,
    params: Sequence[float] = (0.0,) * 4,
    *,
    frame: int = int(mavlink2.MAV_FRAME_GLOBAL_INT),
    x: int = 0,
    y: int = 0,
    z: float = 0.0,
    target_component: int = 1,
    timeout_s: float | None = None,
    retries: int | None = None,
    in_progress_timeout_s: float = DEFAULT_IN_PROGRESS_TIMEOUT_S,
    policy: RetryPolicy | None = None,
) -> CommandAck:
    """Send COMMAND_INT (params 1-4, frame, x, y, z) and wait for its final ACK."""
    return await _send(
        link, target_system, command, params, IntPosition(frame, x, y, z), target_component,
        timeout_s, retries, in_progress_timeout_s, policy,
    )  # fmt: skip


async def _send(
    link: Link,
    target_system: int,
    command: int,
    params: Sequence[float],
    position: IntPosition | None,
    target_component: int,
    timeout_s: float | None,
    retries: int | None,
    in_progress_timeout_s: float,
    policy: RetryPolicy | None,
) -> CommandAck:
    """One command transaction (COMMAND_INT when ``position`` is given), run to its ACK."""
    own_sys, own_comp = _own_ids(link)
    tx = CommandTransaction(
        target_system,
        command,
        params,
        target_component=target_component,
        position=position,
        own_system=own_sys,
        own_component=own_comp,
        timeout_s=timeout_s,
        retries=retries,
        in_progress_timeout_s=in_progress_timeout_s,
        policy=policy or DEFAULT_POLICY,
        rtt_hint_s=rtt_hint_s(link, target_system),
    )
    return await run_transaction(link, tx)


# -- helpers -------------------------------------------------------------------------------


async def _arm_disarm(
    link: Link,
    sysid: int,
    arm: bool,
    force: bool,
    target_component: int,
    timeout_s: float | None,
    retries: int | None,
) -> CommandAck:
    return await command_long(
        link,
        sysid,
        int(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM),
        (1.0 if arm else 0.0, FORCE_ARM_MAGIC if force else 0.0),
        target_component=target_component,
        timeout_s=timeout_s,
        retries=retries,
    )


async def arm(
    link: Link,
    sysid: int,
    *,
    force: bool = False,
    target_component: int = 1,
    timeout_s: float | None = None,
    retries: int | None = None,
) -> CommandAck:
    """MAV_CMD_COMPONENT_ARM_DISARM arm (``force`` skips pre-arm checks)."""
    return await _arm_disarm(link, sysid, True, force, target_component, timeout_s, retries)


async def disarm(
    link: Link,
    sysid: int,
    *,
    force: bool = False,
    target_component: int = 1,
    timeout_s: float | None = None,
    retries: int | None = None,
) -> CommandAck:
    """MAV_CMD_COMPONENT_ARM_DISARM disarm (``force`` disarms in flight: the aircraft falls)."""
    return await _arm_disarm(link, sysid, False, force, target_component, timeout_s, retries)


def set_mode_params(mode: str, autopilot: int) -> tuple[float, float, float]:
    """DO_SET_MODE params 1-3 for a mode name (PX4: main and sub mode apart)."""
    number = mode_number(mode, autopilot)
    base = float(mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
    if autopilot == AUTOPILOT_PX4:
        main, sub = px4_main_sub(number)
        return base, float(main), float(sub)
    return base, float(number), 0.0


async def set_mode(
    link: Link,
    sysid: int,
    mode_name: str,
    *,
    autopilot: int | None = None,
    target_component: int = 1,
    timeout_s: float | None = None,
    retries: int | None = None,
) -> CommandAck:
    """MAV_CMD_DO_SET_MODE to a named custom mode (ArduPlane or PX4 names).

    ``autopilot`` (MAV_AUTOPILOT_*) defaults to the one in the vehicle's HEARTBEAT.
    """
    if autopilot is None:
        peer = link.vehicles.get(sysid)
        if peer is None:
            raise ValueError(
                f"vehicle {sysid}: autopilot unknown (no HEARTBEAT yet); pass autopilot="
            )
        autopilot = int(peer.autopilot)
    params = set_mode_params(mode_name, autopilot)
    return await command_long(
        link,
        sysid,
        int(mavlink2.MAV_CMD_DO_SET_MODE),
        params,
        target_component=target_component,
        timeout_s=timeout_s,
        retries=retries,
    )


async def start_mission(
    link: Link,
    sysid: int,
    first: int = 0,
    last: int = 0,
    *,
    target_component: int = 1,
    timeout_s: float | None = None,
    retries: int | None = None,
) -> CommandAck:
    """MAV_CMD_MISSION_START from item ``first`` to ``last`` (0, 0: the whole mission)."""
    if first < 0 or last < 0:
        raise ValueError(f"mission items must be >= 0, got first={first} last={last}")
    return await command_long(
        link,
        sysid,
        int(mavlink2.MAV_CMD_MISSION_START),
        (float(first), float(last)),
        target_component=target_component,
        timeout_s=timeout_s,
        retries=retries,
    )


def change_speed_params(
    speed_m_s: float, *, airspeed: bool = True, throttle_pct: float = -1
) -> tuple[float, float, float]:
    """DO_CHANGE_SPEED params 1-3, validated."""
    if not (math.isfinite(speed_m_s) and speed_m_s >= 0):
        raise ValueError(f"speed must be a finite, non-negative m/s value, got {speed_m_s!r}")
    if not (throttle_pct == -1 or (math.isfinite(throttle_pct) and 0 <= throttle_pct <= 100)):
        raise ValueError(f"throttle_pct must be -1 (no change) or 0..100, got {throttle_pct!r}")
    return (0.0 if airspeed else 1.0), float(speed_m_s), float(throttle_pct)


async def change_speed(
    link: Link,
    sysid: int,
    speed_m_s: float,
    *,
    airspeed: bool = True,
    throttle_pct: float = -1,
    target_component: int = 1,
    timeout_s: float | None = None,
    retries: int | None = None,
) -> CommandAck:
    """MAV_CMD_DO_CHANGE_SPEED: airspeed (or groundspeed with ``airspeed=False``) in m/s."""
    params = change_speed_params(speed_m_s, airspeed=airspeed, throttle_pct=throttle_pct)
    return await command_long(
        link,
        sysid,
        int(mavlink2.MAV_CMD_DO_CHANGE_SPEED),
        params,
        target_component=target_component,
        timeout_s=timeout_s,
        retries=retries,
    )


async def change_altitude(
    link: Link,
    sysid: int,
    alt_m: float,
    *,
    above_home: bool = False,
    target_component: int = 1,
    timeout_s: float | None = None,
    retries: int | None = None,
) -> CommandAck:
    """MAV_CMD_DO_CHANGE_ALTITUDE as COMMAND_INT: param1 the altitude (m), param2 its frame,
    AMSL (MAV_FRAME_GLOBAL) or above home with ``above_home`` (MAV_FRAME_GLOBAL_RELATIVE_ALT).
    ArduPlane takes it in AUTO for the waypoint flown to now (the next one brings the
    mission's altitude back): ArduPlane/GCS_Mavlink.cpp handle_command_int_DO_CHANGE_ALTITUDE
    reads the frame from param2, not from the message's frame field."""
    if not math.isfinite(alt_m):
        raise ValueError(f"altitude must be a finite number of metres, got {alt_m!r}")
    frame = mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT if above_home else mavlink2.MAV_FRAME_GLOBAL
    return await command_int(
        link,
        sysid,
        int(mavlink2.MAV_CMD_DO_CHANGE_ALTITUDE),
        (float(alt_m), float(frame), 0.0, 0.0),
        target_component=target_component,
        timeout_s=timeout_s,
        retries=retries,
    )


def message_id_of(message: str | int) -> int:
    """A MAVLink message id from a name (``"GLOBAL_POSITION_INT"``) or an id."""
    if isinstance(message, str):
        msg_id = _MESSAGE_IDS.get(message.strip().upper())
        if msg_id is None:
            raise ValueError(f"unknown MAVLink message {message!r}")
        return msg_id
    if isinstance(message, bool) or not 0 <= message <= 0xFFFFFF:
        raise ValueError(f"message id must be in 0..16777215, got {message!r}")
    return int(message)


def message_interval_us(interval_s: float) -> float:
    """SET_MESSAGE_INTERVAL param2: µs; -1 disables the message, 0 restores its default."""
    if interval_s in (-1, 0):
        return float(interval_s)
    if not (math.isfinite(interval_s) and interval_s > 0):
        raise ValueError(
            f"interval_s must be > 0 seconds, -1 (disable) or 0 (default), got {interval_s!r}"
        )
    us = round(interval_s * 1e6)
    if us < 1 or us > 2**31 - 1:
        raise ValueError(f"interval_s {interval_s!r} is outside 1 µs .. 2147 s")
    return float(us)


async def set_message_interval(
    link: Link,
    sysid: int,
    message: str | int,
    interval_s: float,
    *,
    target_component: int = 1,
    timeout_s: float | None = None,
    retries: int | None = None,
) -> CommandAck:
    """MAV_CMD_SET_MESSAGE_INTERVAL: stream ``message`` every ``interval_s`` (-1 off, 0 default)."""
    params = (float(message_id_of(message)), message_interval_us(interval_s))
    return await command_long(
        link,
        sysid,
        int(mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL),
        params,
        target_component=target_component,
        timeout_s=timeout_s,
        retries=retries,
    )


async def request_message(
    link: Link,
    sysid: int,
    msg_id: str | int,
    *,
    target_component: int = 1,
    timeout_s: float | None = None,
    retries: int | None = None,
) -> CommandAck:
    """MAV_CMD_REQUEST_MESSAGE: ask for one message now (it arrives separately)."""
    return await command_long(
        link,
        sysid,
        int(mavlink2.MAV_CMD_REQUEST_MESSAGE),
        (float(message_id_of(msg_id)),),
        target_component=target_component,
        timeout_s=timeout_s,
        retries=retries,
    )
