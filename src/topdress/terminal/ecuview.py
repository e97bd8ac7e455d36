"""What the terminal's CAN link (terminal.canlink) knows and asks of the ECU: the command it
sends, the ECU's frames as last heard, the link's counters, and who the ECU says it is."""

from __future__ import annotations

from dataclasses import dataclass

from topdress import protocol
from topdress.config import CanConfig
from topdress.i18n import Text, text
from topdress.protocol import FrameIds


def frame_ids(cfg: CanConfig) -> FrameIds:
    """The identifiers of the `[can.ids]` table."""
    return FrameIds(**cfg.ids)


@dataclass(frozen=True)
class Command:
    """What the terminal asks of the ECU (the content of PcCommand)."""

    start: bool = False
    fan_rpm: float = 0.0
    rate_upper_kg_ha: float = 0.0
    rate_lower_kg_ha: float = 0.0
    gnss_kmh: float | None = None


@dataclass
class LinkCounters:
    rx_frames: int = 0
    rx_foreign: int = 0
    rx_malformed: int = 0
    rx_implausible: int = 0  # well-formed frames impossible in the current state: ignored
    tx_commands: int = 0
    tx_params: int = 0
    tx_errors: int = 0
    param_retries: int = 0
    ecu_lost: int = 0
    ecu_restarts: int = 0  # EcuIdent said the ECU restarted on its defaults while heard
    clamped: int = 0


@dataclass(frozen=True)
class EcuView:
    """The latest of each ECU frame, decoded (None until first received)."""

    status: protocol.EcuStatus | None = None
    diag: protocol.EcuDiag | None = None
    speeds: protocol.EcuSpeeds | None = None
    targets: protocol.EcuTargets | None = None
    status_t: float | None = None
    cal: protocol.EcuCalStatus | None = None  # the catch test's status (calibration)
    cal_t: float | None = None  # when that status arrived (the terminal's clock)
    lag: protocol.EcuGnssLag | None = None  # the GNSS lag in use and learned
    ident: protocol.EcuIdent | None = None  # who the ECU says it is (EcuIdent)
    can_health: protocol.EcuCanHealth | None = None  # a firmware's CAN controller (ecuhealth)


def ident_mismatch(ident: protocol.EcuIdent) -> bool:
    """The ECU was built from another version of the protocol than this terminal's."""
    return ident.protocol != protocol.protocol_version()


def terminal_protocol() -> str:
    """This terminal's protocol version, "1.1" (the DBC's VERSION)."""
    return "{}.{}".format(*protocol.protocol_version())


def ident_text(ident: protocol.EcuIdent) -> Text:
    """ "stm32f4 firmware 0.1.0, protocol 1.1" (the console, the screens, the event)."""
    return text(
        "view.ecu_ident",
        target=ident.target,
        firmware=ident.firmware_version,
        protocol=ident.protocol_version,
    )
