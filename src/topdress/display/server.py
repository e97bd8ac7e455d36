"""NiceGUI's server of the display's pages (in the display process, see
topdress.display.process)."""

from __future__ import annotations

import logging

from topdress.display.hub import DisplayHub
from topdress.display.options import DisplayOptions

log = logging.getLogger(__name__)


def run_server(hub: DisplayHub, opts: DisplayOptions) -> None:
    """Serve the pages on this thread until the server is stopped (the display process's
    main thread: uvicorn handles its signals there)."""
    from nicegui import ui

    from topdress.display.pages import register_pages  # NiceGUI only when serving

    register_pages(hub)
    ui.run(
        host=opts.host,
        port=opts.port,
        title="topdress",
        reload=False,
        show=False,
        show_welcome_message=False,
        uvicorn_logging_level="warning",
        favicon="🌽",
    )
