"""The page never shows a dead machine as live: a full-screen stale state.

The browser decides by itself, because a dead server cannot tell it anything: a script in the
page covers everything with "no connection to the terminal — the values are stale" (and greys
the page under it) as soon as socket.io loses the server (the display process killed: at once)
or when no heartbeat came for `STALE_AFTER_S` (a display process that hangs). The server's
heartbeat also says whether the terminal is still heard (a snapshot within `TERMINAL_SILENT_S`),
so a terminal that hangs or ends shows the same state. socket.io then retries every second at
most; a display process started again accepts the page (NiceGUI reloads it from the new
process) and the state clears.
"""

from __future__ import annotations

import json
import time

from nicegui import ui

from topdress import i18n
from topdress.display.hub import DisplayHub
from topdress.i18n import tr

HEARTBEAT_S = 0.5  # the server tells each page it is alive this often
STALE_AFTER_S = 1.5  # no heartbeat for this long: the page is stale
TERMINAL_SILENT_S = 1.0  # no snapshot from the terminal for this long (10 ticks): stale
RECONNECT_MAX_S = 1.0  # socket.io's longest wait between two tries

_SCRIPT = """
<style>
html.td-stale #app { filter: grayscale(1) blur(3px); opacity: 0.35; }
#td-stale { position: fixed; inset: 0; z-index: 100000; display: none; color: #fff;
  background: rgba(20,20,20,.82); flex-direction: column; align-items: center;
  justify-content: center; text-align: center; padding: 5vh 6vw; font-family: sans-serif; }
html.td-stale #td-stale { display: flex; }
#td-stale .td-title { font-size: 2.2rem; font-weight: 700; line-height: 1.2;
  margin-bottom: 1.2rem; }
#td-stale .td-body { font-size: 1.3rem; max-width: 42rem; }
</style>
<script>
(function () {
  if (window.tdLive) return;
  const live = { beat: Date.now(), fresh: true, connected: false, tuned: false,
                 title: %(title)s, body: %(body)s };
  window.tdLive = live;
  live.beatNow = function (fresh, title, body) {
    live.beat = Date.now();
    live.fresh = fresh;
    if (title) { live.title = title; live.body = body; }
  };
  function overlay() {
    let el = document.getElementById("td-stale");
    if (!el) {
      el = document.createElement("div");
      el.id = "td-stale";
      el.setAttribute("data-testid", "stale");
      el.setAttribute("role", "alertdialog");
      el.innerHTML = '<div class="td-title"></div><div class="td-body"></div>';
      document.body.appendChild(el);
    }
    return el;
  }
  setInterval(function () {
    const socket = window.socket;
    if (socket && !live.tuned) {  // a dead server is tried every second, not up to five
      socket.io.reconnectionDelay(250);
      socket.io.reconnectionDelayMax(%(reconnect_ms)d);
      live.tuned = true;
    }
    if (socket && socket.connected) live.connected = true;
    const lost = live.connected && !(socket && socket.connected);
    const stale = lost || !live.fresh || Date.now() - live.beat > %(stale_ms)d;
    const el = overlay();
    el.querySelector(".td-title").textContent = live.title;
    el.querySelector(".td-body").textContent = live.body;
    document.documentElement.classList.toggle("td-stale", stale);
  }, 100);
})();
</script>
"""


def _texts() -> tuple[str, str]:
    return tr("stale.title"), tr("stale.body")


def watch_liveness(hub: DisplayHub) -> None:
    """Add the stale state and its heartbeat to the page being built."""
    title, body = _texts()
    ui.add_body_html(
        _SCRIPT
        % {
            "title": json.dumps(title),
            "body": json.dumps(body),
            "stale_ms": round(STALE_AFTER_S * 1000),
            "reconnect_ms": round(RECONNECT_MAX_S * 1000),
        }
    )
    shown = [i18n.version()]

    def beat() -> None:
        _, published_wall_s, _ = hub.latest()
        fresh = time.time() - published_wall_s < TERMINAL_SILENT_S
        texts = ""
        if shown[0] != i18n.version():  # the language changed: the texts with the beat
            shown[0] = i18n.version()
            texts = ", " + ", ".join(json.dumps(t) for t in _texts())
        ui.run_javascript(f"window.tdLive && tdLive.beatNow({json.dumps(fresh)}{texts})")

    ui.timer(HEARTBEAT_S, beat)
