"""The pages: a common frame (screens, language, links) around each screen.

Each page pulls the latest snapshot with a `ui.timer` in the display's own event loop; the
control loop never waits on it. A change of language (from any page, or the console's setting)
redraws every open page's content in place.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from nicegui import Client, ui

from topdress import i18n
from topdress.display.actions import Actions
from topdress.display.calibration import CalibrationScreen
from topdress.display.guard import SCOPE_KEY, ClientInfo
from topdress.display.hub import DisplayHub
from topdress.display.liveness import watch_liveness
from topdress.display.main_screen import MainScreen
from topdress.display.options import is_loopback
from topdress.display.settings_screens import CommunicationScreen, ControlScreen
from topdress.i18n import tr
from topdress.view.snapshot import Snapshot

UPDATE_PERIOD_S = 0.2  # how often a page looks for a new snapshot (5 Hz of the loop's 10)

#: path, catalogue key of the screen's name
SCREENS = (
    ("/", "screen.main"),
    ("/communication", "screen.communication"),
    ("/control", "screen.control"),
    ("/calibration", "screen.calibration"),
)


class Screen(Protocol):
    def update(self, s: Snapshot) -> None: ...


@dataclass
class PageState:
    """One browser tab's view: what it last drew."""

    serial: int = -1
    lang_version: int = -1


# ---- who the page is for, and whether it is live (issue 21: liveness, security) ----------------
def client_info() -> ClientInfo:
    """The client of the page being built, as topdress.display.guard judged its request."""
    request = ui.context.client.request
    info = request.scope.get(SCOPE_KEY) if request is not None else None
    if isinstance(info, ClientInfo):
        return info
    # Not behind the guard (NiceGUI's simulated browser): the peer's address alone.
    host = request.client.host if request is not None and request.client is not None else ""
    return ClientInfo(host, is_loopback(host))


def client_is_remote() -> bool:
    """Whether the page being built is for anyone but the cab's own browser (the PIN rule)."""
    return not client_info().cab


def operator_surface(hub: DisplayHub) -> Actions:
    """The page's command path (the PIN asked of all but the cab's browser), its stale state,
    and whom the page takes it for (`data-operator`: cab or remote, for the tests)."""
    remote = client_is_remote()
    ui.element("span").props(f'data-operator="{"remote" if remote else "cab"}" hidden')
    watch_liveness(hub)
    return Actions(hub, remote, client_info().address)


def frame(hub: DisplayHub, path: str, build: Callable[[Actions], Screen]) -> None:
    """The header (screens, language, time) and the screen's content, kept up to date."""
    state = PageState()
    actions = operator_surface(hub)
    client = ui.context.client
    screen: list[Screen] = []
    ui.page_title("topdress")

    @ui.refreshable
    def content() -> None:
        state.lang_version = i18n.version()
        state.serial = -1  # new elements: the next update fills them whatever the serial
        with ui.row().classes(
            "w-full items-center gap-2 bg-green-900 text-white px-3 py-1 rounded"
        ):
            ui.label("topdress").classes("text-lg font-bold mr-3")
            for target, key in SCREENS:
                button = ui.button(tr(key), on_click=lambda t=target: ui.navigate.to(t))
                button.props("flat no-caps" + (" outline" if target == path else "")).classes(
                    "text-white"
                ).mark(f"nav_{key.removeprefix('screen.')}")
            ui.space()
            clock = ui.label("").classes("font-mono text-sm").mark("clock")
            ui.select(
                {lang: i18n.LANGUAGE_NAMES[lang] for lang in i18n.LANGUAGES},
                value=i18n.language(),
                on_change=lambda e: hub.set_language(str(e.value)),
            ).props("dense dark options-dark standout").classes("w-28").mark("language")
        screen[:] = [build(actions)]
        clock_label[:] = [clock]

    clock_label: list[ui.label] = []
    content()

    def update() -> None:
        if state.lang_version != i18n.version():
            content.refresh()
        expose_markers(client)
        serial, published, s = hub.latest()
        if serial == state.serial:
            return
        state.serial = serial
        clock = clock_label[0]
        clock.set_text(f"t {s.t_s:7.1f} s")
        # The wall-clock time this snapshot was published: the benchmark's update latency.
        clock.props["data-published"] = f"{published:.3f}"
        for sc in screen:
            sc.update(s)

    update()  # the first view carries the values, not dashes until the timer fires
    ui.timer(UPDATE_PERIOD_S, update)


def expose_markers(client: Client) -> None:
    """Each element's marker (what the simulated browser finds it by) as its `data-testid` in
    the real browser, for the end-to-end test and the benchmark: one name for both."""
    for element in list(client.elements.values()):
        markers = element._markers
        if markers and "data-testid" not in element.props:
            element.props["data-testid"] = markers[0]


def register_pages(hub: DisplayHub) -> None:
    """Add the display's pages to NiceGUI's app (call once, before `ui.run`)."""

    @ui.page("/")
    def main_page() -> None:
        cfg = hub.config()
        width_m, max_kg_ha = cfg.machine.width_m, cfg.rate.linear.max_kg_ha
        frame(hub, "/", lambda a: MainScreen(hub, a, width_m, max_kg_ha))

    @ui.page("/communication")
    def communication_page() -> None:
        frame(hub, "/communication", lambda a: CommunicationScreen(hub, a))

    @ui.page("/control")
    def control_page() -> None:
        frame(hub, "/control", lambda a: ControlScreen(hub, a))

    @ui.page("/calibration")
    def calibration_page() -> None:
        frame(hub, "/calibration", lambda a: CalibrationScreen(hub, a))
