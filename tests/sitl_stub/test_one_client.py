"""One TCP client per vehicle at a time, as ArduPilot SITL serves its TCP serial ports."""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_stub.api import Home, SimTeam
from tests.sitl_stub.conftest import Client

HOME = Home(-35.36, 149.16, 584.0)


def param_read() -> mavlink2.MAVLink_param_request_read_message:
    return mavlink2.MAVLink_param_request_read_message(1, 1, b"SYSID_THISMAV", -1)


async def test_second_client_waits_until_the_first_disconnects() -> None:
    """Follows libraries/AP_HAL_SITL/UARTDriver.cpp: the listening socket has a backlog
    (listen(fd, 5)) and _check_connection accepts only while not connected ("we only want 1
    connection at a time"); once the client goes, the next pending connection is served."""
    async with SimTeam.start(
        homes=[HOME], tcp_base=0, speedup=20.0, one_client_per_port=True
    ) as team:
        first = await Client.connect(team.ports[0])
        second: Client | None = None
        try:
            await first.recv("HEARTBEAT")
            second = await Client.connect(team.ports[0])  # the connect itself succeeds
            second.send(param_read())
            assert await second.try_recv(lambda _m: True, 1.0) is None
            await first.recv("HEARTBEAT")  # the first is still served
            await first.close()
            # Its request, sent while it waited, is read and answered now.
            value = await second.recv("PARAM_VALUE", timeout=10.0)
            assert value.param_id == "SYSID_THISMAV" and value.param_value == 1.0
            await second.recv("HEARTBEAT")
        finally:
            await first.close()
            if second is not None:
                await second.close()


async def test_default_serves_every_client() -> None:
    async with SimTeam.start(homes=[HOME], tcp_base=0, speedup=20.0) as team:
        a, b = await Client.connect(team.ports[0]), await Client.connect(team.ports[0])
        try:
            await a.recv("HEARTBEAT")
            await b.recv("HEARTBEAT")
        finally:
            await a.close()
            await b.close()
