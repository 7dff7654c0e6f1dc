"""Command transactions: sans-IO with a fake clock, the runner over a fake link, helpers,
and loopback against the stub."""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import AsyncIterator, Callable, Collection
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from gcs.errors import GcsError
from gcs.mavlink.commands import (
    FORCE_ARM_MAGIC,
    CommandAck,
    CommandCancelled,
    CommandDenied,
    CommandError,
    CommandFailed,
    CommandTemporarilyRejected,
    CommandTimeout,
    CommandTransaction,
    CommandUnsupported,
    IntPosition,
    Result,
    Step,
    arm,
    change_altitude,
    change_speed,
    command_int,
    command_long,
    disarm,
    request_message,
    set_message_interval,
    set_mode,
    start_mission,
)
from gcs.mavlink.link import Link
from gcs.mavlink.retry import RetryPolicy
from sitl_stub.api import Home, SimTeam
from sitl_stub.autopilot import Mode
from sitl_stub.items import MissionItem

GCS_SYS, GCS_COMP = 255, 190
CMD_ARM = int(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM)
CMD_MODE = int(mavlink2.MAV_CMD_DO_SET_MODE)
CMD_SPEED = int(mavlink2.MAV_CMD_DO_CHANGE_SPEED)
ACCEPTED = int(mavlink2.MAV_RESULT_ACCEPTED)
IN_PROGRESS = int(mavlink2.MAV_RESULT_IN_PROGRESS)
DENIED = int(mavlink2.MAV_RESULT_DENIED)
POLICY = RetryPolicy()


def wire(msg: Any, src: tuple[int, int] = (1, 1)) -> Any:
    """``msg`` as a receiver sees it: packed by ``src`` and decoded again."""
    mav = mavlink2.MAVLink(None, srcSystem=src[0], srcComponent=src[1])
    decoded = mavlink2.MAVLink(None).parse_buffer(msg.pack(mav))
    assert decoded is not None and len(decoded) == 1
    return decoded[0]


def ack(
    command: int,
    result: int,
    *,
    src: tuple[int, int] = (1, 1),
    target: tuple[int, int] = (GCS_SYS, GCS_COMP),
    progress: int = 0,
    result_param2: int = 0,
) -> Any:
    return wire(
        mavlink2.MAVLink_command_ack_message(
            command, result, progress, result_param2, target[0], target[1]
        ),
        src,
    )


def tx_for(command: int = CMD_ARM, **kwargs: Any) -> CommandTransaction:
    kwargs.setdefault("own_system", GCS_SYS)
    kwargs.setdefault("own_component", GCS_COMP)
    return CommandTransaction(1, command, (1.0, 0.0), **kwargs)


# -- sans-IO: sending and resending ------------------------------------------------------


def test_command_sends_command_long_with_params_and_zero_confirmation() -> None:
    tx = tx_for()
    (msg,) = tx.start(100.0)
    assert msg.get_type() == "COMMAND_LONG"
    assert (msg.target_system, msg.target_component, msg.command) == (1, 1, CMD_ARM)
    assert msg.confirmation == 0
    params = [getattr(msg, f"param{i}") for i in range(1, 8)]
    assert params == [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    assert tx.step is Step.AWAITING_ACK
    assert tx.deadline_s == pytest.approx(100.0 + POLICY.initial_rto_s)  # nothing measured yet


def test_command_resends_with_incremented_confirmation() -> None:
    tx = tx_for(timeout_s=1.5, retries=5)
    (first,) = tx.start(0.0)
    confirmations = [first.confirmation]
    now = 0.0
    for _ in range(5):
        assert tx.tick(now + 1.49) == []  # not yet
        now += 1.5
        (again,) = tx.tick(now)
        assert again.get_type() == "COMMAND_LONG"
        assert (again.command, again.param1) == (CMD_ARM, 1.0)
        confirmations.append(again.confirmation)
    assert confirmations == [0, 1, 2, 3, 4, 5]
    assert tx.attempts == 6


def test_command_int_resends_same_position_without_confirmation() -> None:
    pos = IntPosition(int(mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT), -353600000, 1491600000, 80.0)
    tx = CommandTransaction(
        2, int(mavlink2.MAV_CMD_DO_REPOSITION), (-1.0, 1.0), position=pos, target_component=1
    )
    (first,) = tx.start(0.0)
    (second,) = tx.tick(1.5)
    for msg in (first, second):
        assert msg.get_type() == "COMMAND_INT"
        assert (msg.target_system, msg.frame, msg.x, msg.y, msg.z) == (
            2,
            pos.frame,
            pos.x,
            pos.y,
            80.0,
        )
        assert (msg.param1, msg.param2, msg.param3, msg.param4) == (-1.0, 1.0, 0.0, 0.0)
        assert not hasattr(msg, "confirmation")
    assert tx.attempts == 2


def test_command_times_out_after_retries() -> None:
    tx = tx_for(timeout_s=1.0, retries=2)
    sent = list(tx.start(0.0))
    now = 0.0
    while not tx.done:
        now += 0.25
        sent += tx.tick(now)
        assert now < 100, "never finished"
    assert len(sent) == 3  # first send + 2 retries
    assert now == pytest.approx(3.0)  # three full timeouts
    assert tx.result is Result.TIMEOUT
    err = tx.error()
    assert isinstance(err, CommandTimeout)
    assert isinstance(err, TimeoutError) and isinstance(err, GcsError)
    assert (err.command, err.result, err.vehicle) == (CMD_ARM, None, 1)
    assert "vehicle 1" in str(err) and "MAV_CMD_COMPONENT_ARM_DISARM" in str(err)
    assert "3 attempts" in str(err)
    assert tx.tick(now + 10) == []  # done: nothing more to send


def test_command_with_zero_retries_sends_once() -> None:
    tx = tx_for(timeout_s=1.0, retries=0)
    assert len(tx.start(0.0)) == 1
    assert tx.tick(1.0) == []
    assert tx.result is Result.TIMEOUT


def test_command_succeeds_on_accepted_ack() -> None:
    tx = tx_for()
    tx.start(0.0)
    tx.tick(1.5)  # one resend
    assert tx.handle(ack(CMD_ARM, ACCEPTED, result_param2=7), 1.6) == []
    assert tx.done and tx.result is Result.SUCCESS
    assert tx.error() is None
    assert tx.ack == CommandAck(
        command=CMD_ARM,
        result=ACCEPTED,
        progress=0,
        result_param2=7,
        vehicle=1,
        component=1,
        attempts=2,
    )
    assert tx.elapsed_s == pytest.approx(1.6)
    assert tx.tick(10.0) == []


# -- sans-IO: the adaptive defaults (gcs.mavlink.retry) ------------------------------------------


def test_command_with_defaults_resends_after_the_measured_round_trip() -> None:
    tx = tx_for(rtt_hint_s=0.004)  # the link's TIMESYNC round trip
    tx.start(0.0)
    assert tx.deadline_s == pytest.approx(tx.rtt.rto_s) and tx.rtt.rto_s < 0.05
    (again,) = tx.tick(tx.deadline_s)
    assert again.confirmation == 1


def test_an_ack_to_a_command_sent_once_is_a_round_trip_sample_and_a_resent_one_not() -> None:
    once = tx_for()
    once.start(0.0)
    once.handle(ack(CMD_ARM, ACCEPTED), 0.03)
    assert once.rtt.samples == 1 and once.rtt.srtt_s == pytest.approx(0.03)
    twice = tx_for()
    twice.start(0.0)
    twice.tick(twice.deadline_s)
    twice.handle(ack(CMD_ARM, ACCEPTED), 0.6)  # either copy's answer (Karn's rule)
    assert twice.done and twice.rtt.samples == 0


def test_command_with_defaults_keeps_resending_while_the_vehicle_is_heard() -> None:
    """No fixed count: it ends at the stall bound, long after five resends."""
    tx = tx_for(rtt_hint_s=0.01)
    tx.start(0.0)
    now, sent = 0.0, 1
    while not tx.done:
        now = tx.deadline_s
        tx.heard(now)  # heartbeats keep coming
        sent += len(tx.tick(now))
    assert now == pytest.approx(POLICY.stall_s)
    assert sent > 100 and tx.result is Result.TIMEOUT
    err = tx.error()
    assert isinstance(err, CommandTimeout)
    assert f"no answer for {POLICY.stall_s:.1f} s" in str(err)


def run_to_the_end_unanswered(tx: CommandTransaction) -> float:
    """Start ``tx`` at 0 and tick it at each deadline until it ends; returns when it did."""
    tx.start(0.0)
    now = 0.0
    while not tx.done:
        now = tx.deadline_s
        tx.tick(now)
    return now


def test_command_with_defaults_fails_when_the_vehicle_is_silent_for_the_bound() -> None:
    tx = tx_for(rtt_hint_s=0.01)
    assert run_to_the_end_unanswered(tx) == pytest.approx(POLICY.silence_s)
    assert f"nothing heard from the vehicle for {POLICY.silence_s:.1f} s" in str(tx.error())
    # Silent for more than quiet_s: the resends backed off (doubling up to max_rto_s), far
    # fewer than one every timeout.
    assert tx.attempts < POLICY.silence_s / tx.rtt.rto_s / 5


def test_in_progress_keeps_a_default_command_alive_past_the_stall_bound() -> None:
    tx = tx_for(rtt_hint_s=0.01, in_progress_timeout_s=5.0)
    tx.start(0.0)
    now = 0.0
    for pct in range(0, 100, 10):
        now += 4.0
        tx.handle(ack(CMD_ARM, IN_PROGRESS, progress=pct), now)
        assert tx.tick(now) == [] and not tx.done
    assert now > POLICY.stall_s
    tx.handle(ack(CMD_ARM, ACCEPTED, progress=100), now + 1.0)
    assert tx.result is Result.SUCCESS and tx.attempts == 1


def test_a_fixed_timeout_without_a_count_is_bounded_by_silence() -> None:
    tx = tx_for(timeout_s=1.0)
    assert run_to_the_end_unanswered(tx) == pytest.approx(POLICY.silence_s)
    assert tx.attempts == int(POLICY.silence_s / 1.0)  # one a second until the bound


# -- sans-IO: in progress ------------------------------------------------------------------


def test_command_in_progress_extends_deadline_without_resend() -> None:
    tx = tx_for(timeout_s=1.5, retries=5, in_progress_timeout_s=4.0)
    tx.start(0.0)
    tx.handle(ack(CMD_ARM, IN_PROGRESS, progress=10), 1.0)
    assert tx.step is Step.IN_PROGRESS
    assert tx.progress == 10
    assert tx.deadline_s == pytest.approx(5.0)
    # well past the command timeout: no resend while the in-progress deadline holds
    assert tx.tick(1.5) == []
    assert tx.tick(4.9) == []
    tx.handle(ack(CMD_ARM, IN_PROGRESS, progress=60), 4.9)
    assert tx.progress == 60
    assert tx.tick(8.8) == []
    assert not tx.done
    tx.handle(ack(CMD_ARM, ACCEPTED, progress=100), 8.8)
    assert tx.done and tx.result is Result.SUCCESS
    assert tx.attempts == 1
    assert tx.ack is not None and tx.ack.progress == 100


def test_command_in_progress_with_unknown_progress_keeps_last_known() -> None:
    tx = tx_for()
    tx.start(0.0)
    tx.handle(ack(CMD_ARM, IN_PROGRESS, progress=30), 0.5)
    tx.handle(ack(CMD_ARM, IN_PROGRESS, progress=255), 1.0)
    assert tx.progress == 30


def test_command_in_progress_then_silence_times_out_without_resend() -> None:
    tx = tx_for(timeout_s=1.5, retries=5, in_progress_timeout_s=3.0)
    tx.start(0.0)
    tx.handle(ack(CMD_ARM, IN_PROGRESS, progress=42), 0.5)
    assert tx.tick(3.49) == []
    assert tx.tick(3.5) == []
    assert tx.done and tx.result is Result.TIMEOUT
    err = tx.error()
    assert isinstance(err, CommandTimeout)
    assert "progress at 42%" in str(err)


def test_command_in_progress_then_denied_ends_with_denied() -> None:
    tx = tx_for()
    tx.start(0.0)
    tx.handle(ack(CMD_ARM, IN_PROGRESS, progress=5), 0.5)
    tx.handle(ack(CMD_ARM, DENIED), 0.7)
    assert tx.result is Result.DENIED
    assert isinstance(tx.error(), CommandDenied)


# -- sans-IO: results and errors -------------------------------------------------------------


@pytest.mark.parametrize(
    ("result", "outcome", "error_cls", "name"),
    [
        (2, Result.DENIED, CommandDenied, "MAV_RESULT_DENIED"),
        (4, Result.FAILED, CommandFailed, "MAV_RESULT_FAILED"),
        (3, Result.UNSUPPORTED, CommandUnsupported, "MAV_RESULT_UNSUPPORTED"),
        (1, Result.TEMPORARILY_REJECTED, CommandTemporarilyRejected, "TEMPORARILY_REJECTED"),
        (6, Result.CANCELLED, CommandCancelled, "MAV_RESULT_CANCELLED"),
        (8, Result.UNSUPPORTED, CommandUnsupported, "MAV_RESULT_COMMAND_INT_ONLY"),
        (42, Result.FAILED, CommandFailed, "MAV_RESULT(42)"),
    ],
)
def test_command_denied_raises_typed_error(
    result: int, outcome: Result, error_cls: type[CommandError], name: str
) -> None:
    tx = CommandTransaction(3, CMD_MODE, (1.0, 10.0), own_system=GCS_SYS)
    tx.start(0.0)
    tx.handle(ack(CMD_MODE, result, src=(3, 1)), 0.2)
    assert tx.result is outcome
    err = tx.error()
    assert type(err) is error_cls
    assert isinstance(err, CommandError) and isinstance(err, GcsError)
    assert (err.command, err.result, err.vehicle) == (CMD_MODE, result, 3)
    text = str(err)
    assert "vehicle 3" in text and "MAV_CMD_DO_SET_MODE" in text and name in text


def test_ignores_ack_for_other_command_or_system() -> None:
    tx = tx_for()
    tx.start(0.0)
    others = [
        ack(CMD_MODE, ACCEPTED),  # another command
        ack(CMD_ARM, ACCEPTED, src=(2, 1)),  # another vehicle
        ack(CMD_ARM, ACCEPTED, src=(1, 100)),  # another component of our vehicle
        ack(CMD_ARM, ACCEPTED, target=(254, GCS_COMP)),  # addressed to another GCS
        ack(CMD_ARM, ACCEPTED, target=(GCS_SYS, 191)),  # another component of our GCS
        wire(mavlink2.MAVLink_heartbeat_message(1, 3, 0, 0, 0, 3)),
    ]
    for msg in others:
        assert tx.handle(msg, 0.1) == []
        assert not tx.done
    assert tx.step is Step.AWAITING_ACK
    tx.handle(ack(CMD_ARM, DENIED), 0.2)
    assert tx.result is Result.DENIED


def test_accepts_ack_with_zero_target_fields() -> None:
    tx = tx_for()
    tx.start(0.0)
    tx.handle(ack(CMD_ARM, ACCEPTED, target=(0, 0)), 0.1)
    assert tx.result is Result.SUCCESS


def test_ack_before_start_and_after_done_is_ignored() -> None:
    tx = tx_for()
    tx.handle(ack(CMD_ARM, ACCEPTED), 0.0)
    assert tx.step is Step.IDLE
    tx.start(0.0)
    tx.handle(ack(CMD_ARM, ACCEPTED), 0.1)
    tx.handle(ack(CMD_ARM, DENIED), 0.2)  # a late duplicate must not change the outcome
    assert tx.result is Result.SUCCESS
    with pytest.raises(RuntimeError):
        tx.start(1.0)


def test_error_before_done_is_a_programming_error() -> None:
    tx = tx_for()
    tx.start(0.0)
    with pytest.raises(RuntimeError):
        tx.error()


@pytest.mark.parametrize(
    "kwargs",
    [{"timeout_s": 0.0}, {"timeout_s": math.nan}, {"retries": -1}, {"in_progress_timeout_s": -1}],
)
def test_transaction_rejects_bad_settings(kwargs: dict[str, Any]) -> None:
    with pytest.raises(ValueError):
        tx_for(**kwargs)


def test_transaction_rejects_too_many_params() -> None:
    with pytest.raises(ValueError, match="COMMAND_LONG takes at most 7"):
        CommandTransaction(1, CMD_ARM, (0.0,) * 8)
    with pytest.raises(ValueError, match="COMMAND_INT takes at most 4"):
        CommandTransaction(1, CMD_ARM, (0.0,) * 5, position=IntPosition(0))


# -- the runner over a fake link -----------------------------------------------------------

Responder = Callable[[Any], list[Any]]


class FakeSubscription:
    def __init__(self, link: FakeLink, types: Collection[str] | None, system_id: int | None):
        self.link = link
        self.types = None if types is None else frozenset(types)
        self.system_id = system_id
        self.queue: asyncio.Queue[Any] = asyncio.Queue()

    async def get(self, timeout_s: float | None = None) -> Any | None:
        try:
            async with asyncio.timeout(timeout_s):
                return await self.queue.get()
        except TimeoutError:
            return None

    def __enter__(self) -> FakeSubscription:
        return self

    def __exit__(self, *exc: object) -> None:
        self.link.subs.remove(self)


class FakePeer:
    def __init__(self, autopilot: int) -> None:
        self.autopilot = autopilot


class FakeLink:
    """Enough of gcs.mavlink.link.Link for the runner: replies are delivered synchronously."""

    system_id = GCS_SYS
    component_id = GCS_COMP

    def __init__(self, responder: Responder) -> None:
        self.responder = responder
        self.sent: list[Any] = []
        self.subs: list[FakeSubscription] = []
        self.vehicles: dict[int, FakePeer] = {}

    def add_listener(self, callback: Callable[[Any, float], None]) -> Callable[[], None]:
        return lambda: None

    def subscribe(
        self, types: Collection[str] | None = None, system_id: int | None = None
    ) -> FakeSubscription:
        sub = FakeSubscription(self, types, system_id)
        self.subs.append(sub)
        return sub

    def send(self, msg: Any) -> bool:
        self.sent.append(msg)
        for reply in self.responder(msg):
            for sub in self.subs:
                type_ok = sub.types is None or reply.get_type() in sub.types
                if type_ok and sub.system_id in (None, reply.get_srcSystem()):
                    sub.queue.put_nowait(reply)
        return True


def replying(result: int, *, after: int = 0) -> Responder:
    """A vehicle 1 that answers every command with ``result``, ignoring the first ``after``."""
    seen = [0]

    def respond(msg: Any) -> list[Any]:
        seen[0] += 1
        if seen[0] <= after:
            return []
        return [ack(msg.command, result)]

    return respond


async def test_runner_returns_final_ack() -> None:
    link = FakeLink(replying(ACCEPTED, after=1))
    result = await command_long(link, 1, CMD_ARM, (1.0,), timeout_s=0.05)
    assert result.result == ACCEPTED and result.attempts == 2
    assert [m.confirmation for m in link.sent] == [0, 1]
    assert link.subs == []  # unsubscribed


async def test_runner_with_defaults_resends_and_seeds_the_next_command_with_its_round_trip() -> (
    None
):
    link = FakeLink(replying(ACCEPTED, after=1))
    first = await command_long(link, 1, CMD_ARM, (1.0,))
    assert first.attempts == 2  # resent after the initial timeout, nothing measured
    second = await command_long(link, 1, CMD_ARM, (1.0,))
    assert second.attempts == 1
    from gcs.mavlink.retry import rtt_hint_s

    hint = rtt_hint_s(link, 1)
    assert hint is not None and hint < POLICY.initial_rto_s  # the second ACK's round trip


async def test_runner_raises_typed_error() -> None:
    link = FakeLink(replying(DENIED))
    with pytest.raises(CommandDenied) as err:
        await command_long(link, 1, CMD_ARM, (1.0,))
    assert err.value.ack is not None and err.value.ack.result == DENIED


async def test_runner_never_hangs_on_a_silent_vehicle() -> None:
    link = FakeLink(lambda _msg: [])
    loop = asyncio.get_running_loop()
    t0 = loop.time()
    async with asyncio.timeout(2.0):
        with pytest.raises(CommandTimeout):
            await command_long(link, 1, CMD_ARM, timeout_s=0.05, retries=3)
    assert len(link.sent) == 4  # the first and three retries
    # Each timeout waited out (a busy machine only makes it longer; the 2 s above is the hang).
    assert loop.time() - t0 >= 4 * 0.05 - 1e-3


async def test_runner_command_int_sends_command_int() -> None:
    link = FakeLink(replying(ACCEPTED))
    await command_int(link, 1, int(mavlink2.MAV_CMD_DO_REPOSITION), (-1.0, 1.0), x=1, y=2, z=3.0)
    (msg,) = link.sent
    assert msg.get_type() == "COMMAND_INT" and (msg.x, msg.y, msg.z) == (1, 2, 3.0)


async def test_runner_ignores_ack_addressed_to_another_gcs() -> None:
    def respond(msg: Any) -> list[Any]:
        return [ack(msg.command, DENIED, target=(254, 1)), ack(msg.command, ACCEPTED)]

    link = FakeLink(respond)
    result = await command_long(link, 1, CMD_ARM)
    assert result.result == ACCEPTED


# -- helpers (parameters, validation) --------------------------------------------------------


def last_params(link: FakeLink) -> list[float]:
    msg = link.sent[-1]
    return [getattr(msg, f"param{i}") for i in range(1, 8)]


async def test_arm_and_disarm_params() -> None:
    link = FakeLink(replying(ACCEPTED))
    await arm(link, 1)
    assert link.sent[-1].command == CMD_ARM and last_params(link)[:2] == [1.0, 0.0]
    await arm(link, 1, force=True)
    assert last_params(link)[:2] == [1.0, FORCE_ARM_MAGIC]
    await disarm(link, 1, force=True)
    assert last_params(link)[:2] == [0.0, 21196.0]


async def test_set_mode_arduplane_sends_custom_mode_number() -> None:
    link = FakeLink(replying(ACCEPTED))
    link.vehicles[1] = FakePeer(int(mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA))
    await set_mode(link, 1, "guided")
    assert link.sent[-1].command == CMD_MODE
    assert last_params(link)[:3] == [float(mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), 15.0, 0.0]


async def test_set_mode_px4_sends_main_and_sub_mode() -> None:
    link = FakeLink(replying(ACCEPTED))
    await set_mode(link, 1, "AUTO.MISSION", autopilot=int(mavlink2.MAV_AUTOPILOT_PX4))
    assert last_params(link)[:3] == [1.0, 4.0, 4.0]


async def test_set_mode_validates_before_sending() -> None:
    link = FakeLink(replying(ACCEPTED))
    with pytest.raises(ValueError, match="no HEARTBEAT"):
        await set_mode(link, 1, "AUTO")
    with pytest.raises(ValueError, match=r"valid modes: .*FBWA"):
        await set_mode(link, 1, "HOVER", autopilot=3)
    assert link.sent == []


async def test_change_speed_params_and_validation() -> None:
    link = FakeLink(replying(ACCEPTED))
    await change_speed(link, 1, 22.5)
    assert last_params(link)[:3] == [0.0, 22.5, -1.0]
    await change_speed(link, 1, 18.0, airspeed=False, throttle_pct=60)
    assert last_params(link)[:3] == [1.0, 18.0, 60.0]
    for bad in (math.nan, math.inf, -1.0):
        with pytest.raises(ValueError, match="speed"):
            await change_speed(link, 1, bad)
    with pytest.raises(ValueError, match="throttle"):
        await change_speed(link, 1, 20.0, throttle_pct=150)
    assert len(link.sent) == 2


async def test_change_altitude_is_command_int_with_its_frame_in_param2() -> None:
    """ArduPlane/GCS_Mavlink.cpp handle_command_int_DO_CHANGE_ALTITUDE reads the altitude from
    param1 and its MAV_FRAME from param2 (not the message's frame field)."""
    link = FakeLink(replying(ACCEPTED))
    await change_altitude(link, 1, 812.5)
    sent = link.sent[-1]
    assert sent.get_type() == "COMMAND_INT"
    assert sent.command == int(mavlink2.MAV_CMD_DO_CHANGE_ALTITUDE)
    assert (sent.param1, sent.param2) == (812.5, float(mavlink2.MAV_FRAME_GLOBAL))
    await change_altitude(link, 1, 400.0, above_home=True)
    sent = link.sent[-1]
    assert (sent.param1, sent.param2) == (400.0, float(mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT))
    with pytest.raises(ValueError, match="altitude"):
        await change_altitude(link, 1, math.nan)
    assert len(link.sent) == 2


async def test_set_message_interval_by_name_and_id() -> None:
    link = FakeLink(replying(ACCEPTED))
    await set_message_interval(link, 1, "GLOBAL_POSITION_INT", 0.1)
    assert link.sent[-1].command == int(mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL)
    assert last_params(link)[:2] == [33.0, 100000.0]
    await set_message_interval(link, 1, 74, -1)
    assert last_params(link)[:2] == [74.0, -1.0]
    with pytest.raises(ValueError, match="unknown MAVLink message"):
        await set_message_interval(link, 1, "NOT_A_MESSAGE", 1.0)
    with pytest.raises(ValueError, match="interval_s"):
        await set_message_interval(link, 1, 33, -5.0)


async def test_request_message_and_start_mission_params() -> None:
    link = FakeLink(replying(ACCEPTED))
    await request_message(link, 1, "HOME_POSITION")
    assert link.sent[-1].command == int(mavlink2.MAV_CMD_REQUEST_MESSAGE)
    assert last_params(link)[0] == 242.0
    await start_mission(link, 1, 2, 5)
    assert link.sent[-1].command == int(mavlink2.MAV_CMD_MISSION_START)
    assert last_params(link)[:2] == [2.0, 5.0]


# -- loopback against the stub -------------------------------------------------------------

HOME = Home(-35.36, 149.16, 584.0)


@contextlib.asynccontextmanager
async def stub_link(speedup: float = 20.0) -> AsyncIterator[tuple[SimTeam, Link]]:
    """One stub ArduPlane (system 1) and a link to it that has seen its HEARTBEAT."""
    async with (
        asyncio.timeout(30.0),
        SimTeam.start(homes=[HOME], tcp_base=0, speedup=speedup) as team,
        Link.open(
            f"tcp:127.0.0.1:{team.ports[0]}", system_id=GCS_SYS, component_id=GCS_COMP
        ) as link,
    ):
        await link.wait_vehicle(system_id=1, timeout_s=5.0)
        yield team, link


async def test_loopback_arm_and_set_modes_on_arduplane_stub() -> None:
    async with stub_link() as (team, link):
        ap = team.vehicles[0].autopilot
        result = await arm(link, 1)
        assert result.result == ACCEPTED and result.vehicle == 1 and ap.armed
        # mode numbers from the vehicle's HEARTBEAT autopilot (ArduPilot), no autopilot= given
        await set_mode(link, 1, "FBWA")
        assert ap.mode is Mode.FBWA
        await set_mode(link, 1, "guided")
        assert ap.mode is Mode.GUIDED
        # AUTO with an empty mission would end at once (RTL); give the vehicle a mission
        home = MissionItem(0, int(mavlink2.MAV_FRAME_GLOBAL), 16, x=-353600000, y=1491600000)
        wp = MissionItem(1, 3, 16, x=-353500000, y=1491600000, z=100.0)
        ap.replace_mission([home, wp])
        await set_mode(link, 1, "AUTO")
        assert ap.mode is Mode.AUTO
        await set_mode(link, 1, "MANUAL")
        await disarm(link, 1)
        assert not ap.armed and ap.mode is Mode.MANUAL


async def test_loopback_refused_mode_is_command_failed() -> None:
    async with stub_link() as (team, link):
        with pytest.raises(CommandFailed) as err:
            await set_mode(link, 1, "ACRO")  # the stub refuses modes it does not simulate
        assert err.value.result == int(mavlink2.MAV_RESULT_FAILED) and err.value.vehicle == 1
        assert team.vehicles[0].autopilot.mode is not Mode.ACRO


async def test_loopback_unsupported_command_raises_command_unsupported() -> None:
    async with stub_link() as (_team, link):
        servo = int(mavlink2.MAV_CMD_DO_SET_SERVO)
        with pytest.raises(CommandUnsupported) as err:
            await command_long(link, 1, servo, (5.0, 1500.0))
        assert err.value.result == int(mavlink2.MAV_RESULT_UNSUPPORTED)
        assert "MAV_CMD_DO_SET_SERVO" in str(err.value)
        assert err.value.ack is not None and err.value.ack.attempts == 1
        with pytest.raises(CommandUnsupported):
            await command_int(link, 1, servo, (5.0, 1500.0))


async def test_loopback_change_speed_acknowledged_and_visible_in_stub() -> None:
    async with stub_link(speedup=40.0) as (team, link):
        ap = team.vehicles[0].autopilot
        with pytest.raises(CommandFailed):  # ArduPlane takes it in AUTO or GUIDED only
            await change_speed(link, 1, 12.0, airspeed=False)
        await set_mode(link, 1, "GUIDED")
        await change_speed(link, 1, 12.0, airspeed=False)
        assert ap.params.min_groundspeed_m_s == 12.0
        with pytest.raises(CommandFailed):  # above AIRSPEED_MAX: refused, not clamped
            await change_speed(link, 1, ap.params.airspeed_max_m_s + 5.0)
        # an airspeed demand shows once flying
        await arm(link, 1)
        await set_mode(link, 1, "TAKEOFF")
        await team.wait_sim_time(team.sim_time_s + 12.0)
        assert not team.vehicles[0].true_state.on_ground
        await set_mode(link, 1, "GUIDED")
        target = ap.params.airspeed_max_m_s - 2.0
        await change_speed(link, 1, target)
        await team.wait_sim_time(team.sim_time_s + 0.5)
        assert ap.target_airspeed_m_s == pytest.approx(target)


async def test_loopback_change_altitude_sets_the_waypoint_flown_to() -> None:
    """The stub takes it as ArduPlane does (ArduPlane/GCS_Mavlink.cpp
    handle_command_int_DO_CHANGE_ALTITUDE): AMSL, or above home; holding, it is the held
    altitude."""
    async with stub_link() as (team, link):
        ap = team.vehicles[0].autopilot
        await change_altitude(link, 1, 950.0)
        assert ap._next_wp[2] == pytest.approx(950.0)
        await change_altitude(link, 1, 300.0, above_home=True)
        assert ap._next_wp[2] == pytest.approx(ap.home[2] + 300.0)


async def test_loopback_message_interval_request_message_and_start_mission() -> None:
    async with stub_link() as (team, link):
        vehicle = team.vehicles[0]
        await set_message_interval(link, 1, "GLOBAL_POSITION_INT", 0.1)
        assert vehicle.intervals_s["GLOBAL_POSITION_INT"] == pytest.approx(0.1)
        await set_message_interval(link, 1, "WIND", -1)
        assert vehicle.intervals_s["WIND"] == 0.0
        with link.subscribe(types={"HOME_POSITION"}, system_id=1) as sub:
            await request_message(link, 1, "HOME_POSITION")
            home = await sub.get(timeout_s=2.0)
        assert home is not None and home.latitude == round(HOME.lat_deg * 1e7)
        with pytest.raises(CommandFailed):  # no mission on the vehicle
            await start_mission(link, 1)


async def test_loopback_command_survives_a_lossy_link() -> None:
    async with stub_link() as (team, link):
        team.vehicles[0].link.faults(loss=0.4)
        acks = [await arm(link, 1, timeout_s=0.1, retries=40) for _ in range(5)]
        assert all(a.result == ACCEPTED for a in acks)
        # with 40 % of the packets lost each way (seeded), some commands needed a resend
        assert max(a.attempts for a in acks) > 1
