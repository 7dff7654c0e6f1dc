"""The operator console in a real browser: Debian's Chromium, headless, on the page the service
serves at ``/ui/``; the service is ``python -m gcs serve`` on loopback (``tests/service``).

Every request the page makes is recorded (none may leave 127.0.0.1), an uncaught error in the
page fails the test, and screenshots go to ``out/test-artifacts/web/`` (or
``$TCGCS_TEST_ARTIFACTS/web/``)."""

from __future__ import annotations

import asyncio
import os
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import pytest
from playwright.async_api import Browser, Page, async_playwright

from tests.service.conftest import TOKEN, Service, serve

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = Path("/usr/bin/chromium")
ARTIFACTS = Path(os.environ.get("TCGCS_TEST_ARTIFACTS", ROOT / "out" / "test-artifacts")) / "web"
VIEWPORT = {"width": 1600, "height": 1000}


@dataclass
class Console:
    """The page, and what the test reads of it."""

    page: Page
    service: Service
    requests: list[str] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)

    async def open(self, path: str) -> None:
        await self.page.goto(self.service.url + path)

    async def login(self, token: str = TOKEN) -> None:
        await self.page.fill("#token", token)
        await self.page.click("#login-form button[type=submit]")

    async def js(self, expr: str, arg: Any = None) -> Any:
        return await self.page.evaluate(expr, arg)

    async def until(self, expr: str, arg: Any = None, timeout_s: float = 30.0) -> Any:
        """The value of ``expr`` (a JS function of ``arg``) once it is truthy."""
        handle = await self.page.wait_for_function(
            expr, arg=arg, timeout=timeout_s * 1000, polling=50
        )
        return await handle.json_value()

    async def confirm(self) -> None:
        """Press the confirmation dialog's Confirm."""
        await self.page.click("#confirm[open] #confirm-ok")

    async def mission_s(self) -> float:
        return float(await self.js("tcgcs.telemetry ? tcgcs.telemetry.t_s : -1e9"))

    async def until_mission(self, t_s: float, timeout_s: float = 60.0) -> float:
        """Wait for the telemetry's mission time ``t_s``."""
        return float(
            await self.until(
                "t => tcgcs.telemetry && tcgcs.telemetry.t_s >= t && tcgcs.telemetry.t_s",
                t_s,
                timeout_s,
            )
        )

    async def text(self, selector: str) -> str:
        return (await self.page.text_content(selector)) or ""

    async def screenshot(self, name: str) -> Path:
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        path = ARTIFACTS / name
        await self.page.screenshot(path=str(path))
        print(f"screenshot: {path}")
        return path

    def external(self) -> list[str]:
        """Every request whose host is not 127.0.0.1 (a blob: URL is its origin's)."""
        out = []
        for url in self.requests:
            inner = url[5:] if url.startswith("blob:") else url
            if urlsplit(inner).hostname != "127.0.0.1":
                out.append(url)
        return out


@pytest.fixture
async def service(tmp_path: Path) -> AsyncIterator[Service]:
    async with serve(tmp_path / "data") as s:
        yield s


@pytest.fixture
async def chromium() -> AsyncIterator[Browser]:
    if not CHROMIUM.exists():
        pytest.skip(f"{CHROMIUM} is missing (make browser installs it)")
    async with async_playwright() as pw:
        b = await pw.chromium.launch(executable_path=str(CHROMIUM), args=["--no-sandbox"])
        try:
            yield b
        finally:
            await b.close()


@pytest.fixture
async def console(service: Service, chromium: Browser) -> AsyncIterator[Console]:
    context = await chromium.new_context(viewport=VIEWPORT)
    context.set_default_timeout(15_000)
    page = await context.new_page()
    c = Console(page, service)
    page.on("request", lambda r: c.requests.append(r.url))
    page.on("websocket", lambda ws: c.requests.append(ws.url))
    page.on("pageerror", lambda e: c.errors.append(str(e)))
    # Anything the service's Content-Security-Policy refused the page (said on its console).
    page.on(
        "console",
        lambda m: c.errors.append(m.text) if "Content Security Policy" in m.text else None,
    )
    try:
        yield c
    finally:
        await context.close()
        await asyncio.sleep(0)
    assert not c.errors, c.errors
