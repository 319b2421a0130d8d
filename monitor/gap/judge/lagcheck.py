"""A ``sensor_lag`` verdict checked against the engine's speed ripple.

A lagged sensor reports late whatever moved the plant; a slow spool (``spool_dynamics``)
delays only what the spool drives.  On the four pressure and flow signals the two look
alike as long as the spool is what moves them: the valve opens late, so the flow and every
pressure follow late, and a delay of the readings does the same (without RodPos nothing
measured is left undelayed to tell them apart; on development and blind seeds the two
removed shares of the held-out gap within 0.04 of each other, 0.39-0.97).

The engine is the one input that reaches the signals without the spool: the pump's flow is
its displacement times the engine speed, so the speed's ripple (a few rpm, sample to
sample) shows at once in QP, and in PP through the pump line's compliance.  A flow or
pressure sensor with a delay or a filter shows that ripple late or smeared out; a slow
spool leaves it where it is.  So before ``sensor_lag`` is named, the response of each of
QP and PP to the sample-to-sample change of EngineSpeed, at lag zero, is measured in the
recording and in two simulations of the same held-out segments: the calibrated simulator
read by undelayed sensors, and the fitted sensor lag.  When the recording's response
sits clearly on the undelayed side (``prompt``), the readings are not late: the gap's
delay lives in the plant (the spool), and ``sensor_lag`` is not named.  When it sits
clearly on the lagged side (``late``), the sensors are late, and ``sensor_lag`` is named if
it explains the gap alone though another verdict was reached (``diagnose._check_lag``).

Both need positive evidence: when EngineSpeed is constant (no ripple) or the fitted lag is
too short to move the response, the check abstains and the verdict stands.  If the
recording's EngineSpeed were a noisy reading of a steady engine, the measured response
would be zero, i.e. on the lagged side: a ``sensor_lag`` verdict stands then too.

Units: EngineSpeed in rpm, QP in L/min, PP in bar; responses in signal units per rpm of
change within one 10 ms sample.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from monitor.gap.data.prepare import Prepared
from monitor.gap.data.segments import Segment

#: The catalogue effect this module checks.
NAME = "sensor_lag"

#: The signals the engine's ripple reaches without the spool: pump flow and pump pressure.
SIGNALS = ("QP", "PP")
#: A signal counts only when the two simulated responses are this many standard errors
#: apart (otherwise it cannot tell them apart and is left out): on the development seeds
#: QP had 5.5-12.4, PP 0.5-2.4 (the ripple moves the pump pressure little).
Z_POWER = 3.0
#: The sensor lag is not named when the recording's response is this many standard errors
#: (pooled over the signals that count) away from the fitted lag's, towards the undelayed
#: one ...  Development seeds 60-62: 5.4-10.7 with a slow spool, -0.6-2.3 with a lagged
#: sensor (the same threshold, from the undelayed response, reads ``late``).
Z_PROMPT = 4.0
#: ... and nearer the undelayed response than the lagged one (``position`` above 1/2).
PROMPT_POSITION = 0.5
#: Fewest sample pairs with a finite change of every quantity involved.
MIN_PAIRS = 500


@dataclass
class Response:
    """Lag-zero response of one signal to the change of EngineSpeed (signal unit per rpm)."""

    signal: str
    measured: float
    undelayed: float  # the calibrated simulator read by undelayed sensors
    lagged: float  # the fitted sensor lag's simulation
    se: float  # standard error of ``measured``
    pairs: int

    @property
    def power(self) -> float:
        """How many standard errors apart the two simulated responses are."""
        return abs(self.undelayed - self.lagged) / max(self.se, 1e-30)

    @property
    def z(self) -> float:
        """Standard errors of ``measured`` away from ``lagged``, towards ``undelayed``."""
        return float(
            np.sign(self.undelayed - self.lagged) * (self.measured - self.lagged) / self.se
        )

    @property
    def position(self) -> float:
        """Where ``measured`` lies: 0 at the lagged response, 1 at the undelayed one."""
        return (self.measured - self.lagged) / (self.undelayed - self.lagged)

    def as_dict(self) -> dict:
        return {
            "signal": self.signal,
            "measured": _sig(self.measured),
            "undelayed": _sig(self.undelayed),
            "lagged": _sig(self.lagged),
            "se": _sig(self.se),
            "position": round(float(self.position), 3) if self.power > 0 else None,
            "pairs": self.pairs,
        }


@dataclass
class LagCheck:
    """How the recording's QP and PP follow the engine's ripple, against the two simulations."""

    responses: list[Response]
    z: float  # pooled, from the lagged response towards the undelayed (nan: no power)
    z_late: float  # pooled, from the undelayed response towards the lagged
    position: float  # pooled: 0 at the fitted lag's response, 1 at the undelayed one

    @property
    def decided(self) -> bool:
        return bool(np.isfinite(self.z))

    @property
    def prompt(self) -> bool:
        """The readings are not late: the sensor lag is ruled out."""
        return self.decided and self.z >= Z_PROMPT and self.position >= PROMPT_POSITION

    @property
    def late(self) -> bool:
        """The readings are as late as the fitted lag: what slows them is the sensors."""
        return self.decided and self.z_late >= Z_PROMPT and self.position < PROMPT_POSITION

    @property
    def sensor_named(self) -> bool:
        """False when the check rules the sensor lag out."""
        return not self.prompt

    def as_dict(self) -> dict:
        return {
            "signals": [r.as_dict() for r in self.responses],
            "readings": "prompt" if self.prompt else "late" if self.late else "undecided",
            "prompt_z": round(float(self.z), 2) if self.decided else None,
            "late_z": round(float(self.z_late), 2) if self.decided else None,
            "position": round(float(self.position), 3) if self.decided else None,
        }


def _sig(x: float) -> float:
    return float(f"{x:.4g}")


def _pairs(prep: Prepared, segments: Sequence[Segment]) -> np.ndarray:
    """Rows ``i`` (with ``i - 1`` in the same segment) whose change from ``i - 1`` is used."""
    rows = [np.arange(seg.score_from + 1, seg.stop + 1) for seg in segments]
    i = np.concatenate(rows) if rows else np.zeros(0, dtype=np.int64)
    ok = prep.valid[i] & prep.valid[i - 1]
    if prep.unscored is not None:
        ok &= ~prep.unscored[i] & ~prep.unscored[i - 1]
    return i[ok]


def response(
    prep: Prepared,
    segments: Sequence[Segment],
    signal: str,
    undelayed: dict[str, np.ndarray],
    lagged: dict[str, np.ndarray],
) -> Response | None:
    """Least-squares slope of each series' one-sample change on EngineSpeed's (lag zero).

    The ripple is close to white from sample to sample and independent of the lever, so
    whatever else moves the signal (the spool's response, noise) only adds to the spread of
    the slope (its standard error allows for one sample of autocorrelation)."""
    i = _pairs(prep, segments)
    x = prep.cmd["EngineSpeed"][i] - prep.cmd["EngineSpeed"][i - 1]
    series = [prep.meas[signal], undelayed[signal], lagged[signal]]
    d = [s[i] - s[i - 1] for s in series]
    ok = np.isfinite(x) & np.all([np.isfinite(v) for v in d], axis=0)
    x = x[ok]
    sxx = float(x @ x)
    if ok.sum() < MIN_PAIRS or sxx <= 0.0:
        return None
    beta = [float(x @ v[ok]) / sxx for v in d]
    # Newey-West with one lag: the change of a white ripple is correlated with its
    # neighbour (-1/2), and so is the change of white sensor noise.
    u = x * (d[0][ok] - beta[0] * x)
    se = float(np.sqrt(max(u @ u + 2.0 * (u[:-1] @ u[1:]), u @ u)) / sxx)
    if se <= 0.0:
        return None
    return Response(signal, beta[0], beta[1], beta[2], se, int(len(x)))


def check(
    prep: Prepared,
    segments: Sequence[Segment],
    undelayed: dict[str, np.ndarray],
    lagged: dict[str, np.ndarray],
) -> LagCheck:
    """Do QP and PP respond to the engine's ripple promptly (``undelayed``) or as late as
    the fitted sensor lag says (``lagged``)?  Both simulations on ``segments``' rows.

    Pooled over the signals whose two simulated responses are ``Z_POWER`` standard errors
    apart: the z values by Stouffer's sum, the position weighted by its inverse variance.
    The readings are ``prompt`` (no sensor lag) when z reaches ``Z_PROMPT`` and the position
    ``PROMPT_POSITION``; ``late`` (a sensor lag) when ``z_late`` reaches ``Z_PROMPT`` and the
    position stays below it."""
    found = [response(prep, segments, s, undelayed, lagged) for s in SIGNALS]
    responses = [r for r in found if r is not None]
    strong = [r for r in responses if r.power >= Z_POWER]
    if not strong:
        return LagCheck(responses, float("nan"), float("nan"), float("nan"))
    z = float(sum(r.z for r in strong) / np.sqrt(len(strong)))
    z_late = float(sum(r.power - r.z for r in strong) / np.sqrt(len(strong)))
    w = np.array([r.power**2 for r in strong])
    position = float(np.array([r.position for r in strong]) @ w / w.sum())
    return LagCheck(responses, z, z_late, position)
