"""The API docs page (``/v1/docs``) works offline: Swagger UI from the service's own files,
every operation of its OpenAPI document drawn, nothing loaded from outside the service, and
nothing refused by its Content-Security-Policy (the console fixture fails on either)."""

from __future__ import annotations

from tests.web.conftest import Console


async def test_the_docs_page_draws_every_operation_from_the_services_own_files(
    console: Console,
) -> None:
    c = console
    async with c.service.client() as client:
        spec = (await client.get("/v1/openapi.json")).json()
    operations = sum(
        1
        for path in spec["paths"].values()
        for method in path
        if method in ("get", "post", "put", "patch", "delete")
    )
    await c.open("/v1/docs")
    drawn = await c.until(
        "n => document.querySelectorAll('.opblock').length >= n"
        " && document.querySelectorAll('.opblock').length",
        operations,
    )
    assert drawn == operations
    assert "tcgcs" in await c.text(".info .title")
    assert not c.external(), c.external()
    assert any(u.endswith("/ui/docs/swagger-ui-bundle.js") for u in c.requests), c.requests
