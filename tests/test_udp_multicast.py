"""Two processes over udp_multicast CAN: this one plays the machine (World + C ECU core on two
pseudo-terminals and the bus), a child process runs `topdress run` against it like a cab PC."""

from __future__ import annotations

import os
import random
import subprocess
import sys
import time
from pathlib import Path

import can
import pytest

from isobus_rig import udp_port
from topdress.log.session import SessionReader
from topdress.sim.live import LiveMachine
from topdress.sim.tractor import Drive
from topdress.sim.world import World


def _udp_bus(group: str) -> can.BusABC:
    return can.Bus(interface="udp_multicast", channel=group, port=udp_port(group), fd=False)


def _multicast_or_skip(group: str) -> None:
    """Skip (with the reason printed) when this host cannot loop multicast back to itself."""
    try:
        a, b = _udp_bus(group), _udp_bus(group)
    except OSError as exc:
        pytest.skip(f"udp_multicast CAN unavailable here: {exc}")
    try:
        a.send(can.Message(arbitration_id=0x1FFFFFF0, data=b"probe", is_extended_id=True))
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline:
            msg = b.recv(timeout=0.2)
            if msg is not None and msg.arbitration_id == 0x1FFFFFF0:
                return
        pytest.skip(
            "udp_multicast CAN: a probe frame did not loop back; "
            "add a multicast route (ip route add 239.0.0.0/8 dev lo)"
        )
    finally:
        a.shutdown()
        b.shutdown()


@pytest.mark.wallclock
def test_terminal_process_drives_the_machine_over_udp_multicast(tmp_path: Path) -> None:
    group = f"239.74.{random.randrange(1, 250)}.{random.randrange(1, 250)}"
    _multicast_or_skip(group)
    drive = Drive.field_passes(4, 30.0, 7.0)
    world = World(seed=5, drive=drive)
    bus = _udp_bus(group)
    machine = LiveMachine(world, bus)
    cfg = tmp_path / "terminal.toml"
    cfg.write_text(
        "[machine]\nwidth_m = 3.4\n"  # pushed to the ECU in the other process
        f'[gnss]\nport = "{machine.gnss_port.path}"\nbaud = 115200\n'
        f'[crop]\nport = "{machine.crop_port.path}"\nbaud = 115200\n'
        f'[can]\ninterface = "udp_multicast"\nchannel = "{group}"\n'
        f"[can.options]\nport = {udp_port(group)}\n"
        f'[log]\ndir = "{tmp_path}"\n'
    )
    machine.start()
    try:
        child = subprocess.run(
            # headless: --start, the meters start without an operator
            [
                *(sys.executable, "-m", "topdress.cli", "run", "--config", str(cfg)),
                *("--start", "--duration", "8"),
            ],
            capture_output=True,
            text=True,
            timeout=60,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
    finally:
        machine.stop()
        bus.shutdown()
    assert child.returncode == 0, child.stderr
    assert machine.error is None
    # the parameters crossed the process boundary and the ECU worked with them
    assert world.ecu.params.working_width_m == pytest.approx(3.4)
    assert world.ecu.counters.rx_ok > 27
    assert world.truth.applied_kg[0] > 0.0
    (session,) = tmp_path.glob("*.sqlite")
    assert f"session log: {session}" in child.stdout
    with SessionReader(session) as reader:
        rows = list(reader.states())
        counts = reader.raw_counts()
    assert len(rows) >= 70
    assert counts["nmea"] > 50 and counts["crop"] > 40 and counts["can_rx"] > 200
    assert any(r.meter_rpm_upper > 1.0 for r in rows)
    assert any(r.source == "wheel" for r in rows)
