"""Benchmark: reading the MAVLink stream, FramingCodec against pymavlink's own parser.

The stream is what a flight's vehicles send the coordinator (the runner's TELEMETRY_HZ mix:
GLOBAL_POSITION_INT, VFR_HUD, HEARTBEAT, SYSTEM_TIME, WIND, MISSION_CURRENT, SYS_STATUS,
GPS_RAW_INT, in those proportions) from 30 system ids, cut into 4 KiB reads as TCP delivers it.
Both codecs read the same bytes in alternating rounds; the best round of each is kept (the
least disturbed by other work on the machine). Microseconds per message and messages per
second of one core; both must give the same messages, which is checked.

    .venv/bin/python bench/bench_framing.py [--messages 60000] [--rounds 7]
"""

from __future__ import annotations

import argparse
import platform
import random
import time
from typing import Any

from gcs.coordination.runner import TELEMETRY_HZ
from gcs.mavlink.dialect import mavlink2
from gcs.mavlink.framing import FramingCodec
from gcs.mavlink.signing import CheckingCodec


def _message(name: str, rng: random.Random) -> Any:
    m = mavlink2
    t = rng.randrange(1, 2**31)
    return {
        "GLOBAL_POSITION_INT": lambda: m.MAVLink_global_position_int_message(
            t, 356_000_000, 1_085_000_000, 1_200_000, 900_000, 2400, -300, 10, 27_000
        ),
        "VFR_HUD": lambda: m.MAVLink_vfr_hud_message(25.2, 27.9, 270, 48, 1200.0, 0.1),
        "HEARTBEAT": lambda: m.MAVLink_heartbeat_message(1, 3, 217, 10, 4, 3),
        "SYSTEM_TIME": lambda: m.MAVLink_system_time_message(1_796_000_000_000_000 + t, t),
        "WIND": lambda: m.MAVLink_wind_message(270.0, 5.2, 0.1),
        "MISSION_CURRENT": lambda: m.MAVLink_mission_current_message(7, 12, 1, 0),
        "SYS_STATUS": lambda: m.MAVLink_sys_status_message(
            1, 1, 1, 500, 12_000, 1500, 80, 0, 0, 0, 0, 0, 0
        ),
        "GPS_RAW_INT": lambda: m.MAVLink_gps_raw_int_message(
            t, 3, 356_000_000, 1_085_000_000, 1_200_000, 80, 100, 2500, 27_000, 14
        ),
    }[name]()


def stream(n: int, seed: int = 0) -> bytes:
    """``n`` messages of the runner's telemetry mix (and heartbeats) from 30 vehicles."""
    rng = random.Random(seed)
    rates = {k: v for k, v in TELEMETRY_HZ.items() if v > 0} | {"HEARTBEAT": 1.0}
    names, weights = list(rates), list(rates.values())
    packers = [mavlink2.MAVLink(None, srcSystem=s, srcComponent=1) for s in range(1, 31)]
    out = bytearray()
    for _ in range(n):
        name = rng.choices(names, weights)[0]
        out += _message(name, rng).pack(rng.choice(packers))
    return bytes(out)


def read(codec_cls: Any, chunks: list[bytes]) -> tuple[float, list[Any]]:
    codec = codec_cls(None)
    codec.robust_parsing = True
    got: list[Any] = []
    t0 = time.perf_counter()
    for chunk in chunks:
        got += codec.parse_buffer(chunk) or []
    return time.perf_counter() - t0, got


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--messages", type=int, default=60_000)
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args()
    data = stream(args.messages)
    chunks = [data[i : i + 4096] for i in range(0, len(data), 4096)]
    best = {"pymavlink": float("inf"), "FramingCodec": float("inf")}
    for _ in range(args.rounds):
        slow_s, slow = read(CheckingCodec, chunks)
        fast_s, fast = read(FramingCodec, chunks)
        best["pymavlink"] = min(best["pymavlink"], slow_s)
        best["FramingCodec"] = min(best["FramingCodec"], fast_s)
    assert [m.get_msgbuf() for m in fast] == [m.get_msgbuf() for m in slow]
    assert [m.to_dict() for m in fast] == [m.to_dict() for m in slow]
    n = len(slow)
    print(f"machine: {platform.machine()}, CPython {platform.python_version()}; {n} messages")
    print("| reader | µs per message | messages per second (one core) |")
    print("|---|---:|---:|")
    for name, s in best.items():
        print(f"| {name} | {s / n * 1e6:.2f} | {n / s:,.0f} |")
    print(f"ratio pymavlink / FramingCodec: {best['pymavlink'] / best['FramingCodec']:.2f}")


if __name__ == "__main__":
    main()
