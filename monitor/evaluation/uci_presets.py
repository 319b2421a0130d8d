"""The real-rig evaluation's settings (`monitor eval-uci`): model presets, J windows, z-score
floors and the detection keys of the JSON contract.  Light to import (no kernels), so the
command line can offer them."""

from __future__ import annotations

from monitor.model.spec import DGRNNSpec

CYCLE_TIME = "CycleTime"  # derived signal: seconds since the start of the cycle, 0..59

_RIG_LAGS = (
    ("PS1", (1, 2)),
    ("PS2", (1, 2)),
    ("PS3", (1, 2)),
    ("FS1", (1, 2)),
    ("EPS1", (0, 1)),
    (CYCLE_TIME, (0,)),
)

UCI_PRESETS: dict[str, DGRNNSpec] = {
    "paper": DGRNNSpec(
        outputs=("FS1",),
        exogenous=("PS1", "PS2", "PS3"),
        lags=(("FS1", (1, 2)), ("PS1", (1, 2)), ("PS2", (1, 2)), ("PS3", (1, 2))),
    ),
    "rig": DGRNNSpec(
        outputs=("PS1", "PS2", "PS3", "FS1"),
        exogenous=("EPS1", CYCLE_TIME),
        lags=_RIG_LAGS,
    ),
    "rig_temp": DGRNNSpec(  # rig plus the oil temperature TS1
        outputs=("PS1", "PS2", "PS3", "FS1"),
        exogenous=("EPS1", "TS1", CYCLE_TIME),
        lags=(*_RIG_LAGS[:-1], ("TS1", (0,)), _RIG_LAGS[-1]),
    ),
}

#: J windows tried (N; the window holds N + 1 samples): a load phase of the cycle is ~10 s.
WINDOWS = (9, 19, 29)

#: z-score floors [signal units]: keep a nearly constant signal from blowing up distances.
MIN_STD = {
    "PS1": 0.1,
    "PS2": 0.1,
    "PS3": 0.05,
    "FS1": 0.05,
    "EPS1": 5.0,
    "TS1": 0.1,
    CYCLE_TIME: 1.0,
}

#: Detection keys of the JSON contract: (profile column, value).
DETECTION_KEYS: tuple[tuple[str, int], ...] = (
    ("pump_leak", 1),
    ("pump_leak", 2),
    ("valve", 90),
    ("valve", 80),
    ("valve", 73),
    ("accumulator", 115),
    ("accumulator", 100),
    ("accumulator", 90),
    ("cooler", 20),
    ("cooler", 3),
)
