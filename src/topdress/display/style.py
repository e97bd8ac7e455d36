"""The cab's look: touch targets, day and night colours, and the alarm tone.

One style sheet for every page. Colours are chosen for WCAG AA in both modes (text 4.5:1,
controls 3:1 against what is behind them; tests/test_display_browser.py measures them from the
rendered page). Every control is at least 48 px high and wide (a gloved finger on a bumping
cab), Stop 64 px. Night mode is Quasar's dark mode plus the overrides below for the few
light-mode colours that would be too dark on a dark background.

The alarm tone is a Web Audio beep made in the page (no audio file): while an alarm is
unacknowledged it beeps every 1.5 s. A browser plays sound only after a first touch on the
page, unless started with `--autoplay-policy=no-user-gesture-required` (the kiosk set-up of
docs/display.md).
"""

from __future__ import annotations

PRIMARY = "#1565c0"  # white text on it 5.8:1, against the day page 5.8:1
PRIMARY_NIGHT = "#1976d2"  # white text on it 4.6:1, against the night page and cards 3.7:1
TOUCH_PX = 48  # the smallest control
STOP_PX = 64  # Stop, on every screen
STOP_W_PX = 144  # Stop's width, whatever the language's word
STOP_Z = 9000  # above every overlay (Quasar's: 6000), below the stale page (liveness: 100000)

#: The header bar, day and night (white text on it: 11.6:1 and 15.4:1).
BAR_DAY = "#1b4332"
BAR_NIGHT = "#0d1f17"

# In NiceGUI's `overrides` layer: after Quasar's and Tailwind's for plain rules, and ahead of
# Quasar's `!important` colour classes (layered importants win in the reverse order).
CSS = f"""
@layer overrides {{
.q-btn {{ min-height: {TOUCH_PX}px; min-width: {TOUCH_PX}px; }}
.q-field__control, .q-field--dense .q-field__control,
.q-field__marginal, .q-field--dense .q-field__marginal {{ min-height: {TOUCH_PX}px; }}
.q-radio, .q-toggle, .q-checkbox {{ min-height: {TOUCH_PX}px; }}
.q-item {{ min-height: {TOUCH_PX}px; }}
.q-tab {{ min-height: {TOUCH_PX}px; }}
.td-stop {{ min-height: {STOP_PX}px !important; min-width: {STOP_PX * 2}px !important;
  border: 3px solid #fff; }}
/* Stop over its place in the header bar, above Quasar's dialogs and menus (z-index 6000) */
.td-stop {{ position: fixed !important; top: 4px; right: 4px; z-index: {STOP_Z};
  width: {STOP_W_PX}px; }}
/* the panel row: each label on one line (Chinese words too), the buttons as wide as they are */
.td-panels .q-btn {{ padding: 0 8px; flex: 1 1 auto; }}
.td-panels .q-btn .block {{ white-space: nowrap; }}
/* the language field sits on the dark bar by day and night: white words on a dark fill, also
   focused (Quasar's standout would turn it white, black words, on a night screen) */
.td-lang .q-field__native, .td-lang .q-field__native span, .td-lang .q-select__dropdown-icon
  {{ color: #fff !important; }}
.td-stop-place {{ width: {STOP_W_PX}px; height: {STOP_PX}px; flex: none; }}
/* a light fill (amber) on a light page: its edge carries the 3:1 */
.td-edge {{ border: 2px solid #000; }}
body.body--dark .td-edge {{ border-color: #fff; }}
.td-bar {{ background: {BAR_DAY}; color: #fff; }}
body.body--dark .td-bar {{ background: {BAR_NIGHT}; }}
.td-muted {{ color: #4b5563; }}
body.body--dark .td-muted {{ color: #c4c4c4; }}
.td-ok {{ color: #1b5e20; }}
body.body--dark .td-ok {{ color: #81c784; }}
.td-bad {{ color: #b71c1c; font-weight: 700; }}
body.body--dark .td-bad {{ color: #ff8a80; }}
.td-warn {{ color: #7a4100; }}
body.body--dark .td-warn {{ color: #ffcc80; }}
/* coloured text (outline and unselected toggle buttons) lightened on a dark page */
body.body--dark .text-primary {{ color: #90caf9 !important; }}
body.body--dark .text-green-10 {{ color: #a5d6a7 !important; }}
.td-card {{ background: #fff; }}
body.body--dark .td-card {{ background: #1d1d1d; }}
.td-alarm-active {{ background: #b71c1c; color: #fff; }}
.td-alarm-acked {{ background: #ffb74d; color: #000; }}
.td-alarm-cleared {{ background: #616161; color: #fff; }}
.td-alarm-none {{ background: transparent; color: #e8f5e9; }}
.td-manual {{ background: #bf360c; color: #fff; }}
.nicegui-content {{ padding: 6px; gap: 6px; }}
.leaflet-container {{ background: #fff !important; }}
body.body--dark .leaflet-container {{ background: #2b2b2b !important; }}
/* the field's lines by night: the day's black is 1.4:1 on the night map, white 14:1 */
body.body--dark .leaflet-container path.td-boundary {{ stroke: #fff; }}
body.body--dark .leaflet-container path.td-zone {{ stroke: #b0bec5; }}
}}
"""

#: The alarm tone (Web Audio) and what the page calls: tdAlarm(on).
JS = """
<script>
window.tdAudio = window.tdAudio || {ctx: null, timer: null, beeps: 0};
function tdBeep() {
  const a = window.tdAudio;
  try {
    if (!a.ctx) a.ctx = new (window.AudioContext || window.webkitAudioContext)();
    if (a.ctx.state === 'suspended') a.ctx.resume();
    const osc = a.ctx.createOscillator(), gain = a.ctx.createGain();
    osc.type = 'square';
    osc.frequency.value = 2400;
    gain.gain.value = 0.25;
    osc.connect(gain);
    gain.connect(a.ctx.destination);
    const t = a.ctx.currentTime;
    osc.start(t);
    osc.stop(t + 0.3);
    a.beeps += 1;
  } catch (e) { a.error = String(e); }
}
function tdAlarm(on) {
  const a = window.tdAudio;
  if (on && !a.timer) { tdBeep(); a.timer = setInterval(tdBeep, 1500); }
  if (!on && a.timer) { clearInterval(a.timer); a.timer = null; }
  document.body.dataset.alarmTone = on ? 'on' : 'off';
}
document.addEventListener('pointerdown', () => {
  const a = window.tdAudio;
  if (a.ctx && a.ctx.state === 'suspended') a.ctx.resume();
}, {capture: true});
</script>
"""


def _linear(channel: float) -> float:
    c = channel / 255.0
    return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4


def luminance(rgb: tuple[float, float, float]) -> float:
    """WCAG 2 relative luminance of an sRGB colour (0..255 channels)."""
    r, g, b = (_linear(c) for c in rgb)
    return 0.2126 * r + 0.7152 * g + 0.0722 * b


def contrast(a: tuple[float, float, float], b: tuple[float, float, float]) -> float:
    """WCAG 2 contrast ratio, 1..21."""
    la, lb = sorted((luminance(a), luminance(b)), reverse=True)
    return (la + 0.05) / (lb + 0.05)
