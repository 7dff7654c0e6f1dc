"""The stub's own MAVLink 2 framing must give exactly pymavlink's bytes."""

from __future__ import annotations

import itertools
import struct
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_stub.api import Home, SimTeam
from sitl_stub.autopilot import Mode
from sitl_stub.items import MissionItem
from sitl_stub.model import displace_deg
from sitl_stub.telemetry import SPECS
from sitl_stub.wire import Packer, spec_for
from tests.sitl_stub.conftest import Client

HOME = Home(-35.363261, 149.165230, 584.0, 30.0)

_INT_RANGES = {
    "int8_t": (-(2**7), 2**7 - 1),
    "uint8_t": (0, 2**8 - 1),
    "int16_t": (-(2**15), 2**15 - 1),
    "uint16_t": (0, 2**16 - 1),
    "int32_t": (-(2**31), 2**31 - 1),
    "uint32_t": (0, 2**32 - 1),
    "int64_t": (-(2**63), 2**63 - 1),
    "uint64_t": (0, 2**64 - 1),
}


def reference(system_id: int, seq: int, msg: Any) -> bytes:
    """pymavlink's own framing of ``msg`` with sequence number ``seq``."""
    mav = mavlink2.MAVLink(None, srcSystem=system_id, srcComponent=1)
    mav.seq = seq
    return bytes(msg.pack(mav))


def field_values(name: str) -> st.SearchStrategy[tuple[Any, ...]]:
    cls = spec_for(name).cls
    parts: list[st.SearchStrategy[Any]] = []
    for ftype in cls.fieldtypes:
        if ftype in ("float", "double"):
            parts.append(st.one_of(st.just(0.0), st.floats(width=32, allow_nan=False)))
        else:
            lo, hi = _INT_RANGES[ftype]
            parts.append(st.one_of(st.just(0), st.integers(lo, hi)))
    return st.tuples(*parts)


FAST = sorted(name for name, spec in SPECS.items() if spec.fast)


def test_every_stream_but_arrays_takes_the_fast_path() -> None:
    assert set(SPECS) - set(FAST) == {"HOME_POSITION", "AUTOPILOT_VERSION"}


@pytest.mark.parametrize("name", FAST)
@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_fast_framing_equals_pymavlink_for_any_values(name: str, data: st.DataObject) -> None:
    values = data.draw(field_values(name))
    seq = data.draw(st.integers(0, 255))
    spec = SPECS[name]
    packer = Packer(7, 1)
    for _ in range(seq):
        packer.pack(spec, values)
    assert packer.pack(spec, values) == reference(7, seq, spec.message(values))
    assert packer.seq == (seq + 1) % 256


def _flying_vehicle_messages() -> list[tuple[int, bytes, Any]]:
    """(seq, bytes, pymavlink message) for every stream of a climbing, turning aircraft."""
    team = SimTeam.create(homes=[HOME], seed=5)
    v = team.vehicles[0]
    sent: list[bytes] = []
    v.set_sender(lambda _link, data: sent.append(data))
    items = [MissionItem(0, 0, 16)]
    for n, e, cmd, alt in ((300, 0, 22, 60.0), (1500, 800, 16, 150.0), (0, 1500, 16, 40.0)):
        lat, lon = displace_deg(HOME.lat_deg, HOME.lon_deg, HOME.alt_m, n, e)
        items.append(MissionItem(len(items), 3, cmd, x=round(lat * 1e7), y=round(lon * 1e7), z=alt))
    v.autopilot.replace_mission(items)
    v.autopilot.arm()
    assert v.autopilot.set_mode(Mode.AUTO)
    out: list[tuple[int, bytes, Any]] = []
    for k in range(900):
        team.step()
        if k % 150 == 149:
            for name in SPECS:
                sent.clear()
                msg = v.message(name)
                v.emit_named(name)
                (data,) = sent
                out.append((data[4], data, msg))
    assert not v.true_state.on_ground
    return out


def test_stream_bytes_equal_pymavlink_in_flight() -> None:
    checked = _flying_vehicle_messages()
    assert {m.get_type() for _, _, m in checked} == set(SPECS)
    for seq, data, msg in checked:
        assert data == reference(1, seq, msg), msg.get_type()


def test_packets_decode_with_the_values_sent() -> None:
    parser = mavlink2.MAVLink(None)
    for _, data, msg in _flying_vehicle_messages():
        (got,) = parser.parse_buffer(data)
        assert got.get_type() == msg.get_type()
        for field in msg.get_fieldnames():
            want = getattr(msg, field)
            if isinstance(want, float):
                assert getattr(got, field) == struct.unpack("<f", struct.pack("<f", want))[0]
            elif isinstance(want, list | tuple):
                assert list(getattr(got, field)) == pytest.approx(list(want))
            else:
                assert getattr(got, field) == want


def test_missing_extension_fields_take_pymavlink_defaults() -> None:
    spec = spec_for("MISSION_CURRENT")
    assert spec.complete((3,)) == (3, 0, 0, 0)
    with pytest.raises(TypeError):
        spec_for("GLOBAL_POSITION_INT").complete((1, 2))


def test_sequence_wraps_and_is_shared_with_pymavlink_path() -> None:
    packer = Packer(1, 1)
    spec = SPECS["SYSTEM_TIME"]
    seqs = []
    for i in range(300):
        if i % 7 == 0:
            data = packer.pack_message(mavlink2.MAVLink_mission_item_reached_message(i))
        else:
            data = packer.pack(spec, (i, i))
        seqs.append(data[4])
    assert seqs == [i % 256 for i in range(300)]


async def test_one_client_sees_consecutive_sequence_numbers() -> None:
    """MAVProxy and MAVSDK count link loss from sequence gaps (pymavlink's pack alone: 0)."""
    async with SimTeam.start(homes=[HOME], tcp_base=0, speedup=50.0, seed=1) as team:
        c = await Client.connect(team.ports[0])
        try:
            await c.recv(lambda _m: len(c.history) >= 300, timeout=10)
        finally:
            await c.close()
    seqs = [m.get_seq() for m in c.history]
    assert len(seqs) >= 300
    assert all((b - a) % 256 == 1 for a, b in itertools.pairwise(seqs))
