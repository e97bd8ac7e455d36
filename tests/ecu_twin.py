"""The ECU's twin on the other end of a bus, for tests and bench scripts: the C core through the
binding, on virtual time, with fault knobs (mute, deaf to parameters). Test code, no part of
the package (the simulator's World is the machine the demo and the experiments run)."""

from __future__ import annotations

import can

from topdress import protocol
from topdress.ecu import Ecu, EcuParams


class SimulatedEcu:
    """The ECU's twin on a bus: the C core on virtual time, with zero encoder inputs.

    Fault knobs: `mute` (sends nothing: the link must report the ECU lost), `deaf_to_params`
    (drops every PcParamSet unanswered: the link must retry, then fail).
    """

    STEP_S = 0.01

    def __init__(self, bus: can.BusABC, params: EcuParams | None = None, now: float = 0.0) -> None:
        self._bus = bus
        self.ecu = Ecu(params, now_us=self._us(now))
        self._t = now
        self.mute = False
        self.deaf_to_params = False

    @staticmethod
    def _us(t: float) -> int:
        return round(t * 1e6)

    def pump(self, now: float) -> None:
        """Take every pending frame, step the core up to `now`, send what it put out."""
        while (msg := self._bus.recv(timeout=0)) is not None:
            if self.deaf_to_params and msg.arbitration_id == protocol.DEFAULT_IDS.param_set:
                continue
            self.ecu.rx(msg, self._us(self._t))
        while self._t + self.STEP_S <= now + 1e-9:
            self._t += self.STEP_S
            self.ecu.step_raw(self._us(self._t), 0, 0, 0, 0, 0)
        frames = self.ecu.tx()
        if not self.mute:
            for frame in frames:
                self._bus.send(frame)
