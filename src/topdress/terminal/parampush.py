"""The ECU's parameters pushed by the terminal's CAN link (terminal.canlink): one PcParamSet
each, every EcuParamAck waited for; retries with a backoff while the ECU is silent; a refusal
fails naming the parameter (at start) or is told to the settings change that asked; the
values in force pushed again to an ECU that restarted (back from a loss, or saying so in its
EcuIdent), with the values renewed meanwhile (the GNSS lag learned so far)."""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field

import can

from topdress import protocol
from topdress.errors import EcuParamError
from topdress.i18n import Text, text
from topdress.protocol import AckResult, FrameIds
from topdress.terminal.ecuview import EcuView, LinkCounters

log = logging.getLogger(__name__)

#: Waits between parameter tries once the fast retries went unanswered (the ECU is not on the
#: bus yet): every 1 s for 5 s, then every 2 s; the last repeats.
PARAM_BACKOFF_S = (1.0, 1.0, 1.0, 1.0, 1.0, 2.0)
GNSS_LAG_ID = protocol.param("GnssLag").id
GNSS_LAG_AUTO_ID = protocol.param("GnssLagAuto").id
# Tolerance of time comparisons: a deadline met to the microsecond counts as met.
_EPS_S = 1e-6


@dataclass
class _ParamPush:
    items: list[tuple[int, float]]
    index: int = 0
    tries: int = 0
    sent_t: float | None = None
    waiting: bool = False  # the fast retries of this parameter went unanswered
    deferred: set[int] = field(default_factory=set)  # ids moved to the end once (inconsistent)
    # A settings push (push_params): told the outcome instead of raising on a refusal.
    on_done: Callable[[str | None, list[int]], None] | None = None
    again: bool = False  # the parameters in force, pushed again to an ECU back from a loss
    refused: AckResult | None = None  # the ECU refused items[index]: not asked again

    @property
    def done(self) -> bool:
        return self.index >= len(self.items)


def _impossible_ack(
    ack: protocol.EcuParamAck, param_id: int, value: float, push: _ParamPush
) -> str | None:
    """Why an answer to `param_id` cannot have come from the ECU, or None when it can."""
    if push.sent_t is None:
        return "no PcParamSet was sent yet"
    spec = protocol.param(param_id)
    raw = spec.to_raw(value)
    if ack.result is AckResult.OK and ack.raw != raw:
        return f"ok, but in force {ack.raw} is not the {raw} sent"  # ok means the value took
    in_force = ack.raw * spec.scale
    if not spec.minimum - spec.scale <= in_force <= spec.maximum + spec.scale:
        # AckRaw is the value the ECU now holds, and it never holds one outside the range
        return f"the value in force {in_force:g} is outside {spec.minimum:g}..{spec.maximum:g}"
    return None


class ParamPusher:
    """The parameter push of one link on one bus. `send(msg)` sends (False: not sent); `stop()`
    stops a running ECU (False: not sent, it is stopped another way); `ecu()`
    is the link's view of the ECU's frames; `counters` the link's (tx_params, param_retries,
    rx_implausible, ecu_restarts)."""

    def __init__(
        self,
        send: Callable[[can.Message], bool],
        stop: Callable[[], bool],
        ids: FrameIds,
        where: str,
        counters: LinkCounters,
        ecu: Callable[[], EcuView],
        event: Callable[[Text], None],
        on_again: Callable[[Mapping[int, float], float], None] | None,
        ack_timeout_s: float,
        retries: int,
        backoff_s: tuple[float, ...],
        isobus: bool = False,
    ) -> None:
        self._isobus = isobus  # on an ISOBUS: no [can.ids] to blame for a deaf ECU
        self._send = send
        self._stop = stop
        self.ids = ids
        self._where = where
        self.counters = counters
        self._ecu = ecu
        self._event = event
        self._on_again = on_again
        self._ack_timeout_s = ack_timeout_s
        self._retries = retries
        self._backoff_s = backoff_s
        self._push: _ParamPush | None = None
        self._params: list[tuple[int, float]] = []
        self._begin_t = 0.0
        self._waited = False  # the push had to wait for a silent ECU
        self.ready = False  # every parameter acknowledged once: the ECU works for us

    @property
    def started(self) -> bool:
        """A push was begun (the ECU is waited for until it is done)."""
        return self._push is not None

    @property
    def done(self) -> bool:
        return self._push is not None and self._push.done

    @property
    def refused(self) -> tuple[str, float, AckResult] | None:
        """The parameter the ECU refused in the push at start (name, value, its answer): the
        push stops there until a new one begins."""
        push = self._push
        if push is None or push.refused is None or push.done:
            return None
        param_id, value = push.items[push.index]
        return protocol.param_name(param_id), value, push.refused

    def heard(self, now: float, back: bool) -> None:
        """The ECU's first status frame, or the first after a loss."""
        push = self._push
        if push is None or push.refused is not None:
            return  # refused: asked again only in a new push
        if push.done:
            if back:  # an ECU that rebooted meanwhile runs on its defaults
                self._push = _ParamPush(list(self._params), again=True)
                self._send_param(now)
        elif push.waiting:
            # It has just been powered: go on at once, not at the end of the backoff.
            push.tries = 0
            push.waiting = False
            self._send_param(now)

    def begin(self, params: Mapping[int, float], now: float) -> None:
        """Start pushing `params` (PcParamSet id -> physical value); see `params_done`.

        Raises ProtocolError at once for a value the frame cannot carry."""
        for param_id, value in params.items():
            protocol.param(param_id).check(value)
        self._begin_t = now
        self._params = sorted(params.items())
        self._push = _ParamPush(list(self._params))
        if self._push.done:
            self._on_push_done(now)
        else:
            self._send_param(now)

    def _send_param(self, now: float) -> None:
        push = self._push
        if push is None or push.done:
            return
        param_id, value = push.items[push.index]
        push.tries += 1
        push.sent_t = now
        self._send(protocol.encode_param_set(param_id, value, ids=self.ids))
        self.counters.tx_params += 1

    def on_ack(self, ack: protocol.EcuParamAck, now: float) -> None:
        push = self._push
        if push is None or push.done or push.refused is not None:
            return
        param_id, value = push.items[push.index]
        if ack.param_id != param_id:
            return  # a late answer to an earlier parameter
        if (why := _impossible_ack(ack, param_id, value, push)) is not None:
            # On a bus anyone can write to (udp_multicast on a LAN), a forged refusal would stop
            # the terminal: an answer the ECU cannot give is counted and ignored instead.
            self.counters.rx_implausible += 1
            log.warning("ignored EcuParamAck for %s: %s", protocol.param_name(param_id), why)
            return
        busy_other = ack.raw != protocol.param(param_id).to_raw(value)
        if ack.result is AckResult.BUSY and busy_other and not self._lag_learned(param_id, push):
            # Running with another value (the terminal restarted mid-field with a new file):
            # stop it, then write again. Busy with the value already in force is as good as Ok.
            # Where the stop goes another way (an ISOBUS: the Task Controller's work state), the
            # parameter is asked again after the acknowledge's timeout, not Busy on Busy at once.
            push.tries = 0
            if self._stop():
                self._send_param(now)
            else:
                push.sent_t = now
            return

        if ack.result is AckResult.INCONSISTENT and self._defer(push, now):
            return
        if ack.result not in (AckResult.OK, AckResult.BUSY):
            reason = ack.result.name.lower().replace("_", " ")
            if push.on_done is not None:
                accepted = [pid for pid, _ in push.items[: push.index]]
                self._push = _ParamPush([])  # nothing pending: commands go on
                name = protocol.param_name(param_id)
                push.on_done(f"{name} = {value:g}: refused by the ECU: {reason}", accepted)
                return
            push.refused = ack.result
            raise EcuParamError(
                protocol.param_name(param_id), value, f"refused by the ECU: {reason}"
            )
        push.index += 1
        push.tries = 0
        push.waiting = False
        if push.done:
            self._on_push_done(now)
        else:
            self._send_param(now)

    def _lag_learned(self, param_id: int, push: _ParamPush) -> bool:
        """`GnssLag` is only where the ECU's learning starts: not worth a stop while it reports
        a lag it learned since it was last heard again, learning on in it and in this push (a
        push that turns learning off makes `GnssLag` the lag in use: written as any other)."""
        lag = self._ecu().lag
        return (
            param_id == GNSS_LAG_ID
            and lag is not None
            and lag.automatic
            and lag.learned_ms is not None
            and dict(push.items).get(GNSS_LAG_AUTO_ID) == 1
        )

    def _defer(self, push: _ParamPush, now: float) -> bool:
        """Move a parameter the ECU finds inconsistent with a value it still holds to the end,
        once: the file's queue_len 3 and cv_window 3 reach an ECU holding cv_window 5 in id
        order, and queue_len 3 is accepted only after cv_window 3."""
        item = push.items[push.index]
        if item[0] in push.deferred or push.index == len(push.items) - 1:
            return False
        push.deferred.add(item[0])
        push.items.append(push.items.pop(push.index))
        push.tries = 0
        self._send_param(now)
        return True

    def push_params(
        self,
        params: Mapping[int, float],
        now: float,
        on_done: Callable[[str | None, list[int]], None],
    ) -> None:
        """Push changed parameters later in the run (settings), acknowledged one by one as at
        start; `on_done(None, ids)` once all are in force, or `on_done(reason, accepted_ids)` at
        the first refusal (nothing raised: the caller puts the accepted ones back). The ECU
        takes parameters only while stopped. ProtocolError at once for a value the frame
        cannot carry."""
        for param_id, value in params.items():
            protocol.param(param_id).check(value)
        self._push = _ParamPush(sorted(params.items()), on_done=on_done)
        if self._push.done:
            self._on_push_done(now)
        else:
            self._send_param(now)

    def renew(self, params: Mapping[int, float]) -> None:
        """Values to push again, in place of those in force, when the ECU comes back from a loss
        (it may have restarted on its defaults); nothing is sent now. ProtocolError for a value
        the frame cannot carry."""
        for param_id, value in params.items():
            protocol.param(param_id).check(value)
        self._keep(params.items())

    def _keep(self, params: Iterable[tuple[int, float]]) -> None:
        """These values replace those kept for the push after the ECU comes back."""
        merged = dict(self._params)
        merged.update(params)
        self._params = sorted(merged.items())

    def _on_push_done(self, now: float) -> None:
        push = self._push
        if push is not None and push.on_done is not None:
            # In force now: what is pushed again after the ECU comes back.
            self._keep(push.items)
            push.on_done(None, [pid for pid, _ in push.items])
            push.on_done = None
        if push is not None and push.again:
            push.again = False
            if self._on_again is not None:
                self._on_again(dict(push.items), now)
        self.ready = True
        if self._waited:
            self._waited = False
            since = now - self._begin_t
            self._event(text("event.ecu_ready", s=since))

    def poll(self, now: float) -> None:
        push = self._push
        if push is None or push.done or push.sent_t is None or push.refused is not None:
            return
        waited = now - push.sent_t + _EPS_S
        if push.tries > self._retries and not push.waiting and waited >= self._ack_timeout_s:
            push.waiting = True
            self._waited = True
            self._event(self._wait_text(push))
        if waited >= self._retry_gap_s(push.tries):
            self.counters.param_retries += 1
            self._send_param(now)

    def _retry_gap_s(self, tries: int) -> float:
        # A present ECU answers within milliseconds: fast retries, then the backoff.
        if tries <= self._retries:
            return self._ack_timeout_s
        return self._backoff_s[min(tries - self._retries - 1, len(self._backoff_s) - 1)]

    def _wait_text(self, push: _ParamPush) -> Text:
        name = protocol.param_name(push.items[push.index][0])
        head = dict(name=name, tries=push.tries, where=self._where)
        if self._ecu().status_t is None:
            return text("event.ecu_wait_silent", **head)
        # It talks but does not answer: other frame identifiers, or a firmware without them.
        return text("event.ecu_wait_deaf_isobus" if self._isobus else "event.ecu_wait_deaf", **head)

    def restarted(
        self, now: float, had: bool, lost: bool, said: str = "event.ecu_restarted"
    ) -> None:
        """The ECU says it runs on its firmware defaults (EcuIdent.OnDefaults) after it said it
        had parameters (`had`), or amid a push it took some of: it restarted, and whatever it
        took is gone, though it was never unheard long enough to be lost (it rebooted within
        ecu_timeout_s). The parameters in force are pushed again from the first; a settings
        change under way is refused. `said`: the event's key (why it is thought restarted)."""
        push = self._push
        if push is None or lost:
            return  # nothing to push yet, or lost: the status that ends the loss pushes them
        if not (had or (not push.done and push.index > 0)):
            return
        self.counters.ecu_restarts += 1
        self._event(text(said))
        if push.on_done is not None and not push.done:
            self._push = None
            push.on_done(str(text(said)), [])
        again = self.ready or push.again
        self._push = _ParamPush(list(self._params), again=again)
        self._send_param(now)
