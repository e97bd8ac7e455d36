"""Subcommands of this subsystem (registered by topdress.cli)."""

from __future__ import annotations

import argparse
from typing import Any


def register(sub: Any) -> None:
    """Add this subsystem's subcommands to the top-level parser."""
    del sub


_ = argparse
