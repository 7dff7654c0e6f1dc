"""When to resend and when to give up, for request/reply exchanges with one vehicle (sans-IO).

A transfer resends after a timeout that follows the measured round trip, as TCP's
retransmission timer does (RFC 6298): a smoothed round-trip time and its variation from
replies to requests that were sent once (Karn's rule: a reply to a resent request could
answer either copy), ``rto = srtt + 4 * rttvar`` within ``[min_rto_s, max_rto_s]``. A lost
message then costs a few round trips, not a fixed 1.5 s. A reply that shows an earlier
resend was needless (a duplicate answer) doubles the timeout until the next clean sample, so
a round trip that grows under way is learnt instead of flooded.

A transfer does not fail after a fixed count of resends while the vehicle answers and the
transfer advances. It fails when nothing at all has been heard from the vehicle for
``silence_s`` (it is gone), or when the transfer has not advanced for ``stall_s`` (it is
there but not taking part). While the vehicle is silent the resends back off to
``max_rto_s``, so a dead link is not flooded.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass
from typing import Any, Final

__all__ = ["DEFAULT_POLICY", "RetryPolicy", "RttEstimator", "remember_rtt", "rtt_hint_s"]


@dataclass(frozen=True, slots=True)
class RetryPolicy:
    """Bounds of the adaptive resend timer and of a transfer (wall seconds)."""

    min_rto_s: float = 0.01
    """Shortest resend timeout: a few loopback round trips (on a radio the round trip rules)."""
    max_rto_s: float = 1.5
    """Longest resend timeout: the MAVLink mission service's fixed one."""
    initial_rto_s: float = 0.5
    """Timeout before the first round trip was measured (unless the link measured one)."""
    silence_s: float = 10.0
    """Nothing heard from the vehicle (no reply, no heartbeat, no telemetry) this long: gone."""
    stall_s: float = 20.0
    """No progress (no new item requested or received, no final answer) this long: failed."""
    quiet_s: float = 1.0
    """Resends back off (doubling up to ``max_rto_s``) once the vehicle was silent this long."""

    def __post_init__(self) -> None:
        for name in ("min_rto_s", "max_rto_s", "initial_rto_s", "silence_s", "stall_s", "quiet_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number of seconds, got {v!r}")
        if self.min_rto_s > self.max_rto_s:
            raise ValueError(f"min_rto_s {self.min_rto_s} exceeds max_rto_s {self.max_rto_s}")


DEFAULT_POLICY: Final = RetryPolicy()

_CLOCK_GRANULARITY_S: Final = 0.001  # asyncio's timers on Linux


class RttEstimator:
    """Smoothed round trip and the resend timeout derived from it (RFC 6298)."""

    def __init__(self, policy: RetryPolicy, rtt_hint_s: float | None = None) -> None:
        self.policy = policy
        self.srtt_s: float | None = None
        self.rttvar_s = 0.0
        self.samples = 0
        self._backoff = 1.0
        self._rto_s = policy.initial_rto_s
        if rtt_hint_s is not None and math.isfinite(rtt_hint_s) and rtt_hint_s >= 0:
            self.sample(rtt_hint_s)
            self.samples = 0  # a hint, not a sample of this transfer

    @property
    def rto_s(self) -> float:
        """The resend timeout now (backed off after a needless resend)."""
        p = self.policy
        return min(p.max_rto_s, max(p.min_rto_s, self._rto_s * self._backoff))

    def sample(self, rtt_s: float) -> None:
        """A round trip of an exchange whose request went out once."""
        rtt_s = max(0.0, rtt_s)
        if self.srtt_s is None:
            self.srtt_s, self.rttvar_s = rtt_s, rtt_s / 2.0
        else:
            self.rttvar_s = 0.75 * self.rttvar_s + 0.25 * abs(self.srtt_s - rtt_s)
            self.srtt_s = 0.875 * self.srtt_s + 0.125 * rtt_s
        self.samples += 1
        self._backoff = 1.0
        self._rto_s = self.srtt_s + max(_CLOCK_GRANULARITY_S, 4.0 * self.rttvar_s)

    def needless_resend(self) -> None:
        """A reply arrived for a request already answered: the timer fired too early."""
        self._backoff = min(self._backoff * 2.0, 64.0)

    def wait_s(self, resends: int, silent_s: float) -> float:
        """Timeout before resend number ``resends + 1`` of one exchange.

        ``silent_s``: how long nothing has been heard from the vehicle. A vehicle that is
        heard is answering something, so a missing reply was lost: resend after one
        timeout. A silent one gets doubling waits, up to ``max_rto_s``.
        """
        rto = self.rto_s
        if silent_s < self.policy.quiet_s or resends == 0:
            return rto
        return min(self.policy.max_rto_s, rto * 2.0 ** min(resends, 16))


# The smoothed round trip the last exchange measured, per (link, vehicle): the next one's start.
_srtt_s: weakref.WeakKeyDictionary[Any, dict[int, float]] = weakref.WeakKeyDictionary()


def rtt_hint_s(link: Any, system_id: int) -> float | None:
    """Where a new transfer's timer starts: the round trip last measured with this vehicle on
    this link (by a mission transfer or a command), else the link's TIMESYNC round trip."""
    hint = _srtt_s.get(link, {}).get(system_id)
    if hint is None:
        hint = getattr(getattr(link, "counters", None), "rtt_s", None)
    return hint


def remember_rtt(link: Any, system_id: int, rtt: RttEstimator) -> None:
    """Keep what ``rtt`` measured (if anything) for the next exchange with this vehicle."""
    if rtt.samples and rtt.srtt_s is not None:
        _srtt_s.setdefault(link, {})[system_id] = rtt.srtt_s
