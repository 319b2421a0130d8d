"""Faults of the whole machine, per loop: ``LOOP.FAULT:SEV[@ONSET_S[+RAMP_S]]``.

- boom, stick, bucket: ``piston_wear``, ``spool_stroke``, ``spool_wear`` exactly as the
  boom loop's (monitor/sim/faults.py: the same severities, onsets and physical inputs).
- swing: ``spool_stroke`` and ``spool_wear`` of its section, and ``motor_leakage``: extra
  internal leakage A<->B of the swing motor, ``MOTOR_LEAK_MAX_M3_S_PA`` x severity.
- pump: ``pump_wear``, volumetric leakage of the one pump that feeds every loop,
  ``PUMP_LEAK_MAX_M3_S_PA`` x severity x PP.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.errors import ConfigError
from monitor.signals import FAULT_NAMES
from monitor.sim.faults import Fault, fault_inputs, fault_parts
from monitor.sim.whole import kernel as K

#: 7 L/min at 100 bar (half the swing section's full flow): a worn motor that drifts.
MOTOR_LEAK_MAX_M3_S_PA = 7e-12
#: 10 L/min at 200 bar, a quarter of the pump's 40 L/min.
PUMP_LEAK_MAX_M3_S_PA = 8.3e-12
LOOP_FAULTS: dict[str, tuple[str, ...]] = {
    "boom": FAULT_NAMES,
    "stick": FAULT_NAMES,
    "bucket": FAULT_NAMES,
    "swing": ("spool_stroke", "spool_wear", "motor_leakage"),
    "pump": ("pump_wear",),
}
_OWN = ("motor_leakage", "pump_wear")


@dataclass(frozen=True)
class MachineFault(Fault):
    """A fault of one loop of the whole machine (``loop`` one of ``LOOP_FAULTS``)."""

    loop: str = "boom"

    def __post_init__(self) -> None:
        if self.loop not in LOOP_FAULTS:
            raise ConfigError(f"unknown loop {self.loop!r}; known: {', '.join(LOOP_FAULTS)}")
        if self.name not in LOOP_FAULTS[self.loop]:
            raise ConfigError(
                f"fault {self.name!r} is not one of the {self.loop} loop's: "
                f"{', '.join(LOOP_FAULTS[self.loop])}"
            )
        if self.name not in _OWN:
            super().__post_init__()  # the boom loop's checks
        elif not 0.0 <= self.severity <= 1.0:
            raise ConfigError(f"fault {self.name}: severity {self.severity:g} is outside 0..1")
        elif self.onset_s < 0 or self.ramp_s < 0:
            raise ConfigError(f"fault {self.name}: onset and ramp must be >= 0 s")

    @property
    def label(self) -> str:
        return f"{self.loop}.{self.name}"


def parse_machine_fault(text: str) -> MachineFault:
    """Parse ``LOOP.FAULT:SEV[@ONSET_S[+RAMP_S]]``."""
    form = "LOOP.FAULT:SEV[@ONSET_S[+RAMP_S]]"
    loop, dot, rest = text.strip().partition(".")
    if not dot:
        raise ConfigError(f"--fault {text!r}: expected {form}")
    return MachineFault(*fault_parts(rest, text, form), loop=loop)


def fill_fault_inputs(faults: list[MachineFault], t_s: np.ndarray, u: np.ndarray) -> None:
    """Write every loop's fault inputs (leak, stroke limit, underlap) and the pump's leak."""
    for j, loop in enumerate(K.LOOPS):
        mine = [f for f in faults if f.loop == loop]
        base = [Fault(f.name, f.severity, f.onset_s, f.ramp_s) for f in mine if f.name not in _OWN]
        f = fault_inputs(base, t_s)
        b = K.IN0 + K.NI * j
        u[:, b + K.I_STROKE_LIM] = f["stroke_limit"]
        u[:, b + K.I_UNDERLAP] = f["underlap"]
        leak = f["piston_leak_m3_s_pa"]
        for fault in mine:
            if fault.name == "motor_leakage":
                leak = np.maximum(leak, MOTOR_LEAK_MAX_M3_S_PA * fault.severity_at(t_s))
        u[:, b + K.I_LEAK] = leak
    pump = np.zeros(len(t_s))
    for fault in faults:
        if fault.name == "pump_wear":
            pump = np.maximum(pump, PUMP_LEAK_MAX_M3_S_PA * fault.severity_at(t_s))
    u[:, K.IN_PUMP_LEAK] = pump
