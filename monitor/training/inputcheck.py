"""What `monitor train` checks in its input before it fits anything.

* The envelope: a model judges only samples whose oil temperature lies inside the range it
  was trained on (plus ``validity`` margin); commissioning data all at one oil temperature
  gives a model that calls every log from a colder morning or a hotter afternoon "not
  judged".  An OilTemp span below ``oil_span_min_c`` is warned about, with the span and the
  range that will be judged.  (The commands and the engine speed are left alone: a machine
  often runs one engine speed and one pump setting by design.)
* Fault signatures: data that holds a fault trains a model that calls that fault healthy.
  Each recording is run through a reference model of the same machine type (the one the
  config names, or ``--reference``) exactly as ``monitor detect`` would; a recording on
  which it raises an alarm isolated as a known fault (``piston_wear``, ``spool_stroke``,
  ``spool_wear``) is named with that fault and the evidence.  A healthy machine that differs
  from the reference's looks like a fault to it too (the shipped model named spool_stroke on
  2 of 4 simulated machines +-5 % from the reference and 3 of 4 at +-15 %), so by default
  the recording is named and trained on (``--fault-check warn``); ``refuse`` stops with exit
  2 before any fitting, for a reference of this very machine.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor.detection.alarm import AlarmConfig
from monitor.detection.gating import GatingConfig
from monitor.detection.offline import detect
from monitor.errors import MonitorError
from monitor.io.recording import Recording
from monitor.model.modelfile import MonitorModel
from monitor.signals import FAULT_NAMES


class SuspectRecordingError(MonitorError, ValueError):
    """Training data the reference model calls faulty (exit 2)."""


@dataclass(frozen=True)
class InputCheckConfig:
    """Limits of the training-input checks."""

    # A day's work moves the oil by tens of degC (the warm-up line to working heat).
    oil_span_min_c: float = 10.0  # OilTemp span below this: warned (logs outside not judged)


@dataclass(frozen=True)
class Suspect:
    """A recording the reference model calls faulty."""

    path: Path
    fault: str
    first_alarm_t: float
    max_level: float
    reference: str

    def message(self) -> str:
        return (
            f"{self.path} looks like {self.fault} (the reference model {self.reference} "
            f"raises {self.fault} from {self.first_alarm_t:.1f} s, max level "
            f"{self.max_level:.3g}; 1 = alarm): a model trained on it would call that "
            "fault healthy"
        )


def envelope_warnings(
    recordings: Sequence[Recording], gating: GatingConfig, cfg: InputCheckConfig | None = None
) -> list[str]:
    """One line per operating signal whose trained range is narrower than the data the
    model will be asked to judge (module docstring); empty when it is wide enough."""
    cfg = cfg or InputCheckConfig()
    oil = [r["OilTemp"] for r in recordings if r.has("OilTemp")]
    values = np.concatenate(oil) if oil else np.empty(0)
    values = values[np.isfinite(values)]
    # Only warm samples are trained on and judged: the warm-up below the line is gated.
    values = values[values >= gating.operating.warmup_oil_c]
    if values.size == 0:
        return []
    lo, hi = float(values.min()), float(values.max())
    if hi - lo >= cfg.oil_span_min_c:
        return []
    validity = gating.validity
    margin = max(validity.margin_fraction * (hi - lo), validity.margin_c)
    return [
        f"OilTemp spans {lo:.1f}-{hi:.1f} degC only; logs outside {lo - margin:.1f}-"
        f"{hi + margin:.1f} degC (the trained range and its margin) will be not judged: "
        f"train on data across the oil temperatures the machine works at (at least "
        f"{cfg.oil_span_min_c:g} degC apart)"
    ]


def fault_suspects(
    recordings: Sequence[Recording],
    paths: Sequence[Path],
    reference: MonitorModel,
    reference_name: str,
    alarm: AlarmConfig,
    horizon: int | None,
    gating: GatingConfig,
) -> list[Suspect]:
    """The recordings on which ``reference`` raises an alarm isolated as a known fault,
    judged as ``monitor detect`` judges them (the same alarm, horizon and gating)."""
    out = []
    for rec, path in zip(recordings, paths, strict=True):
        s = detect(reference, rec, alarm, horizon, gating=gating).summary
        if s["alarm"] and s["fault"] in FAULT_NAMES:
            out.append(
                Suspect(
                    Path(path),
                    s["fault"],
                    float(s["first_alarm_t"]),
                    float(s["max_level"]),
                    reference_name,
                )
            )
    return out
