"""The CAN bus: any python-can interface (socketcan, slcan, pcan, kvaser, virtual,
udp_multicast, ...) opened from the `[can]` section."""

from __future__ import annotations

from typing import Any

import can

from topdress.config import CanConfig
from topdress.errors import DeviceError


def open_bus(cfg: CanConfig, **extra: Any) -> can.BusABC:
    """Open the python-can bus of the `[can]` section; DeviceError when it cannot be opened."""
    kwargs: dict[str, Any] = {"interface": cfg.interface, "channel": cfg.channel}
    if cfg.interface == "udp_multicast":
        kwargs["fd"] = False  # classic CAN frames, like the real bus
    elif cfg.interface != "virtual":
        kwargs["bitrate"] = cfg.bitrate
    kwargs.update(cfg.options)
    kwargs.update(extra)
    try:
        return can.Bus(**kwargs)
    except Exception as exc:
        # anything (kvaser without canlib: NameError); every failure to open is a DeviceError.
        if isinstance(exc, NameError | ImportError | AttributeError):
            raise DeviceError(
                f"cannot open CAN interface {cfg.interface!r}: its driver or the vendor library "
                f"it needs is not installed ({type(exc).__name__}: {exc})"
            ) from exc
        raise DeviceError(
            f"cannot open CAN interface {cfg.interface!r} channel {cfg.channel!r}: {exc}"
        ) from exc
