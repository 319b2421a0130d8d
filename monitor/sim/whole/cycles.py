"""Seeded duty cycles of the whole machine at 100 Hz, as an operator runs them.

``truck-loading``: dig (stick in and bucket curl against the soil, the bucket filling),
lift and swing 90-180 deg to the truck with the boom rising, dump (stick out, bucket open),
swing back with the boom lowering, a pause.  ``lifting``: idling, then a load hung on the
bucket raised slowly, held for a long time, swung 30-90 deg, held, lowered.  ``mixed``:
blocks of both.  Operator variability: every move's lever amplitude, the overlap of the
functions (each starts with a random delay after the last), pauses, swing angles.

``dig-lift`` (``TRAINING_CYCLES``, for training data, not an operator's cycle of its own):
truck loading whose lift starts anywhere from 1.5 s before the stick's dig move ends to 0.3 s
after it, so the boom's ramp meets the stick still curling in, the stick's spool closing and
the stick settled, at every phase.  In ``truck-loading`` the lift starts within 0.3 s of the
dig's end, and a lift ramp meeting a stick still open at 60-100 % comes about 2.5 times an
hour of mixed work for 0.1-0.2 s: too rarely for a kernel model to learn it, often enough
for one that has not to alarm (docs/benchmarks.md, the stick's bias statistic).

``return-to-stop`` (``TRAINING_CYCLES``): truck loading whose return sets the boom down onto
its bottom stop, feathered at 8-25 % over the last few percent of its stroke, the rod
estimated to land 1.5 s before to 0.5 s after the swing back ends and the lever held 0.5 s
less to 1.5 s more than that; a lift with long holds after one load in three.  A boom
stalled on its stop puts its pressure on the load-sense line, and a swing braking then has
its meter-in starved as its spool closes: the motor traps 72-76 bar (mixed work: 55-68 bar,
71.5 at most in the 100 minutes the models were fitted on), and at rest the swing model must
predict that held.  The swing model trained without this cycle predicted the trapped
pressures drifting apart there, 0.3 bar a step, and B alarmed on a normal run
(docs/benchmarks.md, the swing's bias statistic).

The operator aims at rod positions by eye: each move's length comes from a rough speed
(rated section flow x lever over the fed area, no flow sharing), so positions drift and now
and then reach a stop, as in real work.  Returns a ``Recording`` with every loop's spool
command (the DBC's names), EngineSpeed, OilTemp, and the loads the kernel needs:
``DigForce`` (N at the bucket tip) and ``Payload`` (kg in the bucket), never written out.
"""

from __future__ import annotations

import math

import numpy as np

from monitor.errors import ConfigError
from monitor.io.recording import Recording
from monitor.sim.cycles import RATE_LIMIT_PCT_S, _oil_temp, _time_axis, rate_limit
from monitor.sim.whole.params import CYLINDERS, WholeMachine
from monitor.sim.whole.swingstop import swing_stops

WHOLE_CYCLES = ("mixed", "truck-loading", "lifting")
#: Cycles for training data only; kept apart from WHOLE_CYCLES, which fleets draw from.
TRAINING_CYCLES = ("dig-lift", "return-to-stop", "rest-on-stop", "swing-stop")
#: Where the lift starts in ``dig-lift``, s after the stick's dig move ends.
DIG_LIFT_OFFSET_S = (-1.5, 0.3)
#: ``return-to-stop``: when the boom's rod is estimated to land on its bottom stop, s after
#: the swing back ends, and how long the lever stays open after that (negative: released
#: before; the estimate is rough, so the rod lands anywhere around it).
STOP_LANDING_S = (-1.5, 0.5)
STOP_HOLD_S = (-0.5, 1.5)
#: ``rest-on-stop``: how long the lever stays open beyond the estimated landing before
#: ``monitor.sim.whole.landing`` lets it go where the simulated rod lands.
REST_HOLD_S = 1.5
SPOOL_SIGNALS = {
    "boom": "SpoolCmd",
    "stick": "Stick_SpoolCmd",
    "bucket": "Bucket_SpoolCmd",
    "swing": "Swing_SpoolCmd",
}
LOAD_COLUMNS = ("DigForce", "Payload")


class _Operator:
    """Lays out lever moves on a timeline and keeps the estimated pose."""

    def __init__(self, machine: WholeMachine, rng: np.random.Generator, n: int, dt: float):
        self.m = machine
        self.rng = rng
        self.dt = dt
        self.n = n
        self.t = 1.0
        self.spool = {loop: np.zeros(n) for loop in SPOOL_SIGNALS}
        self.dig = np.zeros(n)
        self.payload = np.zeros(n)
        self.pos = {loop: 0.3 * machine.stroke_m(loop) for loop in CYLINDERS}
        self.load_kg = 0.0

    def _span(self, start: float, dur: float) -> slice:
        return slice(min(int(start / self.dt), self.n), min(int((start + dur) / self.dt), self.n))

    def move(self, loop: str, start: float, target_frac: float, amp: float) -> float:
        """Move a cylinder toward ``target_frac`` of its stroke; return the move's end."""
        stroke = self.m.stroke_m(loop)
        target = float(np.clip(target_frac, 0.0, 1.05)) * stroke
        delta = target - self.pos[loop]
        area = self.m.area_a_m2(loop) if delta > 0 else self.m.area_b_m2(loop)
        speed = amp / 100.0 * self.m.rated_flow_m3_s(loop) / area
        dur = float(np.clip(abs(delta) / speed, 0.4, 6.0))
        self.spool[loop][self._span(start, dur)] = math.copysign(amp, delta)
        self.pos[loop] = float(
            np.clip(self.pos[loop] + math.copysign(speed * dur, delta), 0, stroke)
        )
        return start + dur

    def swing(self, start: float, angle_rad: float, amp: float) -> float:
        omega = amp / 100.0 * self.m.rated_flow_m3_s("swing") / self.m.swing_disp_m3_rad
        dur = abs(angle_rad) / omega + 0.3  # the house's run-up
        self.spool["swing"][self._span(start, dur)] = math.copysign(amp, angle_rad)
        return start + dur

    def land(self, loop: str, earliest: float, land_at: float, amp: float, hold_s: float) -> float:
        """Lower a cylinder onto its bottom stop as an operator sets it down: at ``amp`` to
        a few percent of its stroke above, then feathered at 8-25 % so the rod is estimated
        to land at ``land_at`` (starting no earlier than ``earliest``), the lever held
        ``hold_s`` beyond; return the lever's release.  Feathered, the pump rises to the
        stall on the stop over a tenth to half a second, not at once."""
        r = self.rng
        rate = self.m.rated_flow_m3_s(loop) / self.m.area_b_m2(loop)  # m/s at a full lever
        feather_pct = r.uniform(8.0, 25.0)
        near = min(self.pos[loop], r.uniform(0.02, 0.1) * self.m.stroke_m(loop))
        feather_s = near / (feather_pct / 100.0 * rate)
        fast_s = (self.pos[loop] - near) / (amp / 100.0 * rate)
        start = max(earliest, land_at - feather_s - fast_s)
        self.spool[loop][self._span(start, fast_s)] = -amp
        end = max(start + fast_s + 0.4, start + fast_s + feather_s + hold_s)
        self.spool[loop][self._span(start + fast_s, end - start - fast_s)] = -feather_pct
        self.pos[loop] = 0.0
        return end

    def set_payload(self, start: float, dur: float, kg: float) -> None:
        span = self._span(start, dur)
        k = span.stop - span.start
        if k > 0:
            self.payload[span] = np.linspace(self.load_kg, kg, k)
        self.payload[span.stop :] = kg
        self.load_kg = kg

    def lag(self) -> float:
        return float(self.rng.uniform(0.0, 0.8))

    def truck_loading(
        self,
        lift_after_stick_s: tuple[float, float] | None = None,
        to_stop: bool = False,
        onto_stop: bool = False,
    ) -> None:
        """One truck load; ``lift_after_stick_s`` starts the lift that long after the stick's
        dig move ends (drawn in the range) instead of within 0.3 s of the whole dig's end;
        ``to_stop`` lowers the boom onto its bottom stop on the return (``STOP_LANDING_S``,
        ``STOP_HOLD_S``) instead of to 10-30 % of its stroke, feathered; ``onto_stop`` at
        the return's 40-90 % (``lower_onto_stop``)."""
        r = self.rng
        t = self.t
        # Dig: stick in and bucket curl against the soil while the bucket fills.
        t_s = t + self.lag()
        end_s = self.move("stick", t_s, r.uniform(0.6, 0.85), r.uniform(50, 100))
        end_k = self.move("bucket", t + self.lag(), r.uniform(0.7, 0.95), r.uniform(40, 90))
        dig_end = max(end_s, end_k)
        self.dig[self._span(t_s, dig_end - t_s)] = r.uniform(1500.0, 4500.0)
        self.set_payload(t_s, dig_end - t_s, r.uniform(45.0, 75.0))
        # Lift and swing to the truck, overlapping.
        if lift_after_stick_s is None:
            t = dig_end + r.uniform(-0.3, 0.3)
        else:
            t = end_s + r.uniform(*lift_after_stick_s)
        end_b = self.move("boom", t, r.uniform(0.6, 0.9), r.uniform(60, 100))
        angle = math.radians(r.uniform(90.0, 180.0)) * (1 if r.random() < 0.5 else -1)
        end_w = self.swing(t + r.uniform(0.2, 1.2), angle, r.uniform(60, 100))
        # Dump: stick out, bucket open, the load leaving.
        t = max(end_b, end_w) + r.uniform(0.0, 0.6)
        end_s = self.move("stick", t + self.lag(), r.uniform(0.2, 0.4), r.uniform(50, 100))
        end_k = self.move("bucket", t, r.uniform(0.05, 0.2), r.uniform(60, 100))
        self.set_payload(t, end_k - t, 0.0)
        # Return: swing back with the boom lowering.
        t = max(end_s, end_k) + r.uniform(0.0, 0.5)
        end_w = self.swing(t, -angle, r.uniform(60, 100))
        if to_stop:
            land_at = end_w + r.uniform(*STOP_LANDING_S)
            end_b = self.land("boom", t, land_at, r.uniform(40, 90), r.uniform(*STOP_HOLD_S))
        elif onto_stop:
            end_b = self.lower_onto_stop(t + self.lag(), r.uniform(40, 90))
        else:
            end_b = self.move("boom", t + self.lag(), r.uniform(0.1, 0.3), r.uniform(40, 90))
        self.t = max(end_w, end_b) + r.uniform(0.3, 3.0)

    def lower_onto_stop(self, start: float, amp: float) -> float:
        """Lower ``boom`` at ``amp`` towards its bottom stop, the lever held ``REST_HOLD_S``
        beyond the estimated landing; return the lever's release."""
        end = self.move("boom", start, 0.0, amp)
        self.spool["boom"][self._span(end, REST_HOLD_S)] = -amp
        return end + REST_HOLD_S

    def rest_on_stop(self) -> None:
        """One truck load whose return lowers the boom onto its stop, the next dig to run
        with it resting there; after one in three, a lift with long holds."""
        self.truck_loading(onto_stop=True)
        if self.rng.random() < 1 / 3:
            self.lifting()

    def lifting(self) -> None:
        r = self.rng
        t = self.t + r.uniform(5.0, 30.0)  # idling
        self.set_payload(t, 2.0, r.uniform(100.0, 300.0))  # a load hung on the bucket
        t = self.move("boom", t + 2.5, r.uniform(0.5, 0.8), r.uniform(25, 50))
        t += r.uniform(10.0, 60.0)  # hold
        t = self.swing(
            t, math.radians(r.uniform(30.0, 90.0)) * r.choice([-1, 1]), r.uniform(30, 50)
        )
        t += r.uniform(5.0, 30.0)  # hold
        t = self.move("boom", t, r.uniform(0.2, 0.4), r.uniform(20, 40))
        self.set_payload(t + 1.0, 2.0, 0.0)
        self.t = t + 3.5 + r.uniform(2.0, 20.0)


def make_whole_cycle(cycle: str, duration_s: float, seed: int, machine: WholeMachine) -> Recording:
    """Commands and loads of ``cycle`` over ``duration_s`` seconds."""
    if cycle not in WHOLE_CYCLES + TRAINING_CYCLES:
        known = ", ".join(WHOLE_CYCLES + TRAINING_CYCLES)
        raise ConfigError(f"unknown cycle {cycle!r} of the whole machine; known: {known}")
    t = _time_axis(duration_s)
    dt = float(t[1] - t[0])
    rng = np.random.default_rng(seed)
    op = _Operator(machine, rng, len(t), dt)
    while op.t < duration_s:
        if cycle == "truck-loading":
            op.truck_loading()
        elif cycle == "lifting":
            op.lifting()
        elif cycle == "dig-lift":
            op.truck_loading(lift_after_stick_s=DIG_LIFT_OFFSET_S)
        elif cycle == "rest-on-stop":
            op.rest_on_stop()
        elif cycle == "swing-stop":
            swing_stops(op)
        elif cycle == "return-to-stop":
            op.truck_loading(to_stop=True)
            if rng.random() < 1 / 3:
                op.lifting()
        else:  # mixed: a few truck loads, now and then a lift
            for _ in range(int(rng.integers(2, 8))):
                op.truck_loading()
            if rng.random() < 0.5:
                op.lifting()
    cols = {SPOOL_SIGNALS[loop]: rate_limit(op.spool[loop], RATE_LIMIT_PCT_S) for loop in op.spool}
    cols["EngineSpeed"] = np.full_like(t, machine["pump"]["engine_rpm"])
    cols["OilTemp"] = _oil_temp(t, rng)
    cols["DigForce"] = op.dig
    cols["Payload"] = op.payload
    return Recording(t, cols, source=f"excavator4 {cycle} cycle, seed {seed}")
