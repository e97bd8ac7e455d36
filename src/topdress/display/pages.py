"""The pages: a common frame (screens, language, links) around each screen.

Each page pulls the latest snapshot with a `ui.timer` in the display's own event loop; the
control loop never waits on it. A change of language (from any page, or the console's setting)
redraws every open page's content in place.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Protocol

from nicegui import Client, ui

from topdress import i18n
from topdress.display import fmt, style
from topdress.display.actions import Actions
from topdress.display.calibration import CalibrationScreen
from topdress.display.guard import SCOPE_KEY, ClientInfo
from topdress.display.hub import DisplayHub
from topdress.display.liveness import watch_liveness
from topdress.display.main_screen import MainScreen
from topdress.display.map_view import FieldMaps, load_field_maps
from topdress.display.options import is_loopback
from topdress.display.settings_screens import CommunicationScreen, ControlScreen
from topdress.display.units import Units
from topdress.i18n import render, tr
from topdress.view import commands as op
from topdress.view.snapshot import AlarmView, Snapshot

BANNER = "nicegui-row flex-1 items-center no-wrap gap-2 px-2 rounded"
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
    prefs_version: int = -1


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
    client_id = ui.context.client.id
    if not remote:
        hub.operator_pages.add(client_id)
    return Actions(hub, remote, client_info().address, client_id)


def frame(hub: DisplayHub, path: str, build: Callable[[Actions], Screen]) -> None:
    """The header (screens, language, Stop, the run state, the alarm banner) and the screen's
    content, kept up to date.

    The header is built once and stays in view on every screen (a fixed Quasar header): its
    controls are never replaced while shown, only their text and colours change in place, so
    a press never lands on an element that is being redrawn. The screen's content is rebuilt
    only when the language, the units or night mode change."""
    state = PageState()
    actions = operator_surface(hub)
    client = ui.context.client
    screen: list[Screen] = []
    ui.page_title("topdress")
    ui.add_css(style.CSS)
    ui.add_head_html(style.JS)
    dark = ui.dark_mode(hub.prefs.night)
    # NiceGUI's own blue gives white text 3.1:1; by night a lighter one stands out of the dark
    ui.colors(primary=style.PRIMARY_NIGHT if hub.prefs.night else style.PRIMARY)
    header = Header(hub, actions, path)

    @ui.refreshable
    def content() -> None:
        state.lang_version = i18n.version()
        state.prefs_version = hub.prefs_version
        state.serial = -1  # new elements: the next update fills them whatever the serial
        screen[:] = [build(actions)]

    content()

    def update() -> None:
        if state.lang_version != i18n.version() or state.prefs_version != hub.prefs_version:
            dark.set_value(hub.prefs.night)
            ui.colors(primary=style.PRIMARY_NIGHT if hub.prefs.night else style.PRIMARY)
            header.relabel()
            content.refresh()
        expose_markers(client)
        serial, published, s = hub.latest()
        if serial == state.serial:
            return
        state.serial = serial
        header.update(s, published)
        for sc in screen:
            sc.update(s)

    update()  # the first view carries the values, not dashes until the timer fires
    ui.timer(UPDATE_PERIOD_S, update)


def stop_button(on_stop: Callable[[], Awaitable[None]]) -> ui.button:
    """Stop: one touch on every screen, in every state, from every client (no PIN, no lockout,
    no confirmation; it also ends a calibration). Outside the header, fixed over its place in
    the bar and above every dialog, menu and select list (style.CSS), so no overlay takes the
    touch. It acts on the press: an open menu cancels a touch's click (Quasar prevents the
    touchstart outside it), not its pointer events; a keyboard's click (detail 0) acts too."""
    button = (
        ui.button(tr("op.stop"), icon="stop")
        .props("color=red-9 size=lg no-caps")
        .classes("td-stop text-xl font-bold")
        .mark("stop")
    )
    button.on("pointerdown", on_stop)
    button.on("click", on_stop, js_handler="(e) => { if (e.detail === 0) emit(e); }")
    return button


class Header:
    """What every screen shows on top: the screens, language and units, Stop, the run state and
    the alarm banner. Built once per page; `update` and `relabel` change text in place."""

    def __init__(self, hub: DisplayHub, actions: Actions, path: str) -> None:
        self.hub = hub
        self.actions = actions
        self._banner: tuple[object, ...] | None = None
        self._tone: bool | None = None
        self._shown_alarm = ""
        self.nav: dict[str, ui.button] = {}
        with ui.header().classes("td-bar p-1"), ui.column().classes("w-full gap-1"):
            with ui.row().classes("w-full items-center no-wrap gap-1"):
                for target, key in SCREENS:
                    button = ui.button(tr(key), on_click=lambda t=target: ui.navigate.to(t))
                    button.props("flat no-caps" + (" outline" if target == path else "")).classes(
                        "text-white text-base"
                    ).mark(f"nav_{key.removeprefix('screen.')}")
                    self.nav[key] = button
                ui.space()
                self.language = (
                    ui.select(
                        {lang: i18n.LANGUAGE_NAMES[lang] for lang in i18n.LANGUAGES},
                        value=i18n.language(),
                        on_change=lambda e: hub.set_language(str(e.value)),
                    )
                    .props('dark options-dark standout="bg-grey-10 text-white" hide-bottom-space')
                    .classes("w-36 td-lang")
                    .mark("language")
                )
                menu_button = ui.button(icon="tune").props("flat").classes("text-white")
                with menu_button.mark("view_menu"), ui.menu():
                    with ui.menu_item(
                        on_click=lambda: hub.set_prefs(night=not hub.prefs.night)
                    ).mark("night"):
                        self.night_item = ui.label("")
                    with ui.menu_item(on_click=lambda: hub.set_prefs(units=_other_units(hub))).mark(
                        "units"
                    ):
                        self.units_item = ui.label("")
                # Stop's place in the bar; Stop itself floats above every overlay (below).
                ui.element("div").classes("td-stop-place")
            with ui.row().classes("w-full items-center no-wrap gap-2"):
                self.state = (
                    ui.label("--").classes("text-xl font-bold px-2 rounded").mark("op_state")
                )
                with ui.row().classes(f"{BANNER} td-alarm-none") as self.banner:
                    self.banner_icon = ui.icon("notifications_none").classes("text-2xl")
                    self.banner_text = (
                        ui.label(tr("alarm.none")).classes("flex-1 text-lg").mark("alarm_banner")
                    )
                    self.banner_ack = (
                        ui.button(tr("alarm.ack"), on_click=self._ack)
                        .props("color=white text-color=black no-caps")
                        .mark("banner_ack")
                    )
                    self.banner_ack.set_visibility(False)
                self.clock = ui.label("").classes("font-mono text-sm").mark("clock")
        self.stop = stop_button(self._stop)
        self.relabel()

    async def _stop(self) -> None:
        await self.actions.send(op.Stop(), guarded=False)

    async def _ack(self) -> None:
        if self._shown_alarm:
            await self.actions.send(op.AckAlarm(self._shown_alarm))

    def relabel(self) -> None:
        """The header's words in the language in force (after a switch), in place."""
        for key, button in self.nav.items():
            button.set_text(tr(key))
        self.language.set_value(i18n.language())
        self.stop.set_text(tr("op.stop"))
        self.banner_ack.set_text(tr("alarm.ack"))
        prefs = self.hub.prefs
        self.night_item.set_text(tr("view.day" if prefs.night else "view.night"))
        self.units_item.set_text(
            tr("view.metric" if prefs.units == "imperial" else "view.imperial")
        )
        self._banner = None  # redrawn at the next update

    def update(self, s: Snapshot, published: float) -> None:
        self.clock.set_text(f"t {s.t_s:7.1f} s")
        # The wall-clock time this snapshot was published: the benchmark's update latency.
        self.clock.props["data-published"] = f"{published:.3f}"
        self.state.set_text(tr(f"op.state.{s.operator}"))
        fmt.restyle(
            self.state,
            "text-xl font-bold px-2 rounded "
            + {
                "running": "bg-green-9 text-white",
                "paused": "td-alarm-acked",
                "calibrating": "bg-blue-9 text-white",
            }.get(s.operator, "bg-grey-9 text-white"),
        )
        self._draw_banner(s.alarms)

    def _draw_banner(self, alarms: tuple[AlarmView, ...]) -> None:
        key = (alarms, i18n.version())
        if key == self._banner:
            return
        self._banner = key
        order = {"active": 0, "cleared": 1, "acked": 2}
        shown = min(alarms, key=lambda a: order.get(a.state, 3), default=None)
        if shown is None:
            self._shown_alarm = ""
            self.banner_text.set_text(tr("alarm.none"))
            self.banner_icon.name = "notifications_none"
            fmt.restyle(
                self.banner,
                f"{BANNER} td-alarm-none",
            )
            self.banner_ack.set_visibility(False)
        else:
            self._shown_alarm = shown.name
            more = len(alarms) - 1
            said = render(Units(self.hub.prefs.units).shown(shown.text))
            words = f"{said} · {tr(f'alarm.state.{shown.state}')}"
            if more:
                words += " " + tr("alarm.more", n=more)
            self.banner_text.set_text(words)
            self.banner_icon.name = "warning" if shown.state == "active" else "notifications"
            fmt.restyle(
                self.banner,
                f"{BANNER} td-alarm-{shown.state}",
            )
            self.banner_ack.set_visibility(shown.state != "acked")
        self.banner_icon.update()
        tone = any(a.state == "active" for a in alarms)
        if tone != self._tone:
            self._tone = tone
            ui.run_javascript(f"window.tdAlarm && tdAlarm({'true' if tone else 'false'})")


def _other_units(hub: DisplayHub) -> str:
    return "metric" if hub.prefs.units == "imperial" else "imperial"


def expose_markers(client: Client) -> None:
    """Each element's marker (what the simulated browser finds it by) as its `data-testid` in
    the real browser, for the end-to-end test and the benchmark: one name for both."""
    for element in list(client.elements.values()):
        markers = element._markers
        if markers and "data-testid" not in element.props:
            element.props["data-testid"] = markers[0]


def register_pages(hub: DisplayHub) -> None:
    """Add the display's pages to NiceGUI's app (call once, before `ui.run`)."""

    maps: dict[tuple[str, str, float], FieldMaps] = {}

    @ui.page("/")
    def main_page() -> None:
        cfg = hub.config()
        width_m, max_kg_ha = cfg.machine.width_m, cfg.rate.linear.max_kg_ha
        # The field's files, read once (again only when the configuration names others).
        key = (cfg.boundary.path, cfg.prescription.path, cfg.boundary.headland_m)
        if key not in maps:
            maps.clear()
            maps[key] = load_field_maps(cfg)
        field = maps[key]
        frame(hub, "/", lambda a: MainScreen(hub, a, width_m, max_kg_ha, field))

    @ui.page("/communication")
    def communication_page() -> None:
        frame(hub, "/communication", lambda a: CommunicationScreen(hub, a))

    @ui.page("/control")
    def control_page() -> None:
        frame(hub, "/control", lambda a: ControlScreen(hub, a))

    @ui.page("/calibration")
    def calibration_page() -> None:
        frame(hub, "/calibration", lambda a: CalibrationScreen(hub, a))
