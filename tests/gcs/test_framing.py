"""FramingCodec gives what pymavlink's parser gives, for any byte stream.

The streams are generated: random messages of every type of the dialect (random field values,
truncated MAVLink 2 payloads as the packer makes them), MAVLink 1 and signed frames, junk
between frames, corrupted bytes, and cuts at random places between ``parse_buffer`` calls.
"""

from __future__ import annotations

import random
import struct
from typing import Any

import pytest

from gcs.mavlink.dialect import mavlink2
from gcs.mavlink.framing import FramingCodec, plain_layout
from gcs.mavlink.signing import CheckingCodec

_INT_RANGES = {
    "int8_t": (-128, 127),
    "uint8_t": (0, 255),
    "int16_t": (-32768, 32767),
    "uint16_t": (0, 65535),
    "int32_t": (-(2**31), 2**31 - 1),
    "uint32_t": (0, 2**32 - 1),
    "int64_t": (-(2**63), 2**63 - 1),
    "uint64_t": (0, 2**64 - 1),
}
CLASSES = sorted(mavlink2.mavlink_map.values(), key=lambda c: c.id)


def _value(rng: random.Random, ftype: str) -> Any:
    if ftype in ("float", "double"):
        # Representable in float32, so that packing does not round it.
        return struct.unpack("<f", struct.pack("<f", rng.uniform(-1e6, 1e6)))[0]
    if ftype == "char":
        return bytes(rng.choice(b"abcXYZ019_ ") for _ in range(rng.randint(0, 3)))
    lo, hi = _INT_RANGES[ftype]
    return rng.choice([0, lo, hi, rng.randint(lo, hi)])


def _message(rng: random.Random, cls: Any) -> Any:
    args = []
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
    for name, ftype in zip(cls.fieldnames, cls.fieldtypes, strict=True):
        n = lengths[name]
        if ftype == "char":
            args.append(bytes(rng.choice(b"abcXYZ019_") for _ in range(rng.randint(0, n or 3))))
        elif n:
            args.append([_value(rng, ftype) for _ in range(n)])
        else:
            args.append(_value(rng, ftype))
    return cls(*args)


def _stream(rng: random.Random, count: int) -> bytes:
    packer = mavlink2.MAVLink(None, srcSystem=rng.randint(1, 255), srcComponent=1)
    signer = mavlink2.MAVLink(None, srcSystem=7, srcComponent=1)
    signer.signing.secret_key = bytes(range(32))
    signer.signing.sign_outgoing = True
    signer.signing.timestamp = 1
    out = bytearray()
    hot = [c for c in CLASSES if plain_layout(c)]
    for _ in range(count):
        cls = rng.choice(hot) if rng.random() < 0.6 else rng.choice(CLASSES)
        msg = _message(rng, cls)
        kind = rng.random()
        if kind < 0.08:
            frame = bytearray(msg.pack(packer, force_mavlink1=True)) if cls.id < 256 else b""
        elif kind < 0.14:
            frame = bytearray(msg.pack(signer))
        else:
            frame = bytearray(msg.pack(packer))
        if rng.random() < 0.05 and frame:
            k = rng.randrange(len(frame))
            frame[k] ^= 1 << rng.randrange(8)  # a flipped bit: a bad CRC, length or marker
        if rng.random() < 0.05:
            out += bytes(rng.randrange(256) for _ in range(rng.randint(1, 12)))  # junk
        out += frame
    return bytes(out)


def _parse(codec: Any, data: bytes, cuts: list[int]) -> list[tuple[Any, ...]]:
    codec.robust_parsing = True  # as the link reads
    got: list[tuple[Any, ...]] = []
    start = 0
    for end in [*cuts, len(data)]:
        for m in codec.parse_buffer(data[start:end]) or []:
            h = m.get_header()
            if m.get_type() == "BAD_DATA":
                got.append(("BAD_DATA", bytes(m.data), m.reason))
            else:
                fields = repr(m.to_dict())
                head = (h.msgId, h.incompat_flags, h.compat_flags, h.mlen, h.seq, h.srcSystem)
                body = (bytes(m.get_msgbuf()), bytes(m._payload or b""), m._signed, m._crc)
                got.append((m.get_type(), fields, *head, h.srcComponent, *body))
        start = end
    return got


@pytest.mark.parametrize("seed", range(12))
def test_framing_codec_reads_a_stream_as_pymavlink_does(seed: int) -> None:
    rng = random.Random(seed)
    data = _stream(rng, 400)
    cuts = sorted(rng.sample(range(1, len(data)), k=rng.randint(0, 60)))
    slow = CheckingCodec(None)
    expected = _parse(slow, data, cuts)
    fast = FramingCodec(None)
    got = _parse(fast, data, cuts)
    assert len(expected) > 300
    assert any(e[0] == "BAD_DATA" for e in expected) or seed % 3  # corruption is drawn often
    assert got == expected
    assert fast.total_packets_received == slow.total_packets_received
    assert fast.total_bytes_received == slow.total_bytes_received


def test_framing_codec_checks_signatures_as_pymavlink_does() -> None:
    """A link that checks signatures: every frame by pymavlink's path (a forged one refused)."""
    key = bytes(range(32))
    signer = mavlink2.MAVLink(None, srcSystem=7, srcComponent=1)
    signer.signing.secret_key = key
    signer.signing.sign_outgoing = True
    signer.signing.timestamp = 10**9
    good = mavlink2.MAVLink_heartbeat_message(1, 3, 0, 0, 0, 3).pack(signer)
    forged = bytearray(mavlink2.MAVLink_heartbeat_message(1, 3, 0, 0, 0, 4).pack(signer))
    forged[-1] ^= 0xFF
    codecs = []
    for cls in (CheckingCodec, FramingCodec):
        c = cls(None)
        c.robust_parsing = True
        c.signing.secret_key = key
        c.signing.timestamp = 10**9
        codecs.append([m.get_type() for m in c.parse_buffer(bytes(good) + bytes(forged)) or []])
    assert codecs[0] == codecs[1] == ["HEARTBEAT", "BAD_DATA"]


def test_plain_layout_is_what_the_fast_path_takes() -> None:
    """The messages a flight streams most are decoded on the fast path; arrays and strings
    (STATUSTEXT, PARAM_VALUE, MISSION_ITEM_INT's neighbours with arrays) are not."""
    by_name = {c.msgname: c for c in CLASSES}
    for name in ("GLOBAL_POSITION_INT", "VFR_HUD", "HEARTBEAT", "SYSTEM_TIME", "WIND"):
        assert plain_layout(by_name[name]), name
    for name in ("STATUSTEXT", "PARAM_VALUE", "GPS_RTCM_DATA"):
        assert not plain_layout(by_name[name]), name
