"""``python -m gcs serve`` stops gracefully on SIGTERM (a service manager's stop) as on SIGINT:
it finishes, says so, and exits 0."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest

from tests.service.conftest import serve


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
async def test_a_stop_signal_is_a_graceful_stop_that_exits_0(
    tmp_path: Path, sig: signal.Signals
) -> None:
    async with serve(tmp_path / "data") as service, service.client() as client:
        assert (await client.get("/v1/ready")).status_code == 200
        service.proc.send_signal(sig)
        await service.proc.wait()
        assert service.proc.returncode == 0
