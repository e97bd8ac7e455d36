"""A CAN segment inside one single-threaded simulation: python-can buses that hand a sent
Message to the other ends as it is.

python-can's virtual bus deep-copies every frame for every receiver (its ends may live in
different threads) and passes it through a locked queue; the software-in-the-loop run sends
about 70 frames a simulated second between two ends stepped by one loop, and the copies cost
more than the frames' decoding. These ends share the Message object, so a receiver must not
modify it (nothing in the protocol, the ECU binding or the cab PC does). The terminal, the
`sim ecu` command and the tests keep python-can's own interfaces.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import can


class InProcessBus(can.BusABC):
    """One end of an in-process segment (make the ends with `segment`). Not thread-safe: one
    loop sends and receives on every end. A receive never waits, as nothing can arrive while
    the only loop waits: an empty end gives None after any timeout, and refuses to wait
    without one."""

    def __init__(self, channel: str, ends: list[InProcessBus], **kwargs: Any) -> None:
        super().__init__(channel=channel, **kwargs)
        self.channel_info = f"in-process CAN segment {channel}"
        self._ends = ends
        self._inbox: deque[can.Message] = deque()
        ends.append(self)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        for end in self._ends:
            if end is not self:
                end._inbox.append(msg)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        """The oldest frame that passes the filters, or None (at once, whatever the timeout);
        CanOperationError without a timeout on an empty end."""
        inbox = self._inbox
        while inbox:
            msg = inbox.popleft()
            if self._matches_filters(msg):
                return msg
        if timeout is None:
            raise can.CanOperationError(f"{self.channel_info}: nothing to receive, ever")
        return None

    def shutdown(self) -> None:
        if self in self._ends:
            self._ends.remove(self)
        self._inbox.clear()
        super().shutdown()


def segment(channel: str, n: int = 2) -> list[InProcessBus]:
    """`n` connected ends of a new segment."""
    ends: list[InProcessBus] = []
    return [InProcessBus(channel, ends) for _ in range(n)]
