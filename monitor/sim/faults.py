"""Faults of the boom loop with a severity 0..1, abrupt or ramped.

As docs/reference/contracts.md defines them:

- ``piston_wear``: internal leakage C_il (PA - PB), C_il = s * 5e-12 m^3/(s Pa).
- ``spool_stroke``: the spool opening is limited to (1 - 0.6 s) of full stroke.
- ``spool_wear``: worn metering edges leak across every land like an opening of 0.1 s
  (an underlap, largest at and near centre).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from monitor.errors import ConfigError
from monitor.signals import FAULT_NAMES

PISTON_LEAK_MAX_M3_S_PA = 5e-12
STROKE_LOSS_AT_FULL = 0.6
WEAR_UNDERLAP_AT_FULL = 0.1

_SPEC = re.compile(r"^(?P<name>[a-z_]+):(?P<sev>[^@]+)(?:@(?P<onset>[^+]+)(?:\+(?P<ramp>.+))?)?$")


@dataclass(frozen=True)
class Fault:
    """A fault reaching ``severity`` from ``onset_s``, linearly over ``ramp_s`` (0: abrupt)."""

    name: str
    severity: float
    onset_s: float = 0.0
    ramp_s: float = 0.0

    def __post_init__(self) -> None:
        if self.name not in FAULT_NAMES:
            raise ConfigError(f"unknown fault {self.name!r}; known: {', '.join(FAULT_NAMES)}")
        if not 0.0 <= self.severity <= 1.0:
            raise ConfigError(f"fault {self.name}: severity {self.severity:g} is outside 0..1")
        if self.onset_s < 0 or self.ramp_s < 0:
            raise ConfigError(f"fault {self.name}: onset and ramp must be >= 0 s")

    def severity_at(self, t_s: np.ndarray) -> np.ndarray:
        t = np.asarray(t_s, dtype=np.float64)
        if self.ramp_s > 0:
            frac = np.clip((t - self.onset_s) / self.ramp_s, 0.0, 1.0)
        else:
            frac = (t >= self.onset_s).astype(np.float64)
        return self.severity * frac


def parse_fault(text: str) -> Fault:
    """Parse the CLI form ``NAME:SEV[@ONSET_S[+RAMP_S]]``."""
    return Fault(*fault_parts(text.strip(), text, "NAME:SEV[@ONSET_S[+RAMP_S]]"))


def fault_parts(spec: str, text: str, form: str) -> tuple[str, float, float, float]:
    """Name, severity, onset (s) and ramp (s) of ``spec``, the ``NAME:SEV[@ONSET_S[+RAMP_S]]``
    part of the option ``text`` (which the message quotes, with the expected ``form``)."""
    m = _SPEC.match(spec)
    if not m:
        raise ConfigError(f"--fault {text!r}: expected {form}")
    try:
        sev = float(m["sev"])
        onset = float(m["onset"]) if m["onset"] else 0.0
        ramp = float(m["ramp"]) if m["ramp"] else 0.0
    except ValueError:
        raise ConfigError(f"--fault {text!r}: severity, onset and ramp must be numbers") from None
    return m["name"], sev, onset, ramp


def fault_inputs(faults: list[Fault], t_s: np.ndarray) -> dict[str, np.ndarray]:
    """Per-sample physical fault inputs for the kernel: leak, stroke limit, underlap."""
    sev = {name: np.zeros_like(np.asarray(t_s, dtype=np.float64)) for name in FAULT_NAMES}
    for fault in faults:
        sev[fault.name] = np.maximum(sev[fault.name], fault.severity_at(t_s))
    return {
        "piston_leak_m3_s_pa": PISTON_LEAK_MAX_M3_S_PA * sev["piston_wear"],
        "stroke_limit": 1.0 - STROKE_LOSS_AT_FULL * sev["spool_stroke"],
        "underlap": WEAR_UNDERLAP_AT_FULL * sev["spool_wear"],
    }
