"""NiceGUI's server of the display's pages (in the display process, see
topdress.display.process)."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable

from topdress.display.guard import Guard, GuardMiddleware
from topdress.display.hub import DisplayHub
from topdress.display.options import DisplayOptions

log = logging.getLogger(__name__)

ALIVE_PERIOD_S = 0.5  # the display process tells the terminal it serves, this often


def run_server(
    hub: DisplayHub, opts: DisplayOptions, guard: Guard, alive: Callable[[int], None]
) -> None:
    """Serve the pages on this thread until the server is stopped (the display process's
    main thread: uvicorn handles its signals there). `alive(pages)` is called from the event
    loop every ALIVE_PERIOD_S with the browser pages connected: a loop that hangs stops it."""
    from nicegui import Client, app, ui

    from topdress.display.pages import register_pages  # NiceGUI only when serving

    register_pages(hub)
    # In front of everything NiceGUI serves, socket.io included (topdress.display.guard).
    app.add_middleware(GuardMiddleware, guard=guard, attempts=hub)

    async def heartbeat() -> None:
        while True:
            clients = list(Client.instances.values())
            pages = hub.operator_pages_connected(c.id for c in clients if c.has_socket_connection)
            await asyncio.to_thread(alive, pages)  # a socket write: off the event loop
            await asyncio.sleep(ALIVE_PERIOD_S)

    tasks: list[asyncio.Task[None]] = []  # held: the loop keeps only a weak reference
    app.on_startup(lambda: tasks.append(asyncio.get_running_loop().create_task(heartbeat())))
    ui.run(
        host=opts.host,
        port=opts.port,
        title="topdress",
        reload=False,
        show=False,
        show_welcome_message=False,
        uvicorn_logging_level="warning",
        favicon="🌽",
        # The peer is the client: X-Forwarded-For only from display.trusted_proxies (guard).
        proxy_headers=False,
        server_header=False,
        # h11 hands the request target over as written: httptools drops the host of an
        # absolute-form target ("GET http://other.example/"), which the guard must see
        http="h11",
    )
