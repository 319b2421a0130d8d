"""Bus recovery: the receive thread reopens a failed bus with backoff, counts and reports
each bus event and never ends; the daemon keeps its detector state across the outage.

The reader is driven by a scripted bus and a fake clock (delays are checked as numbers,
never by timing).  The daemon runs on python-can's virtual bus behind a link that goes
down and up as SocketCAN's does on ``ip link set vcan0 down/up`` (measured in the CI VM
with python-can 4.6: the first ``recv`` after the link goes down raises CanOperationError
errno ENETDOWN, later ones time out; every send raises ENETDOWN; a socket opened while the
link is down opens and raises ENETDOWN on its first ``recv``).
"""

from __future__ import annotations

import collections
import dataclasses
import errno
import json
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import can
import pytest
from can.interfaces.virtual import VirtualBus
from live_support import (
    assert_same_events,
    assert_same_events_as_sent,
    drain,
    live_config,
    send_all,
    settle,
    wait_until,
)
from naive_frames import recording_from_candump

from monitor.bus.reader import BusReader
from monitor.bus.recovery import Backoff, error_frame_kind, is_link_error
from monitor.codec.frames import FrameCodec
from monitor.config.settings import load_config
from monitor.detection.alarm import State
from monitor.detection.offline import detect
from monitor.errors import BusError, ConfigError
from monitor.io.candump import format_line, read_candump
from monitor.live.daemon import Daemon
from monitor.live.outputs import ALARM, fault_codes
from monitor.live.pipeline import FramePipeline
from monitor.model.modelfile import load_model
from monitor.resources import resource_path


def enetdown(where: str = "receiving") -> can.CanOperationError:
    return can.CanOperationError(f"Error {where}: Network is down", errno.ENETDOWN)


def error_frame(can_id: int, data1: int = 0) -> can.Message:
    """A SocketCAN error frame: class bits in the id, controller status in data[1]."""
    return can.Message(
        arbitration_id=can_id,
        is_extended_id=False,
        is_error_frame=True,
        data=bytes([0, data1, 0, 0, 0, 0, 0, 0]),
    )


def data_frame(n: int) -> can.Message:
    return can.Message(arbitration_id=0x100 + n, is_extended_id=False, data=bytes([n]))


# linux/can/error.h, written out here independently of monitor.bus.recovery
BUSOFF, RESTARTED, CRTL = 0x040, 0x100, 0x004
RX_PASSIVE, TX_PASSIVE, ACTIVE, RX_WARNING = 0x10, 0x20, 0x40, 0x04


def test_error_frames_are_read_as_linux_can_error_h_defines_them() -> None:
    assert error_frame_kind(error_frame(BUSOFF)) == "bus_off"
    assert error_frame_kind(error_frame(BUSOFF | CRTL, TX_PASSIVE)) == "bus_off"
    assert error_frame_kind(error_frame(RESTARTED)) == "restarted"
    assert error_frame_kind(error_frame(CRTL, RX_PASSIVE)) == "error_passive"
    assert error_frame_kind(error_frame(CRTL, TX_PASSIVE | RX_WARNING)) == "error_passive"
    assert error_frame_kind(error_frame(CRTL, ACTIVE)) == "error_active"
    assert error_frame_kind(error_frame(CRTL, RX_WARNING)) is None  # a warning: counted only
    assert error_frame_kind(error_frame(0x020)) is None  # no ACK
    assert error_frame_kind(error_frame(0x080)) is None  # bus error


def test_link_errors_are_told_from_a_full_transmit_queue() -> None:
    assert is_link_error(enetdown())
    assert is_link_error(can.CanOperationError("Failed to transmit: No such device", 6))
    assert is_link_error(OSError(errno.ENODEV, "No such device"))
    assert not is_link_error(can.CanOperationError("Transmit buffer full"))
    assert not is_link_error(can.CanOperationError("No buffer space", errno.ENOBUFS))


def test_backoff_doubles_up_to_the_maximum_and_resets() -> None:
    b = Backoff(0.1, 1.0)
    assert [b.next() for _ in range(6)] == [0.1, 0.2, 0.4, 0.8, 1.0, 1.0]
    b.reset()
    assert b.next() == 0.1
    with pytest.raises(ValueError):
        Backoff(2.0, 1.0)


# -- the reader on a scripted bus and a fake clock ------------------------------------------


class ScriptBus(can.BusABC):
    """Plays a script shared by every bus the opener makes: a Message is received, an
    exception raised by ``recv``, a callable called with the reader (then an empty poll),
    None an empty poll.  When the script is done, ``done`` is set and polls stay empty."""

    def __init__(self, script: collections.deque, done: threading.Event, rig: Rig) -> None:
        self.script, self.done, self.rig, self.closed = script, done, rig, False
        super().__init__(channel="script")

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self.closed:
            raise can.CanOperationError("recv on a closed bus")
        if not self.script:
            self.done.set()
            time.sleep(0.001)
            return None, False
        item = self.script.popleft()
        if isinstance(item, BaseException):
            raise item
        if callable(item):
            item(self.rig.reader)
            return None, False
        return item, False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        pass

    def shutdown(self) -> None:
        self.closed = True
        super().shutdown()


@dataclasses.dataclass
class Rig:
    reader: BusReader
    delays: list[float]  # what the reader slept, in order
    up_while_waiting: list[bool]  # bus_up at each of those sleeps
    opens: list[str]  # outcome of each opener call
    first: ScriptBus | None = None


def rig(script: list, opens: list | None = None, reopen: bool = True, **kw: Any) -> Rig:
    """A reader on a ScriptBus, run until the script is done; ``opens`` lists the opener's
    outcomes in turn: "ok" or an exception to raise."""
    done = threading.Event()
    shared = collections.deque(script)
    outcomes = collections.deque(opens or [])
    now = [0.0]
    r = Rig(None, [], [], [])  # type: ignore[arg-type]
    r.first = ScriptBus(shared, done, r)

    def opener() -> can.BusABC:
        outcome = outcomes.popleft()
        r.opens.append("ok" if outcome == "ok" else type(outcome).__name__)
        if outcome != "ok":
            raise outcome
        return ScriptBus(shared, done, r)

    def sleep(delay: float) -> bool:
        r.delays.append(delay)
        r.up_while_waiting.append(r.reader.bus_up)
        now[0] += delay
        return False

    r.reader = BusReader(
        r.first, 1000, opener=opener if reopen else None, sleep=sleep, clock=lambda: now[0], **kw
    )
    r.reader.start()
    try:
        assert done.wait(30.0), "the script did not finish"
        assert r.reader.alive  # never ends on a bus error
    finally:
        r.reader.stop()
    return r


def received(reader: BusReader) -> list[can.Message]:
    out = []
    while not reader.queue.empty():
        out.append(reader.queue.get_nowait())
    return out


def test_link_down_reopens_with_backoff_until_the_link_works() -> None:
    a, b, c = data_frame(1), data_frame(2), data_frame(3)
    gone = BusError("cannot open CAN bus socketcan:can0: [Errno 19] No such device")
    r = rig(
        [
            a,
            enetdown(),  # link down: 0.1 s, two failed opens (0.2, 0.4), then an open
            enetdown(),  # ... whose first recv fails (bound to a link still down): 0.5 (max)
            None,  # the next reopened bus receives without error: up
            b,  # a frame through it: the backoff starts again from 0.1
            enetdown(),
            c,
        ],  # down again: 0.1, reopened, frames again
        opens=[gone, gone, "ok", "ok", "ok"],
        backoff=Backoff(0.1, 0.5),
    )
    reader = r.reader
    assert r.delays == [0.1, 0.2, 0.4, 0.5, 0.1]
    assert r.opens == ["BusError", "BusError", "ok", "ok", "ok"]
    assert not any(r.up_while_waiting)  # the daemon sends nothing meanwhile
    assert r.first.closed  # the failed bus was closed before the new one was opened
    events = reader.take_events()
    assert [e.kind for e in events] == ["down", "up", "down", "up"]
    assert "Network is down" in events[0].detail
    assert events[1].down_s == pytest.approx(0.1 + 0.2 + 0.4 + 0.5)  # fake clock
    assert events[3].down_s == pytest.approx(0.1)
    assert (events[1].reopens, events[3].reopens) == (2, 3)
    assert reader.recovery.as_dict() == {
        "bus_down": 2,
        "bus_off": 0,
        "error_passive": 0,
        "reopen_attempts": 5,
        "reopens": 3,
        "reopen_failures": 3,
    }
    assert reader.counts.bus_errors == 3
    assert [m.arbitration_id for m in received(reader)] == [0x101, 0x102, 0x103]
    assert reader.bus_up


def test_bus_off_reopens_until_the_controller_restarts_and_passive_is_logged_once() -> None:
    script = [
        data_frame(1),
        error_frame(CRTL, RX_PASSIVE),  # error-passive: logged
        error_frame(CRTL, TX_PASSIVE),  # still passive: nothing new
        error_frame(CRTL, ACTIVE),  # back to error-active: logged
        error_frame(CRTL, TX_PASSIVE),  # passive again: logged, counted
        error_frame(BUSOFF),  # bus-off: reopen after 0.1 s
        None,  # an empty poll is no proof that the controller is back
        error_frame(BUSOFF),  # bus-off again after the reopen: 0.2 s
        error_frame(RESTARTED),  # the controller restarted: up
        data_frame(2),
    ]
    r = rig(script, opens=["ok", "ok"], backoff=Backoff(0.1, 5.0))
    reader = r.reader
    events = reader.take_events()
    kinds = [e.kind for e in events]
    assert kinds == ["error_passive", "error_active", "error_passive", "bus_off", "up"]
    assert events[-1].detail == "controller restarted"
    assert events[-1].down_s == pytest.approx(0.3)
    assert r.delays == [0.1, 0.2] and not any(r.up_while_waiting)
    rec = reader.recovery
    assert (rec.bus_off, rec.error_passive, rec.reopens, rec.reopen_failures) == (1, 2, 2, 1)
    assert reader.counts.error_frames == 7
    assert len(received(reader)) == len(script) - 1  # every frame, error frames too
    assert reader.bus_up and not reader.error_passive


def test_a_link_error_seen_only_by_the_sender_reopens_the_bus() -> None:
    # SocketCAN reports a link going down once per socket: if a send takes that report,
    # recv never sees it, so the sender passes it on.
    def send_fails(exc: BaseException) -> Callable[[BusReader], None]:
        return lambda reader: reader.report_send_error(exc)

    script = [
        data_frame(1),
        send_fails(can.CanOperationError("Transmit buffer full")),
        None,
        send_fails(enetdown("transmitting")),
        data_frame(2),
    ]
    r = rig(script, opens=["ok"])
    events = r.reader.take_events()
    assert [e.kind for e in events] == ["down", "up"]  # the full queue was no link error
    assert events[0].detail.startswith("send: ") and "Network is down" in events[0].detail
    assert r.delays == [0.1] and r.opens == ["ok"]


def test_a_send_error_the_reader_already_heard_reopens_nothing_more() -> None:
    # The link goes down while a heartbeat is on its way: the send fails and the reader's
    # recv fails too.  That is one outage, one reopen; the late report is no second one.
    def both(reader: BusReader) -> None:
        reader.report_send_error(enetdown("transmitting"))
        raise enetdown()

    r = rig([data_frame(1), both, None, data_frame(2)], opens=["ok", "ok"])
    events = r.reader.take_events()
    assert [e.kind for e in events] == ["down", "up"]
    assert events[0].detail.startswith("receive: ")
    assert r.delays == [0.1] and r.opens == ["ok"]
    assert r.reader.recovery.reopen_failures == 0 and len(received(r.reader)) == 2


def test_a_bus_the_caller_owns_is_retried_not_reopened() -> None:
    r = rig(
        [data_frame(1), enetdown(), enetdown(), data_frame(2)],
        reopen=False,
        backoff=Backoff(0.25, 1.0),
    )
    assert r.delays == [0.25, 0.5]
    assert not r.first.closed and r.reader.recovery.reopens == 0
    assert [e.kind for e in r.reader.take_events()] == ["down", "up"]
    assert len(received(r.reader)) == 2


def test_reopen_delays_are_configured_and_checked(tmp_path) -> None:
    cfg = load_config()
    assert (cfg.bus.reopen_initial_s, cfg.bus.reopen_max_s) == (0.1, 10.0)  # shipped
    p = tmp_path / "m.yaml"
    base = f"dbc: {resource_path('dbc', 'monitor.dbc')}\nmodel: {cfg.model}\n"
    p.write_text(base + "bus:\n  reopen_initial_s: 2\n  reopen_max_s: 0.5\n")
    with pytest.raises(ConfigError, match=r"m\.yaml: bus\.reopen_max_s \(0\.5\) must be >="):
        load_config(p)
    p.write_text(base + "bus:\n  reopen_initial_s: 0\n")
    with pytest.raises(ConfigError, match=r"m\.yaml: bus\.reopen_initial_s must be between"):
        load_config(p)


# -- the daemon across a link that goes down and up ------------------------------------------


class Link:
    """A link shared by the buses opened on it; ``epoch`` counts downs (a socket has a
    pending ENETDOWN until it has reported the latest one).  ``known_down`` says whether
    the daemon has learnt of the outage: a send it tries before that is how it may learn
    (the link can go down while its reader waits in ``recv``), one after it is a fault."""

    def __init__(self) -> None:
        self.up = True
        self.epoch = 0
        self.sends_unaware = 0  # tried while down, before the daemon knew
        self.sends_aware = 0  # tried while down, after it knew
        self.known_down: Callable[[], bool] = lambda: False

    def down(self) -> None:
        self.up = False
        self.epoch += 1


class LinkBus(VirtualBus):
    """python-can's virtual bus behind a ``Link``, with SocketCAN's behaviour on a link
    that goes down (see the module docstring)."""

    def __init__(self, channel: str, link: Link) -> None:
        super().__init__(channel=channel, preserve_timestamps=True)
        self.link = link
        self._reported = link.epoch if link.up else link.epoch - 1

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self._reported != self.link.epoch:
            self._reported = self.link.epoch
            raise enetdown()
        if not self.link.up:
            time.sleep(timeout or 0.0)
            return None, False
        return super()._recv_internal(timeout)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if not self.link.up:
            if self.link.known_down():
                self.link.sends_aware += 1
            else:
                self.link.sends_unaware += 1
            raise enetdown("transmitting")
        super().send(msg, timeout)


LOG = resource_path("replay", "spool_wear.log")
CUT_S = 40.0  # log time the link goes down: the 30 s J window is full, the fault at 45 s
GAP_S = 30.0  # bus time the link stays down (the frames after it are this much later)
END_S = 62.0


def _frames() -> tuple[list[can.Message], list[can.Message]]:
    before, after = [], []
    t0 = None
    for m in read_candump(LOG):
        t0 = m.timestamp if t0 is None else t0
        t = m.timestamp - t0
        if t >= END_S:
            break
        if t < CUT_S:
            before.append(m)
        else:
            m.timestamp += GAP_S
            after.append(m)
    return before, after


def _write_log(path: Path, frames: list[can.Message]) -> None:
    with path.open("w") as fh:
        for m in frames:
            fh.write(
                format_line(m.timestamp, "can0", m.arbitration_id, m.is_extended_id, bytes(m.data))
            )


@pytest.fixture(scope="module")
def outage(tmp_path_factory) -> dict[str, Any]:
    tmp = tmp_path_factory.mktemp("outage")
    before, after = _frames()
    _write_log(tmp / "gapped.log", before + after)  # the same frames as a log, for the desk
    cfg = live_config(tmp, silent_s=0.5, reopen_initial_s=0.05, reopen_max_s=0.2)
    link = Link()
    events: list[dict[str, Any]] = []
    daemon = Daemon(cfg, on_event=events.append, opener=lambda: LinkBus(cfg.bus.channel, link))
    link.known_down = lambda: not daemon.reader.bus_up
    sender = can.Bus(interface="virtual", channel=cfg.bus.channel, preserve_timestamps=True)
    daemon.start()
    try:
        sent = send_all(sender, before)
        settle(daemon, sent)
        last_rx = daemon.reader.received_at  # the reader's clock at the last frame before
        link.down()  # ip link set can0 down
        wait_until(lambda: daemon.reader.recovery.bus_down == 1, 30.0)
        # Down long enough for a heartbeat to fall due and the silence to make it inactive.
        wait_until(lambda: daemon.tx.errors >= 1 and daemon.state is State.INACTIVE, 30.0)
        wait_until(lambda: daemon.reader.recovery.reopen_failures >= 2, 30.0)
        link.up = True  # ip link set can0 up
        wait_until(lambda: daemon.reader.bus_up, 30.0)
        # The daemon times the silence on its reader's clock, the desk by the frames: the
        # log's gap must be the longer, or the daemon's clock would have run past the frames
        # after it (3 s measured at a load average of 16 on 2 cores).
        assert time.monotonic() - last_rx < GAP_S, "the outage outlasted the log's gap"
        settle(daemon, sent + send_all(sender, after))
        alive = daemon.healthy
    finally:
        daemon.stop()
    mon = drain(sender)
    lines = [json.loads(x) for x in cfg.event_log.path.read_text().splitlines()]
    return {
        "daemon": daemon,
        "cfg": cfg,
        "events": events,
        "lines": lines,
        "mon": mon,
        "link": link,
        "alive": alive,
        "t0": before[0].timestamp,
        "gapped": tmp / "gapped.log",
    }


def test_the_daemon_survives_the_outage_and_logs_it(outage) -> None:
    d = outage["daemon"]
    assert outage["alive"] and d.error is None
    c = d.counts()
    assert c["bus_down"] == 1 and c["bus_off"] == 0
    # Every attempt opened a bus (opening works on a link that is down, as on SocketCAN);
    # all but the last failed at their first recv.
    assert c["reopen_attempts"] == c["reopens"] == c["reopen_failures"] + 1 >= 3
    # Once the daemon knew the link was down it tried nothing on it: counted, the detector
    # not held up.  A heartbeat may have fallen due while the reader still waited in recv;
    # then that failed send is what reported the outage.
    link = outage["link"]
    assert c["tx_errors"] >= 1 and link.sends_aware == 0
    bus = [x for x in outage["lines"] if x.get("kind") == "bus"]
    assert [x["bus"] for x in bus] == ["down", "up"]
    down, up = bus
    how = down["detail"].split(":")[0]
    assert how == "receive" or (how == "send" and link.sends_unaware >= 1)
    assert "Network is down" in down["detail"] and down["t"] >= CUT_S - 0.1
    assert up["reopens"] == c["reopens"] and up["down_s"] > 0
    assert up["state"] == "inactive"  # the silence made it inactive; frames not back yet
    # Every line keeps the schema's keys; the state changes are the lines without "kind".
    keys = {"t", "time", "state", "J", "threshold", "fault"}
    assert all(keys <= set(x) for x in outage["lines"])
    assert [x for x in outage["lines"] if "kind" not in x] == outage["events"]


def test_alarms_resume_after_recovery_as_the_desk_sees_the_gap(outage) -> None:
    cfg = outage["cfg"]
    model = load_model(cfg.model)
    desk = detect(model, recording_from_candump(outage["gapped"]), cfg.alarm, cfg.horizon)
    # The detector kept its state over the gap.  The daemon may also have heard the bus
    # silent after the last frame, before it was stopped: that depends on wall time.
    events = assert_same_events_as_sent(outage["events"], desk, outage["daemon"].pipeline.last_t_s)
    states = [e["state"] for e in events]
    assert states[-1] == "fault" and "inactive" in states
    fault = next(e for e in events if e["state"] == "fault")
    # The J window was held, not restarted: the alarm comes at the log instant it comes
    # at without the outage (shifted by the gap), not a 30 s window later.
    plain = detect(model, recording_from_candump(LOG), cfg.alarm, cfg.horizon)
    assert fault["t"] - GAP_S == pytest.approx(plain.summary["first_alarm_t"], abs=0.05)
    # MON_Alarm in fault on the bus after the outage, with the event's fault.
    codec = FrameCodec.from_dbc()
    alarm_id = codec.message(ALARM).frame_id
    alarms = [
        (m.timestamp - outage["t0"], codec.decode_message(m).values)
        for m in outage["mon"]
        if m.arbitration_id == alarm_id
    ]
    t_fault, sig = next((t, v) for t, v in alarms if v["State"] == State.FAULT)
    assert t_fault == pytest.approx(fault["t"], abs=1e-6)
    assert sig["Fault"] == fault_codes(codec)[fault["fault"]]


def test_a_silence_after_the_last_frame_adds_an_inactive_only_when_the_reader_proved_it(
    tmp_path: Path,
) -> None:
    """The test above, with the timing it cannot choose made explicit: the gapped log
    through the daemon's frame pipeline (no threads), the reader's receive stamps and empty
    receives given as numbers.  Whether the daemon heard the bus silent after the last frame
    before it was stopped decides whether it ends inactive; the desk's log ends at the frame."""
    cfg = live_config(tmp_path, silent_s=0.5)
    daemon = Daemon(cfg)  # not started: its codec and loops only
    reader = {"heard": -float("inf"), "rx": 1000.0}
    events: list[dict[str, Any]] = []
    pipe = FramePipeline(
        daemon.codec,
        daemon.columns,
        daemon.loops,
        lambda m: None,
        lambda tick, lp: events.append(lp.event(tick, pipe.start_time_s)),
        cfg.bus.silent_s,
        1.0,
        heard_until=lambda: reader["heard"],
        backlog=lambda: False,
        received_at=lambda: reader["rx"],
    )
    before, after = _frames()
    _write_log(tmp_path / "gapped.log", before + after)

    def receive(frames: list[can.Message]) -> None:
        for m in frames:
            reader["rx"] += 1e-4  # the reader takes them as fast as they are sent
            pipe.feed(m)

    try:
        receive(before)
        reader["heard"] = reader["rx"] + 3.0  # the link is down 3 s: silence proven
        pipe.silence()
        reader["rx"] = reader["heard"] + 0.1  # up again, the rest of the log
        receive(after)
    finally:
        daemon.reader.bus.shutdown()
    model = load_model(cfg.model)
    desk = detect(model, recording_from_candump(tmp_path / "gapped.log"), cfg.alarm, cfg.horizon)
    t_end = float(desk.t[-1])
    # Stopped before the reader proved any silence: the desk's events exactly.
    pipe.flush()
    assert pipe.last_t_s == t_end
    assert_same_events(events, desk)
    assert_same_events_as_sent(events, desk, pipe.last_t_s)
    # Stopped after the reader heard 3 s of silence since the last frame: the clock ran on
    # and the rows went stale, inactive 30 ms (3 cycles of the 10 ms frames) after it.
    reader["heard"] = reader["rx"] + 3.0
    pipe.silence()
    assert pipe.last_t_s == pytest.approx(t_end + 3.0, abs=0.011)
    assert [(e["t"], e["state"]) for e in events[len(desk.events) :]] == [
        (pytest.approx(t_end + 0.04, abs=1e-6), "inactive")
    ]
    with pytest.raises(AssertionError):
        assert_same_events(events, desk)  # what the live test compared: then it failed
    assert assert_same_events_as_sent(events, desk, pipe.last_t_s) == events[:-1]
    with pytest.raises(AssertionError):  # an inactive without a clock that ran on
        assert_same_events_as_sent(events, desk, t_end)


def test_a_fault_on_before_an_outage_is_the_same_episode_after_it(tmp_path) -> None:
    # The daemon gives `monitor detect`'s events for a log with the same gap (above), so the
    # desk shows what an outage during an alarm does: inactive over the gap, then, the gap
    # being shorter than alarm.episode_gap_samples, the same alarm episode at once (same
    # isolation, no new debounce, no second black box).
    cfg = load_config()
    model = load_model(cfg.model)
    plain = detect(model, recording_from_candump(LOG), cfg.alarm, cfg.horizon)
    on_s = next(e["t"] for e in plain.events if e["state"] == "fault")
    # The gap opens 2 s into the alarm.  HYD_OilTemp (1 s cycle, 3 s stale) last came up to
    # 1 s before it: after 5 s of silence it is fresh again only by the outage rule
    # (sampler.OUTAGE_S), so the return is to fault directly, not through a stale sensor.
    cut_s, gap_s = on_s + 2.0, 5.0
    path = tmp_path / "gap_in_alarm.log"
    with path.open("w") as fh:
        t0 = None
        for m in read_candump(LOG):
            t0 = m.timestamp if t0 is None else t0
            shift = gap_s if m.timestamp - t0 >= cut_s else 0.0
            fh.write(
                format_line(
                    m.timestamp + shift, "can0", m.arbitration_id, m.is_extended_id, bytes(m.data)
                )
            )
    det = detect(model, recording_from_candump(path), cfg.alarm, cfg.horizon)
    states = [(e["state"], e["t"], e["fault"]) for e in det.events]
    assert [s for s, _, _ in states] == ["normal", "fault", "inactive", "fault"], states
    assert states[1][1] == on_s  # the log before the gap is judged as without it
    assert states[1][2] == states[3][2] == "spool_wear"
    # EngineSpeed is missing over the gap (engine off at once); its return is reported once
    # it has held for engine_confirm_s (one frame is not evidence), then fault at once.
    confirm_s = cfg.gating.operating.engine_confirm_s
    assert cut_s + gap_s + confirm_s <= states[3][1] < cut_s + gap_s + confirm_s + 0.05
    assert det.summary["alarm_episodes"] == 1


def test_mon_status_counts_bus_events_wrapping_at_16(outage) -> None:
    """MON_Status.BusEvents: link-down, bus-off and error-passive events since the start,
    mod 16 (the daemon's counts give the number; the frame wraps like the other counters)."""
    d = outage["daemon"]
    rc = d.reader.recovery
    assert rc.bus_down + rc.bus_off + rc.error_passive == 1  # the one outage
    dbc = d.codec.message("MON_Status").dbc_message
    for n in (1, 15, 17):
        msg = d.loops[0].frames.status(State.NORMAL, 0, 0, 0, 0.0, bus_events=n)
        assert dbc.decode(msg.data)["BusEvents"] == n % 16
    before = [m for m in outage["mon"] if m.arbitration_id == dbc.frame_id]
    assert before and dbc.decode(before[0].data)["BusEvents"] == 0  # sent before the outage
