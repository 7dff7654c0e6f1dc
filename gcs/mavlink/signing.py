"""MAVLink 2 message signing, per link (optional): configuration and codec set-up.

With signing on, every message we send carries a signature made with the link's secret key,
and incoming messages that are unsigned (apart from the ones ``allow_unsigned`` names, by
default RADIO_STATUS, which SiK radios inject unsigned) or wrongly signed are rejected by the
codec; the link counts them (``bad_signature``) and drops them.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Collection
from dataclasses import dataclass, field
from typing import Any

from gcs.mavlink.dialect import MESSAGE_BY_NAME, mavlink2

# MAVLink signing timestamps count 10 microsecond units since 2015-01-01T00:00:00Z.
SIGNING_EPOCH_UNIX_S = 1420070400.0
KEY_BYTES = 32


def key_from_passphrase(passphrase: str) -> bytes:
    """The 32-byte key MAVProxy's ``signing setup PASSPHRASE`` uses (SHA-256 of the text)."""
    return hashlib.sha256(passphrase.encode()).digest()


def signing_timestamp(unix_s: float) -> int:
    return max(0, int((unix_s - SIGNING_EPOCH_UNIX_S) * 100_000))


@dataclass(frozen=True, slots=True)
class SigningConfig:
    """A link's signing key and policy."""

    secret_key: bytes
    link_id: int = 0
    allow_unsigned: Collection[str] = field(default_factory=lambda: frozenset({"RADIO_STATUS"}))

    @classmethod
    def from_hex(cls, key_hex: str) -> SigningConfig:
        """A config for a key given as 64 hex digits.

        Raises
        ------
        ValueError
            Not hex, or not 32 bytes (said in words).
        """
        try:
            key = bytes.fromhex(key_hex)
        except ValueError:
            raise ValueError("not a hex string") from None
        return cls(secret_key=key)

    def __post_init__(self) -> None:
        if len(self.secret_key) != KEY_BYTES:
            raise ValueError(
                f"signing secret_key must be {KEY_BYTES} bytes, got {len(self.secret_key)}"
            )
        if not 0 <= self.link_id <= 255:
            raise ValueError(f"signing link_id {self.link_id} is outside 0..255")
        by_name = MESSAGE_BY_NAME
        for name in self.allow_unsigned:
            if name not in by_name:
                raise ValueError(f"signing allow_unsigned: unknown MAVLink message {name!r}")


class CheckingCodec(mavlink2.MAVLink):  # type: ignore[misc]
    """pymavlink's codec, except that a wrongly signed packet cannot move a stream's clock.

    pymavlink records a stream's timestamp before it compares the signature, so one forged
    packet with a timestamp far in the future would make every genuine packet of that stream
    look like a replay until the real clock caught up. Here a failed check leaves no trace.
    """

    def check_signature(self, msgbuf: bytearray, srcSystem: int, srcComponent: int) -> bool:
        stream = (msgbuf[-13], srcSystem, srcComponent)
        timestamps = self.signing.stream_timestamps
        before, our_ts = timestamps.get(stream), self.signing.timestamp
        ok = bool(super().check_signature(msgbuf, srcSystem, srcComponent))
        if not ok:
            if before is None:
                timestamps.pop(stream, None)
            else:
                timestamps[stream] = before
            self.signing.timestamp = our_ts
        return ok


def apply_signing(mav: Any, config: SigningConfig, *, outgoing: bool) -> None:
    """Set up one pymavlink codec object to sign (``outgoing``) or to check signatures."""
    by_name = MESSAGE_BY_NAME
    allowed_ids = frozenset(by_name[name].id for name in config.allow_unsigned)
    mav.signing.secret_key = config.secret_key
    mav.signing.link_id = config.link_id
    mav.signing.timestamp = signing_timestamp(time.time())
    mav.signing.sign_outgoing = outgoing
    mav.signing.allow_unsigned_callback = lambda _mav, msg_id: msg_id in allowed_ids
