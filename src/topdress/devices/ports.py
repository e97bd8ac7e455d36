"""The serial ports this machine has (pyserial), for the configuration and the settings
screens."""

from __future__ import annotations

from dataclasses import dataclass

from serial.tools import list_ports


@dataclass(frozen=True)
class SerialPortInfo:
    device: str
    description: str
    hwid: str


def list_serial_ports() -> list[SerialPortInfo]:
    """The serial ports this machine has, by device name (USB adapters included)."""
    ports = [
        SerialPortInfo(p.device, p.description or "", p.hwid or "") for p in list_ports.comports()
    ]
    return sorted(ports, key=lambda p: p.device)
