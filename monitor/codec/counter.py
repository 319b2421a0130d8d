"""The alive-counter rule: which frames of one message are believed, by their counter alone.

Byte 6's low nibble counts the frames of a message (+1 mod 16).  A frame whose counter is
the last believed one + 1 is in sequence; + 2 means one frame was lost on the way, which a
bus does, and is believed too.  Any other counter (a jump over two or more frames, a
repeat) is not believed: it is a frame out of sequence, as a forged one is (about one
random frame in 256 passes CRC-8, and then its counter is random).  The message is believed
again only after ``RESYNC_FRAMES`` frames in a row in sequence with each other, the last of
them the first believed; a frame in sequence with the last believed one meanwhile is
believed at once (an intruder's frame between two of the sender's changes nothing).

One exception, so that no intruder's value outlives the sender's next frame: a frame whose
counter repeats the last believed one, or is one behind it, while in sequence with the
believed frame before that (+ 1 or + 2), is believed (``DISPLACED``).  It is the sender's
frame after an intruder's that took its number: which of two frames with one counter is
the sender's no receiver can tell, and believing the later one bounds what the other
changes to less than one cycle.  Refusing it instead kept a forged 0 degC HYD_OilTemp
frame for two seconds, long enough to be confirmed as a cold machine.  A repeat of a
frame whose predecessor was not believed (the first frame, or one after a resync) is not
believed.

``RESYNC_FRAMES`` is 3, from the cycle times: the sampler calls a signal stale when its last
value is older than 3 of its message's cycle times (``GenMsgCycleTime``: 10 ms for the
hydraulic messages, 1 s for HYD_OilTemp), and a sender that restarts its counter (no frame
lost) is then blind for the 2 frames before the third: a gap of 3 cycles, which is not
stale, for every message whatever its cycle time.  A larger N would turn every counter
restart into a sensor fault; N = 2 would let two random frames that pass CRC-8 with
consecutive counters (1 in 16 once two passed) take a message over.  With 3, a random
take-over needs three frames that pass CRC-8 (1 in 256 each) with consecutive counters
(1 in 256 for the last two), all between two frames of the sender: for a 10 ms message
practically never (a saturated bus fits about 20 frames between two of the sender's, 0.07
of them passing CRC-8), for HYD_OilTemp, whose sender is silent for a second, about once a
minute on a bus saturated with random frames on its ID (about 7 a second pass CRC-8).
What no counter rule can refuse is a random frame whose counter happens to be the next
one or the one after (2 in 16 of those passing CRC-8): to a receiver it is the sender's.
The slow signals' plausibility (``monitor.detection.evidence``) is what guards them.

The very first frame of a message is believed: a start mid-operation has nothing to compare
it with.

``counter_step`` is the rule for one frame (the live decoder, ``monitor.codec.frames``, calls
it per frame); ``counter_verdicts`` applies it to every frame of one message of a log (the
bulk decoder, ``monitor.codec.bulk``), stepping only where a counter is not the previous
one + 1, so a healthy hour costs a few numpy operations.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from monitor.codec.layout import COUNTER_MODULO

#: Frames in sequence with each other a message needs to be believed again after a frame out
#: of sequence (the last of them is the first believed); why 3: the module docstring.
RESYNC_FRAMES = 3

# Verdicts of ``counter_step`` (int8 in ``counter_verdicts``).
IN_SEQUENCE = 0  # the last believed + 1 (or the message's first frame): believed
LOST_ONE = 1  # the last believed + 2: one frame lost, believed
RESYNCED = 2  # the RESYNC_FRAMES-th frame of a run in sequence: believed again
DISPLACED = 3  # the last believed one's number, or one behind, after the one before: believed
OUT_OF_SEQUENCE = 4  # a larger jump, a repeat or a run still too short: not believed
BELIEVED = (IN_SEQUENCE, LOST_ONE, RESYNCED, DISPLACED)


class CounterState(NamedTuple):
    """One message's counter state: the last believed counter (-1: no frame yet), the
    believed counter before it (-1: none), the last counter not believed (-1: none since
    the last believed) and how many frames in sequence end with it."""

    last: int = -1
    before: int = -1
    candidate: int = -1
    run: int = 0

    @property
    def previous(self) -> int:
        """The counter of the latest frame seen (believed or not); -1 before the first."""
        return self.candidate if self.candidate >= 0 else self.last


def counter_step(state: CounterState, counter: int) -> tuple[int, CounterState]:
    """The verdict on a frame with alive counter ``counter`` (0-15) and the message's new
    state (module docstring)."""
    last, before, candidate, run = state
    if last < 0:
        return IN_SEQUENCE, CounterState(counter)
    step = (counter - last) % COUNTER_MODULO
    if step == 1:
        return IN_SEQUENCE, CounterState(counter, last)
    if step == 2:
        return LOST_ONE, CounterState(counter, last)
    if (
        step in (0, COUNTER_MODULO - 1)
        and before >= 0
        and (counter - before) % COUNTER_MODULO in (1, 2)
    ):
        return DISPLACED, CounterState(counter, before)
    run = run + 1 if candidate >= 0 and counter == (candidate + 1) % COUNTER_MODULO else 1
    if run >= RESYNC_FRAMES:
        return RESYNCED, CounterState(counter)
    return OUT_OF_SEQUENCE, CounterState(last, before, counter, run)


def is_jump(state: CounterState, counter: int) -> bool:
    """Whether ``counter`` breaks the sequence of the frames seen (not the latest + 1): what
    the ``counter_jumps`` count counts, believed or not."""
    prev = state.previous
    return prev >= 0 and counter != (prev + 1) % COUNTER_MODULO


def counter_verdicts(counters: np.ndarray) -> np.ndarray:
    """``counter_step``'s verdict (int8) on each of one message's frames in order, from a
    fresh state; the same values as stepping frame by frame."""
    c = np.asarray(counters, dtype=np.int64)
    n = c.size
    out = np.full(n, IN_SEQUENCE, dtype=np.int8)
    # Frames that are not the previous one + 1: only there (and after a frame not believed)
    # does the state do anything but follow the counter.
    breaks = np.flatnonzero(c[1:] != (c[:-1] + 1) % COUNTER_MODULO) + 1
    state = CounterState()
    i = 0
    for b in (0, *breaks.tolist()):
        if b < i:  # already stepped over
            continue
        if b > i:  # frames i..b-1 each the previous + 1 after a believed one
            state = CounterState(int(c[b - 1]), int(c[b - 2]))
        i = b
        while i < n:
            verdict, state = counter_step(state, int(c[i]))
            out[i] = verdict
            i += 1
            if verdict != OUT_OF_SEQUENCE:
                break
    return out
