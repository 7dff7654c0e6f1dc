"""Ground-station side of the MAVLink mission protocol, as sans-IO state machines.

One object per transfer, in the style of MAVSDK's ``MavlinkMissionTransferClient`` work
items: an explicit :class:`Step`, a retry counter and a :class:`Result`. A transfer is driven
by ``start(now_s)``, ``handle(msg, now_s)`` for every received message and ``tick(now_s)``
when :meth:`Transfer.next_deadline` has passed; each returns the pymavlink messages to send.
It never touches a socket, a clock or asyncio, so tests drive it with a fake clock
(``gcs.mavlink.mission_client`` is the asyncio runner).

- Upload: MISSION_COUNT -> (MISSION_REQUEST_INT | MISSION_REQUEST)(seq) ->
  MISSION_ITEM_INT(seq) ... -> MISSION_ACK. On timeout: resend the COUNT until a request
  came, then the item last requested. With ``window`` > 1 (a vehicle that takes items in
  order ahead of its requests) up to that many items go out ahead of the requests.
- Download: MISSION_REQUEST_LIST -> MISSION_COUNT -> MISSION_REQUEST_INT(seq) ->
  (MISSION_ITEM_INT | MISSION_ITEM)(seq) ... -> our MISSION_ACK. On timeout: resend the list
  request, then the request for the missing item.
- Clear: MISSION_CLEAR_ALL -> MISSION_ACK. SetCurrent: MISSION_SET_CURRENT(seq) ->
  MISSION_CURRENT with that seq. On timeout: resend.

Timeouts (:mod:`gcs.mavlink.retry`): by default a resend waits a timeout that follows the measured
round trip (SRTT + 4 RTTVAR, Karn's rule, 10 ms to 1.5 s), and a transfer fails only when
nothing has been heard from the vehicle for ``policy.silence_s`` (10 s) or it has not advanced
for ``policy.stall_s`` (20 s), not after a count of resends while the vehicle answers.
``timeout_s`` fixes the timeout and ``retries`` bounds the resends of one exchange, as the
MAVLink mission service has them (1.5 s, 5); any valid request from the vehicle resets that
count (duplicated packets cannot use it up), and an upload that only makes no progress is
bounded by ``4 * (retries + 1) * timeout_s`` without a new item requested. ``within_s``
bounds a whole transfer.
An upload or download that ends by timeout or protocol error, or that the caller cancels,
sends MISSION_ACK MAV_MISSION_OPERATION_CANCELLED so the vehicle stops waiting for it.

Tolerance, as MAVProxy's and MAVSDK's clients:

- Messages from other systems or components, of another mission type, or addressed to
  another GCS (``target_system``/``target_component`` neither ours nor 0) are ignored.
- Upload answers every in-range request, duplicated, stale or out of order, with the item
  asked for; legacy MISSION_REQUEST is answered with MISSION_ITEM_INT too, as MAVSDK and QGC
  do (ArduPilot requests with MISSION_REQUEST and accepts MISSION_ITEM_INT). A timeout resends
  the item last requested: if the vehicle's final ACK was lost, this makes it ACK again.
- An accepting MISSION_ACK before the last item was requested is stale (a duplicate from an
  earlier transfer) and ignored, and so is MAV_MISSION_INVALID_SEQUENCE during items
  (ArduPilot answers a duplicated item with it and carries on); any other NACK ends the
  transfer with that result, naming the item the vehicle was processing.
- Download takes each item once, in order; duplicates and items out of order are dropped
  and a missing one is requested again. Legacy MISSION_ITEM replies are converted (degrees
  x 1e7, rounded; a NaN x or y becomes INT32_MAX, MAVLink's "unset").

ArduPilot convention: item 0 of the mission (type 0) is home. A download gives it as item 0
(the vehicle's home, whatever was uploaded there); an upload should carry a home or
placeholder item 0, as :func:`planner.mission.compile_mission` produces. Uploading no items
is the spec's way of clearing (MISSION_COUNT 0 -> MISSION_ACK).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from typing import Any, ClassVar

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from gcs.mavlink.mission_errors import (
    MAV_MISSION_ACCEPTED,
    MAV_MISSION_INVALID_SEQUENCE,
    MAV_MISSION_OPERATION_CANCELLED,
    MissionCancelled,
    MissionError,
    MissionInputError,
    MissionProtocolError,
    MissionTimeout,
    describe_operation,
    error_for_result,
    result_name,
)
from gcs.mavlink.retry import DEFAULT_POLICY, RetryPolicy, RttEstimator
from planner.mission import INT32_UNSET, MissionItem

__all__ = [
    "Clear",
    "Download",
    "Result",
    "SetCurrent",
    "Step",
    "Transfer",
    "Upload",
    "item_from_message",
    "item_message",
]

MAV_MISSION_TYPE_ALL = 255
SEND_AHEAD_MAX = 7
"""Items an upload sends beyond the one last requested, at most, after timeouts."""
_INT32_MIN, _INT32_MAX = -(2**31), 2**31 - 1
_SEQ_MAX = 65535


class Step(enum.Enum):
    """Where a transfer is."""

    IDLE = enum.auto()
    SEND_COUNT = enum.auto()
    SEND_ITEMS = enum.auto()
    REQUEST_LIST = enum.auto()
    REQUEST_ITEMS = enum.auto()
    SEND_CLEAR = enum.auto()
    SEND_SET_CURRENT = enum.auto()
    DONE = enum.auto()


class Result(enum.Enum):
    """How a transfer ended (NONE while it runs)."""

    NONE = enum.auto()
    SUCCESS = enum.auto()
    TIMEOUT = enum.auto()
    DENIED = enum.auto()
    UNSUPPORTED = enum.auto()
    UNSUPPORTED_FRAME = enum.auto()
    NO_SPACE = enum.auto()
    INVALID_PARAM = enum.auto()
    INVALID_SEQUENCE = enum.auto()
    CANCELLED = enum.auto()
    VEHICLE_ERROR = enum.auto()
    PROTOCOL_ERROR = enum.auto()


_RESULT_BY_MAV: dict[int, Result] = {
    int(mavlink2.MAV_MISSION_ERROR): Result.VEHICLE_ERROR,
    int(mavlink2.MAV_MISSION_UNSUPPORTED_FRAME): Result.UNSUPPORTED_FRAME,
    int(mavlink2.MAV_MISSION_UNSUPPORTED): Result.UNSUPPORTED,
    int(mavlink2.MAV_MISSION_NO_SPACE): Result.NO_SPACE,
    int(mavlink2.MAV_MISSION_INVALID_SEQUENCE): Result.INVALID_SEQUENCE,
    int(mavlink2.MAV_MISSION_DENIED): Result.DENIED,
    int(mavlink2.MAV_MISSION_OPERATION_CANCELLED): Result.CANCELLED,
}
_INVALID_RESULTS = range(
    int(mavlink2.MAV_MISSION_INVALID), int(mavlink2.MAV_MISSION_INVALID_PARAM7) + 1
)
_RESULT_BY_MAV.update({r: Result.INVALID_PARAM for r in _INVALID_RESULTS})


def item_message(
    item: MissionItem, target_system: int, target_component: int, mission_type: int
) -> Any:
    """The MISSION_ITEM_INT that uploads ``item`` (its seq, our mission type)."""
    return mavlink2.MAVLink_mission_item_int_message(
        target_system, target_component, item.seq, item.frame, item.command, item.current,
        item.autocontinue, item.param1, item.param2, item.param3, item.param4, item.x, item.y,
        item.z, mission_type,
    )  # fmt: skip


def _e7(value: float) -> int | None:
    """Degrees (or a raw float param) of a legacy MISSION_ITEM as int32 x 1e7, None if out."""
    if math.isnan(value):
        return INT32_UNSET
    if not math.isfinite(value):
        return None
    e7 = round(value * 1e7)
    return e7 if _INT32_MIN <= e7 <= _INT32_MAX else None


def item_from_message(msg: Any) -> MissionItem | None:
    """A MISSION_ITEM_INT or legacy MISSION_ITEM as a MissionItem (None: x/y not int32)."""
    if msg.get_type() == "MISSION_ITEM":
        x, y = _e7(float(msg.x)), _e7(float(msg.y))
        if x is None or y is None:
            return None
    else:
        x, y = int(msg.x), int(msg.y)
    return MissionItem(
        seq=int(msg.seq),
        frame=int(msg.frame),
        command=int(msg.command),
        current=int(msg.current),
        autocontinue=int(msg.autocontinue),
        param1=float(msg.param1),
        param2=float(msg.param2),
        param3=float(msg.param3),
        param4=float(msg.param4),
        x=x,
        y=y,
        z=float(msg.z),
        mission_type=int(getattr(msg, "mission_type", 0)),
    )


class Transfer:
    """One mission transfer with one vehicle (base of Upload, Download, Clear, SetCurrent).

    ``own_system``/``own_component`` are the GCS's ids: messages addressed to other ids are
    ignored (None: do not filter on target ids). ``target_component`` 0 accepts replies from
    any component of ``target_system``.
    """

    operation: ClassVar[str] = ""
    message_types: ClassVar[frozenset[str]] = frozenset()
    """Message types the transfer reacts to (a runner may subscribe to just these)."""

    def __init__(
        self,
        *,
        target_system: int,
        target_component: int = 1,
        mission_type: int = 0,
        timeout_s: float | None = None,
        retries: int | None = None,
        own_system: int | None = None,
        own_component: int | None = None,
        policy: RetryPolicy = DEFAULT_POLICY,
        rtt_hint_s: float | None = None,
        within_s: float | None = None,
    ) -> None:
        if timeout_s is not None and not (math.isfinite(timeout_s) and timeout_s > 0):
            raise ValueError(f"timeout_s must be a positive number of seconds, got {timeout_s!r}")
        if retries is not None and (
            isinstance(retries, bool) or not isinstance(retries, int) or retries < 0
        ):
            raise ValueError(f"retries must be an integer >= 0, got {retries!r}")
        if within_s is not None and not (math.isfinite(within_s) and within_s > 0):
            raise ValueError(f"within_s must be a positive number of seconds, got {within_s!r}")
        if not 1 <= target_system <= 255:
            raise ValueError(f"target_system must be in [1, 255], got {target_system!r}")
        self.target_system = target_system
        self.target_component = target_component
        self.mission_type = mission_type
        self.timeout_s = timeout_s
        """A fixed resend timeout (None: adaptive, from the measured round trip)."""
        self.retries = retries
        """Resends of one exchange before giving up (None: the policy's silence and stall
        bounds decide, however many resends that takes)."""
        self.policy = policy
        self.within_s = within_s
        """The whole transfer must end within this many seconds of its start (None: no limit)."""
        self.rtt = RttEstimator(policy, rtt_hint_s)
        self.own_system = own_system
        self.own_component = own_component
        self.step = Step.IDLE
        self.result = Result.NONE
        self.mav_result: int | None = None
        """The MAV_MISSION_RESULT of the MISSION_ACK that ended the transfer, if any."""
        self.retries_done = 0
        """Resends of the exchange under way."""
        self._last_nack: int | None = None
        self.counters: dict[str, int] = {
            "handled": 0, "ignored": 0, "resent": 0, "rtt_samples": 0, "needless_resends": 0,
        }  # fmt: skip
        self._deadline_s: float | None = None
        self._error: MissionError | None = None
        self._started_s = 0.0
        self._last_heard_s = 0.0
        self._last_progress_s = 0.0
        self._exchange_s = 0.0  # when the exchange under way was first sent
        self._clean = True  # ...and nothing of it was sent twice since (Karn's rule)

    # -- queries -------------------------------------------------------------------------

    @property
    def done(self) -> bool:
        return self.step is Step.DONE

    @property
    def progress(self) -> tuple[int, int]:
        """(done, total) in the transfer's own unit (items, or 0/1 for single exchanges)."""
        return (1, 1) if self.result is Result.SUCCESS else (0, 1)

    @property
    def stall_limit_s(self) -> float:
        """Time without progress after which the transfer ends as timed out."""
        if self.retries is None:
            return self.policy.stall_s
        return 4.0 * (self.retries + 1) * (self.timeout_s or self.policy.max_rto_s)

    @property
    def timeout_now_s(self) -> float:
        """The resend timeout in force (fixed, or adaptive from the round trips so far)."""
        return self.timeout_s if self.timeout_s is not None else self.rtt.rto_s

    def next_deadline(self) -> float | None:
        """Time (same clock as ``now_s``) at which ``tick`` has something to do, if any."""
        if self.done or self._deadline_s is None:
            return None
        t = self._deadline_s
        if self.within_s is not None:
            t = min(t, self._started_s + self.within_s)
        if self.retries is None:
            t = min(t, self._last_heard_s + self.policy.silence_s)
        return min(t, self._last_progress_s + self.stall_limit_s)

    def error(self) -> MissionError | None:
        """The typed error of a failed transfer (None while running or on success)."""
        return self._error

    def describe(self) -> str:
        """``vehicle 1: mission upload`` for messages."""
        return describe_operation(self.target_system, self.mission_type, self.operation)

    # -- inputs --------------------------------------------------------------------------

    def start(self, now_s: float) -> list[Any]:
        """Begin the transfer; returns the first message(s) to send."""
        if self.step is not Step.IDLE:
            raise RuntimeError(f"{self.describe()}: transfer already started")
        self._started_s = self._last_heard_s = self._last_progress_s = now_s
        self._new_exchange(now_s)
        return self._start(now_s)

    def heard(self, now_s: float) -> None:
        """Anything at all arrived from the vehicle (a heartbeat, telemetry): it is there."""
        self._last_heard_s = now_s

    def handle(self, msg: Any, now_s: float) -> list[Any]:
        """Process one received message; messages not for this transfer are ignored."""
        if self.step is Step.IDLE or self.done or not self._is_ours(msg):
            self.counters["ignored"] += 1
            return []
        self.counters["handled"] += 1
        self._last_heard_s = now_s
        return self._handle(msg, now_s)

    def tick(self, now_s: float) -> list[Any]:
        """Resend after a silent timeout, or end with TIMEOUT when a bound is reached.

        The bounds: ``within_s`` since the start; with ``retries`` None, ``policy.silence_s``
        without hearing the vehicle and ``stall_limit_s`` without progress; else ``retries``
        resends of one exchange. An upload or download that times out returns a MISSION_ACK
        MAV_MISSION_OPERATION_CANCELLED, so that the vehicle stops waiting for it.
        """
        deadline = self.next_deadline()
        if deadline is None or now_s < deadline:
            return []
        waiting = f"waiting for {self._awaited()}"
        if self.within_s is not None and now_s >= self._started_s + self.within_s:
            return self._give_up(
                f"timed out: not finished within {self.within_s:.3g} s ({waiting})"
            )
        if self.retries is None and now_s - self._last_heard_s >= self.policy.silence_s:
            silent = now_s - self._last_heard_s
            return self._give_up(
                f"timed out: nothing heard from the vehicle for {silent:.1f} s ({waiting})"
            )
        if now_s - self._last_progress_s >= self.stall_limit_s:
            stalled = now_s - self._last_progress_s
            return self._give_up(
                f"timed out: no progress for {stalled:.1f} s ({waiting}{self._note()})"
            )
        assert self._deadline_s is not None
        if now_s < self._deadline_s:
            return []
        if self.retries is not None and self.retries_done >= self.retries:
            return self._give_up(f"timed out {waiting} after {self.retries} retries{self._note()}")
        self.retries_done += 1
        self.counters["resent"] += 1
        self._clean = False
        self._deadline_s = now_s + self._wait_s(now_s)
        return self._resend(now_s)

    def _give_up(self, what: str) -> list[Any]:
        self._fail(
            Result.TIMEOUT,
            MissionTimeout(
                f"{self.describe()} {what}",
                vehicle=self.target_system,
                seq=self._timeout_seq(),
                mission_type=self.mission_type,
                operation=self.operation,
            ),
        )
        return self._cancel_messages()

    def _wait_s(self, now_s: float) -> float:
        if self.timeout_s is not None:
            return self.timeout_s
        return self.rtt.wait_s(self.retries_done, now_s - self._last_heard_s)

    def _new_exchange(self, now_s: float) -> None:
        """A new request went out: its own timer and resend count."""
        self.retries_done = 0
        self._exchange_s = now_s
        self._clean = True
        self._deadline_s = now_s + self._wait_s(now_s)

    def _answered(self, now_s: float) -> None:
        """The exchange under way was answered: a round-trip sample if it went out once."""
        if self._clean:
            self._sample(now_s - self._exchange_s)

    def _sample(self, rtt_s: float) -> None:
        self.rtt.sample(rtt_s)
        self.counters["rtt_samples"] += 1

    def _progressed(self, now_s: float) -> None:
        self._last_progress_s = now_s

    def _needless(self) -> None:
        self.counters["needless_resends"] += 1
        self.rtt.needless_resend()

    def cancel(self, now_s: float) -> list[Any]:
        """Abandon a running transfer (the caller gave up); returns the messages to send.

        Ends it with CANCELLED and a :class:`MissionCancelled` error saying the GCS cancelled;
        an upload or download tells the vehicle with MISSION_ACK OPERATION_CANCELLED.
        """
        if self.step is Step.IDLE or self.done:
            return []
        self._fail(
            Result.CANCELLED,
            MissionCancelled(
                f"{self.describe()} cancelled by the GCS",
                vehicle=self.target_system,
                seq=None,
                mission_type=self.mission_type,
                operation=self.operation,
            ),
        )
        return self._cancel_messages()

    # -- for subclasses ------------------------------------------------------------------

    def _cancel_messages(self) -> list[Any]:
        """What tells the vehicle we gave up (MISSION_ACK CANCELLED for item transfers)."""
        return []

    def _start(self, now_s: float) -> list[Any]:
        raise NotImplementedError

    def _handle(self, msg: Any, now_s: float) -> list[Any]:
        raise NotImplementedError

    def _resend(self, now_s: float) -> list[Any]:
        raise NotImplementedError

    def _awaited(self) -> str:
        """What the transfer is waiting for, for the timeout message."""
        raise NotImplementedError

    def _note(self) -> str:
        """What the vehicle last said, if it helps explain a timeout (`` (...)``)."""
        if self._last_nack is None:
            return ""
        return f" (the vehicle last answered {result_name(self._last_nack)})"

    def _timeout_seq(self) -> int | None:
        return None

    def _is_ours(self, msg: Any) -> bool:
        if msg.get_type() not in self.message_types:
            return False
        if msg.get_srcSystem() != self.target_system:
            return False
        if self.target_component != 0 and msg.get_srcComponent() != self.target_component:
            return False
        ts = getattr(msg, "target_system", 0)
        if self.own_system is not None and ts not in (0, self.own_system):
            return False
        tc = getattr(msg, "target_component", 0)
        if self.own_component is not None and tc not in (0, self.own_component):
            return False
        mt = getattr(msg, "mission_type", None)
        return mt is None or int(mt) == self.mission_type

    def _succeed(self) -> None:
        self.step = Step.DONE
        self.result = Result.SUCCESS
        self._deadline_s = None

    def _fail(self, result: Result, error: MissionError) -> None:
        self.step = Step.DONE
        self.result = result
        self._error = error
        self._deadline_s = None

    def _fail_nack(self, mav_result: int, seq: int | None) -> None:
        self.mav_result = mav_result
        self._fail(
            _RESULT_BY_MAV.get(mav_result, Result.VEHICLE_ERROR),
            error_for_result(
                mav_result,
                vehicle=self.target_system,
                seq=seq,
                mission_type=self.mission_type,
                operation=self.operation,
            ),
        )

    def _fail_protocol(self, what: str, seq: int | None) -> None:
        self._fail(
            Result.PROTOCOL_ERROR,
            MissionProtocolError(
                f"{self.describe()} failed: the vehicle broke the protocol: {what}",
                vehicle=self.target_system,
                seq=seq,
                mission_type=self.mission_type,
                operation=self.operation,
            ),
        )

    def _ack(self, result: int) -> Any:
        return mavlink2.MAVLink_mission_ack_message(
            self.target_system, self.target_component, result, self.mission_type
        )


def _check_items(items: Sequence[MissionItem], mission_type: int, vehicle: int) -> None:
    def bad(k: int, what: str) -> MissionInputError:
        return MissionInputError(
            f"vehicle {vehicle}: cannot upload item {k}: {what}",
            vehicle=vehicle,
            seq=k,
            mission_type=mission_type,
            operation="upload",
        )

    if len(items) - 1 > _SEQ_MAX:
        raise bad(len(items) - 1, f"a mission holds at most {_SEQ_MAX + 1} items")
    for k, it in enumerate(items):
        if it.seq != k:
            raise bad(k, f"seq is {it.seq}, expected its index {k}")
        if it.mission_type != mission_type:
            raise bad(k, f"mission_type is {it.mission_type}, the upload's is {mission_type}")
        for name, lo, hi in (
            ("frame", 0, 255),
            ("command", 0, 65535),
            ("current", 0, 255),
            ("autocontinue", 0, 255),
            ("x", _INT32_MIN, _INT32_MAX),
            ("y", _INT32_MIN, _INT32_MAX),
        ):
            v = getattr(it, name)
            if not isinstance(v, int) or not lo <= v <= hi:
                raise bad(k, f"{name} {v!r} is not an integer in [{lo}, {hi}]")


class Upload(Transfer):
    """Send items to the vehicle (a full upload of one mission type).

    ``send_ahead``: on a timeout, send items after the one last requested too (one more on
    each consecutive timeout, the newest :data:`SEND_AHEAD_MAX` of them). When the vehicle's
    request for the next item was lost, it takes the next item at once instead of waiting for
    its own re-request timer (1.5 s on ArduPilot and the stub); items it already has, or that
    come before the one it misses, it ignores or NACKs with INVALID_SEQUENCE, which the
    upload tolerates. Off for PX4, which does not expect items it did not request.
    """

    operation = "upload"
    message_types = frozenset({"MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"})

    def __init__(
        self,
        items: Sequence[MissionItem],
        *,
        send_ahead: bool = False,
        window: int = 1,
        **kwargs: Any,
    ) -> None:
        super().__init__(**kwargs)
        _check_items(items, self.mission_type, self.target_system)
        if isinstance(window, bool) or not isinstance(window, int) or window < 1:
            raise ValueError(f"window must be an integer >= 1, got {window!r}")
        if window > 1 and not send_ahead:
            raise ValueError("an upload window needs send_ahead (a vehicle that takes items ahead)")
        self.items = tuple(items)
        self.send_ahead = send_ahead
        self.window = window
        self.highest_requested = -1
        """Highest seq the vehicle asked for: it holds every item below."""
        self.counters.update(
            legacy_requests=0, bad_requests=0, stale_acks=0, tolerated_nacks=0, sent_ahead=0
        )
        self._messages: list[Any | None] = [None] * len(self.items)
        self._highest_sent = -1
        self._frontier = -1  # highest item sent since the last resend: in flight or taken
        self._sent_s: list[float | None] = [None] * len(self.items)  # None: sent twice

    @property
    def progress(self) -> tuple[int, int]:
        n = len(self.items)
        if self.result is Result.SUCCESS:
            return (n, n)
        return (max(self.highest_requested, 0), n)

    def _cancel_messages(self) -> list[Any]:
        return [self._ack(MAV_MISSION_OPERATION_CANCELLED)]

    def _count(self) -> Any:
        return mavlink2.MAVLink_mission_count_message(
            self.target_system, self.target_component, len(self.items), self.mission_type
        )

    def _item(self, seq: int, now_s: float | None = None) -> Any:
        if seq <= self._highest_sent:
            self._sent_s[seq] = None  # sent again: its answer gives no round-trip sample
        else:
            self._sent_s[seq] = now_s
        self._highest_sent = max(self._highest_sent, seq)
        self._frontier = max(self._frontier, seq)
        msg = self._messages[seq]
        if msg is None:
            msg = self._messages[seq] = item_message(
                self.items[seq], self.target_system, self.target_component, self.mission_type
            )
        return msg

    def _start(self, now_s: float) -> list[Any]:
        self.step = Step.SEND_COUNT
        return [self._count()]

    def _handle(self, msg: Any, now_s: float) -> list[Any]:
        if msg.get_type() == "MISSION_ACK":
            self._on_ack(int(msg.type), now_s)
            return []
        seq = int(msg.seq)
        if not 0 <= seq < len(self.items):
            # A stale request from an earlier, longer upload is possible; a peer that keeps
            # asking for items that do not exist is broken.
            self.counters["bad_requests"] += 1
            if self.counters["bad_requests"] > (5 if self.retries is None else self.retries):
                self._fail_protocol(
                    f"it requested item {seq} of a {len(self.items)}-item upload",
                    seq,
                )
                return self._cancel_messages()
            return []
        if msg.get_type() == "MISSION_REQUEST":
            self.counters["legacy_requests"] += 1
        self.step = Step.SEND_ITEMS
        if seq > self.highest_requested:
            # The answer to our last item (or to the COUNT): the vehicle moved on.
            if self.window == 1 or seq == 0:
                self._answered(now_s)
            else:
                sent_s = self._sent_s[seq - 1]
                if sent_s is not None:
                    self._sample(now_s - sent_s)
            self.highest_requested = seq
            self._progressed(now_s)
            self._new_exchange(now_s)
            in_flight_s = self._sent_s[seq] if seq <= self._frontier else None
            if in_flight_s is not None and self.timeout_s is None:
                # Sent ahead already: its answer is due a round trip after it went out, not
                # after this request came.
                self._deadline_s = max(now_s, in_flight_s + self._wait_s(now_s))
            return self._fill_window(seq, now_s)
        if seq < self.highest_requested:
            # Asked again for an item it had moved past: a late copy of an old request, so an
            # earlier resend of ours was needless (or the link duplicates).
            self._needless()
        elif now_s - self._last_progress_s > self.stall_limit_s:
            return self._give_up(
                f"timed out: no progress for {now_s - self._last_progress_s:.3g} s, the "
                f"vehicle kept requesting item {self.highest_requested}"
            )
        # Answered again: the vehicle is alive (the resends start over), but its next request
        # may answer either copy, so it gives no round-trip sample.
        self.retries_done = 0
        self._clean = False
        self._deadline_s = now_s + self._wait_s(now_s)
        if seq == self.highest_requested:
            # It still misses this one, so it ignored what we sent after it: send that again.
            self._frontier = seq
        return [self._item(seq, now_s)]

    def _fill_window(self, seq: int, now_s: float) -> list[Any]:
        """Item ``seq`` unless already in flight, and the items after it the window allows.

        A vehicle that takes items ahead of its requests holds them only in order, so items
        go out in order and each once per pass; a timeout starts a new pass (see _resend).
        """
        top = min(len(self.items) - 1, seq + self.window - 1)
        first = max(seq, self._frontier + 1) if self.window > 1 else seq
        return [self._item(k, now_s) for k in range(first, top + 1)]

    def _on_ack(self, result: int, now_s: float) -> None:
        n = len(self.items)
        if result == MAV_MISSION_ACCEPTED:
            # With items sent ahead the vehicle may hold the last one before it asked for it.
            last_sent = self.send_ahead and n > 0 and self._highest_sent == n - 1
            complete = last_sent or (
                self.highest_requested == n - 1 and (n > 0 or self.step is Step.SEND_COUNT)
            )
            if not complete:
                self.counters["stale_acks"] += 1
                return
            self._answered(now_s)
            self.mav_result = result
            self._succeed()
            return
        if result == MAV_MISSION_INVALID_SEQUENCE and self.step is Step.SEND_ITEMS:
            self.counters["tolerated_nacks"] += 1
            self._last_nack = result
            return
        self._fail_nack(result, self.highest_requested if self.step is Step.SEND_ITEMS else None)

    def _resend(self, now_s: float) -> list[Any]:
        if self.step is Step.SEND_COUNT:
            return [self._count()]
        h = self.highest_requested
        # What was sent beyond what goes again now was dropped or ignored (the vehicle takes
        # items only in order): the next requests send it again.
        self._frontier = h
        if not self.send_ahead:
            return [self._item(h)]
        # The vehicle needs an item from h to one past the highest sent: h and the newest few
        # go again, and one more each time (the vehicle may have taken all we sent ahead and
        # its requests been lost).
        top = min(len(self.items) - 1, self._highest_sent + 1, h + self.retries_done)
        if self.window > 1:
            # Streaming: the vehicle takes these in order, so the window goes again at once
            # instead of a round trip later with the request that would refill it.
            top = min(len(self.items) - 1, h + self.window - 1)
        ahead = range(max(h + 1, top - SEND_AHEAD_MAX + 1), top + 1)
        self.counters["sent_ahead"] += len(ahead)
        return [self._item(h), *(self._item(seq) for seq in ahead)]

    def _awaited(self) -> str:
        n = len(self.items)
        if self.step is Step.SEND_COUNT:
            what = "a request for item 0" if n else "the MISSION_ACK of MISSION_COUNT 0"
        elif self.highest_requested < n - 1:
            what = f"a request for item {self.highest_requested + 1}"
        else:
            what = f"the final MISSION_ACK (item {n - 1} sent)"
        return what

    def _timeout_seq(self) -> int | None:
        n = len(self.items)
        if self.step is Step.SEND_COUNT:
            return 0 if n else None
        return min(self.highest_requested + 1, n - 1)


class Download(Transfer):
    """Read the vehicle's items of one mission type (item 0 of type 0 is its home).

    ``window``: how many item requests may be outstanding. 1 asks for one item at a time, in
    order, as PX4 requires (it aborts a download on a request out of sequence). ArduPilot and
    the stub answer any request, so with a window the next requests go out as each item
    arrives, replies pace the transfer, and lost items are asked for again together.
    """

    operation = "download"
    message_types = frozenset({"MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_ITEM", "MISSION_ACK"})

    def __init__(self, *, window: int = 1, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        if isinstance(window, bool) or not isinstance(window, int) or window < 1:
            raise ValueError(f"window must be an integer >= 1, got {window!r}")
        self.window = window
        self.count: int | None = None
        self.items: list[MissionItem] = []
        """The items received so far, in order from item 0 (all of them on success)."""
        self.counters.update(legacy_items=0, stale_acks=0, tolerated_nacks=0, duplicates=0)
        self._ahead: dict[int, MissionItem] = {}  # received beyond the in-order prefix
        self._outstanding: dict[int, float | None] = {}  # seq -> sent at (None: resent)
        self._asked_s: dict[int, float] = {}  # seq -> last asked for (each has its own timer)
        self._next_seq = 0  # lowest seq never requested

    @property
    def progress(self) -> tuple[int, int]:
        if self.count is None:
            return (0, 0)
        return (len(self.items) + len(self._ahead), self.count)

    def _cancel_messages(self) -> list[Any]:
        return [self._ack(MAV_MISSION_OPERATION_CANCELLED)]

    def _request_list(self) -> Any:
        return mavlink2.MAVLink_mission_request_list_message(
            self.target_system, self.target_component, self.mission_type
        )

    def _request(self, seq: int) -> Any:
        return mavlink2.MAVLink_mission_request_int_message(
            self.target_system, self.target_component, seq, self.mission_type
        )

    def _request_more(self, now_s: float) -> list[Any]:
        """Fill the window with new requests, lowest seq first."""
        assert self.count is not None
        out = []
        while len(self._outstanding) < self.window and self._next_seq < self.count:
            seq = self._next_seq
            self._next_seq += 1
            self._outstanding[seq] = self._asked_s[seq] = now_s
            out.append(self._request(seq))
        if out:
            self._new_exchange(now_s)
        self._deadline_from_oldest(now_s)
        return out

    def _deadline_from_oldest(self, now_s: float) -> None:
        """The timer runs for the request asked longest ago: a lost one is asked again a
        timeout after it went out, while the others still come in."""
        if self._asked_s and self.timeout_s is None:
            self._deadline_s = min(self._asked_s.values()) + self._wait_s(now_s)

    def _start(self, now_s: float) -> list[Any]:
        self.step = Step.REQUEST_LIST
        return [self._request_list()]

    def _handle(self, msg: Any, now_s: float) -> list[Any]:
        mtype = msg.get_type()
        if mtype == "MISSION_ACK":
            self._on_ack(int(msg.type))
            return []
        if mtype == "MISSION_COUNT":
            if self.step is not Step.REQUEST_LIST:
                self.counters["duplicates"] += 1
                return []
            self._answered(now_s)
            self._progressed(now_s)
            self.count = int(msg.count)
            if self.count == 0:
                self._succeed()
                return [self._ack(MAV_MISSION_ACCEPTED)]
            self.step = Step.REQUEST_ITEMS
            return self._request_more(now_s)
        # MISSION_ITEM_INT or legacy MISSION_ITEM.
        seq = int(msg.seq)
        if self.step is not Step.REQUEST_ITEMS or seq not in self._outstanding:
            # A duplicate, a late copy, or one not asked for: dropped.
            self.counters["duplicates"] += 1
            if self.step is Step.REQUEST_ITEMS and seq < self._next_seq:
                self._needless()
            return []
        item = item_from_message(msg)
        if item is None:
            self._fail_protocol(f"item {seq} has x {msg.x!r}, y {msg.y!r} (not int32 x 1e7)", seq)
            return self._cancel_messages()
        if mtype == "MISSION_ITEM":
            self.counters["legacy_items"] += 1
        sent_s = self._outstanding.pop(seq)
        self._asked_s.pop(seq, None)
        if sent_s is not None:
            self._sample(now_s - sent_s)
        self._progressed(now_s)
        self._ahead[seq] = item
        items, ahead = self.items, self._ahead
        while len(items) in ahead:
            items.append(ahead.pop(len(items)))
        if len(items) == self.count:
            self._succeed()
            return [self._ack(MAV_MISSION_ACCEPTED)]
        out = self._request_more(now_s)
        if not out and self.timeout_s is not None:
            # Nothing new to ask for: the timer now runs for the ones still missing.
            self._new_exchange(now_s)
        return out

    def _on_ack(self, result: int) -> None:
        if result == MAV_MISSION_ACCEPTED:
            self.counters["stale_acks"] += 1  # the end of an earlier upload
            return
        if result == MAV_MISSION_INVALID_SEQUENCE:
            # We only ask for seq < count, so this is a stale NACK (ArduPilot sends one for a
            # duplicated upload item) or the mission changed under us; the timeout decides.
            self.counters["tolerated_nacks"] += 1
            self._last_nack = result
            return
        seq = len(self.items) if self.step is Step.REQUEST_ITEMS else None
        self._fail_nack(result, seq)

    def _resend(self, now_s: float) -> list[Any]:
        if self.step is Step.REQUEST_LIST:
            return [self._request_list()]
        if self.timeout_s is None:
            # Those a timeout overdue (the oldest at least); the others are still on their way.
            oldest_s = min(self._asked_s.values())
            due_s = now_s - self.rtt.rto_s
            again = sorted(k for k, t in self._asked_s.items() if t <= max(oldest_s, due_s))
        else:
            again = sorted(self._outstanding)
        for seq in again:
            self._outstanding[seq] = None
            self._asked_s[seq] = now_s
        self._deadline_from_oldest(now_s)
        return [self._request(seq) for seq in again]

    def _awaited(self) -> str:
        if self.step is Step.REQUEST_LIST:
            what = "MISSION_COUNT"
        else:
            what = f"item {len(self.items)} of {self.count}"
        return what

    def _timeout_seq(self) -> int | None:
        return len(self.items) if self.step is Step.REQUEST_ITEMS else None


class Clear(Transfer):
    """Delete the vehicle's items of one mission type (255: all types)."""

    operation = "clear"
    message_types = frozenset({"MISSION_ACK"})

    def _clear(self) -> Any:
        return mavlink2.MAVLink_mission_clear_all_message(
            self.target_system, self.target_component, self.mission_type
        )

    def _start(self, now_s: float) -> list[Any]:
        self.step = Step.SEND_CLEAR
        return [self._clear()]

    def _handle(self, msg: Any, now_s: float) -> list[Any]:
        result = int(msg.type)
        if result == MAV_MISSION_ACCEPTED:
            self.mav_result = result
            self._succeed()
        else:
            self._fail_nack(result, None)
        return []

    def _resend(self, now_s: float) -> list[Any]:
        return [self._clear()]

    def _awaited(self) -> str:
        return "MISSION_ACK"


class SetCurrent(Transfer):
    """Make item ``seq`` the current mission item; confirmed by MISSION_CURRENT.

    A MISSION_CURRENT with another seq (the vehicle's stream before it took our request) is
    noted, not an error: the request is resent on timeout, and the timeout message says what
    the vehicle last reported.
    """

    operation = "set-current"
    message_types = frozenset({"MISSION_CURRENT"})

    def __init__(self, seq: int, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        if isinstance(seq, bool) or not isinstance(seq, int) or not 0 <= seq <= _SEQ_MAX:
            raise MissionInputError(
                f"vehicle {self.target_system}: cannot set current item {seq!r}: "
                f"seq must be an integer in [0, {_SEQ_MAX}]",
                vehicle=self.target_system,
                seq=None,
                mission_type=self.mission_type,
                operation=self.operation,
            )
        self.seq = seq
        self.reported: tuple[int, int] | None = None
        """(seq, total) of the last MISSION_CURRENT seen."""

    def _set(self) -> Any:
        return mavlink2.MAVLink_mission_set_current_message(
            self.target_system, self.target_component, self.seq
        )

    def _start(self, now_s: float) -> list[Any]:
        self.step = Step.SEND_SET_CURRENT
        return [self._set()]

    def _handle(self, msg: Any, now_s: float) -> list[Any]:
        self.reported = (int(msg.seq), int(getattr(msg, "total", 0)))
        if int(msg.seq) == self.seq:
            self._succeed()
        return []

    def _resend(self, now_s: float) -> list[Any]:
        return [self._set()]

    def _awaited(self) -> str:
        return f"MISSION_CURRENT with seq {self.seq}"

    def _note(self) -> str:
        if self.reported is None:
            return ""
        seq, total = self.reported
        last = f", last item {total}" if total else ""
        return f" (the vehicle last reported current item {seq}{last})"

    def _timeout_seq(self) -> int | None:
        return self.seq
