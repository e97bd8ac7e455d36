"""Which GNSS receiver this is: what the terminal can tell from its configuration and its lines.

The GNSS lag is a property of the receiver (its latency and velocity filter), so the terminal
keeps the lag learned per receiver (topdress.terminal.gnsslag). NMEA has no serial number; a
receiver is known by

- **the input** it is wired to: `serial:<port>`, `file:<path>` or `stdin` ([gnss]);
- **its sentences**: the addresses (talker + type, e.g. `GNRMC`, `GPGGA`; a proprietary one by
  its manufacturer, `PSRF`, `PUBX`) it sends. The set depends on the make and its set-up, not on
  the sky, once the ones that do are left out: GSV and GSA (one per constellation in view, absent
  at a cold start) and TXT (now and then);
- **its version lines**, when it sends any: a proprietary `$P...VER` sentence or a TXT naming
  hardware or firmware (`HW UBX-M8030`, `ROM CORE 3.01`, `FWVER=...`). Receivers send them at
  power-up only, so a session may see none: two receivers differ by their versions only when both
  were seen and share no line.

The sentences are taken from the first `SETTLE_S` of valid lines; the identity is settled then.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from topdress.config import GnssConfig
from topdress.gnss.nmea import GnssFix

SETTLE_S = 10.0  # valid lines over this long give the sentence set (GSV-like ones at 1 Hz)
#: Sentences that come and go with the sky or now and then: not part of the identity.
TRANSIENT_TYPES = frozenset({"GSV", "GSA", "TXT"})
MAX_VERSION_LINES = 4
MAX_VERSION_CHARS = 80
_VERSION_TEXT = re.compile(r"\b(HW|SW|FW|ROM|FWVER|PROTVER|MOD|VER|VERSION|FIRMWARE)\b", re.I)


def input_key(cfg: GnssConfig) -> str:
    """The configured input: `serial:/dev/ttyUSB0`, `file:/path/log.nmea` or `stdin`."""
    if cfg.source == "serial":
        return f"serial:{cfg.port}"
    if cfg.source == "file":
        return f"file:{cfg.path}"
    return cfg.source


@dataclass(frozen=True)
class ReceiverId:
    """A receiver as the terminal knows it (see the module's doc)."""

    input: str
    sentences: tuple[str, ...] = ()  # sorted addresses, transient ones left out
    versions: tuple[str, ...] = ()  # version lines seen, in order

    def same(self, other: ReceiverId) -> bool:
        """The same receiver: same input, same sentences, versions not contradicting."""
        if self.input != other.input or self.sentences != other.sentences:
            return False
        return not (self.versions and other.versions) or bool(
            set(self.versions) & set(other.versions)
        )

    @property
    def known(self) -> bool:
        """Any sentence seen (a receiver that never spoke is only an input)."""
        return bool(self.sentences)


@dataclass
class ReceiverWatch:
    """Builds the ReceiverId from the decoded lines of one session."""

    input: str
    settle_s: float = SETTLE_S
    _sentences: set[str] = field(default_factory=set)
    _versions: list[str] = field(default_factory=list)
    _first_t: float | None = None
    settled: bool = False

    def see(self, t: float, fix: GnssFix, line: bytes) -> bool:
        """Take one decoded line; True when the identity settled with it."""
        if not fix.ok or fix.talker is None or fix.type is None:
            return False
        self._version(fix, line)
        if self.settled:
            return False
        if self._first_t is None:
            self._first_t = t
        address = _address(fix.talker, fix.type)
        if fix.type not in TRANSIENT_TYPES:
            self._sentences.add(address)
        if t - self._first_t >= self.settle_s:
            self.settled = True
            return True
        return False

    def _version(self, fix: GnssFix, line: bytes) -> None:
        if len(self._versions) >= MAX_VERSION_LINES or fix.type is None:
            return
        ver = fix.talker == "P" and fix.type.endswith("VER")
        if not ver and fix.type != "TXT":
            return  # every other line: no decoding (this runs on each line of the session)
        fields = line.decode("latin-1").strip().lstrip("$").split("*", 1)[0].split(",")
        if ver:
            words = ",".join(fields[1:])
        elif len(fields) >= 5:
            words = ",".join(fields[4:])
            if not _VERSION_TEXT.search(words):
                return
        else:
            return
        words = " ".join(words.split())[:MAX_VERSION_CHARS]
        if words and words not in self._versions:
            self._versions.append(words)

    @property
    def receiver(self) -> ReceiverId:
        """The receiver as seen so far (settled or not)."""
        return ReceiverId(self.input, tuple(sorted(self._sentences)), tuple(self._versions))


def _address(talker: str, kind: str) -> str:
    # A proprietary sentence is known by its manufacturer's three letters ($PSRFEPE -> PSRF).
    return f"P{kind[:3]}" if talker == "P" else f"{talker}{kind}"
