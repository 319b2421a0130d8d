"""The plausibility rules on a load-sensing machine (``plausibility.pump_system``): what a
pump shared by several sections makes normal (a held load's port above a pump serving a
lighter one, a stalled section with the pump its margin above it) is not a sensor fault
there, and stays one on the single loop with its own compensated pump; a sensor that is
wrong on either machine is still named."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.config.settings import load_config
from monitor.detection.plausibility import COLUMNS, Plausibility, PlausibilityConfig, finding
from monitor.detection.plausibility_config import PumpSystem
from monitor.errors import ConfigError
from monitor.io.recording import Recording
from monitor.resources import resource_path
from monitor.schema.sections import typed

MIN_RPM = load_config().alarm.min_engine_rpm
LS = PlausibilityConfig(pump=PumpSystem("load_sensing", 20.0))
PC = PlausibilityConfig()


def findings(rec: Recording, cfg: PlausibilityConfig) -> dict[tuple, float]:
    """(sensor, check) -> first time (s) of every finding."""
    x = np.column_stack([rec[c] for c in COLUMNS])
    check, sig = Plausibility(cfg, MIN_RPM).series(x)
    out: dict[tuple, float] = {}
    for i in np.flatnonzero(check):
        out.setdefault(finding(int(check[i]), int(sig[i])), round(float(rec.t[i]), 2))
    return out


def steady(n: int, spool: float, pp: float, pa: float, pb: float, qp: float) -> Recording:
    """``n`` samples of one steady state, engine running; the pressures with 0.3 bar rms of
    noise, QP with 0.1 L/min, or exactly 0.00 for ``qp`` 0 (a flow meter without flow)."""
    t = np.arange(n) * 0.01
    noise = np.random.default_rng(7).normal(0.0, 0.3, (4, n))
    cols = dict(SpoolCmd=spool, PumpDispCmd=100.0, EngineSpeed=2200.0, OilTemp=50.0)
    out = {k: np.full(n, float(v)) for k, v in cols.items()}
    out.update(PP=pp + noise[0], PA=pa + noise[1], PB=pb + noise[2])
    out["QP"] = np.round(qp + noise[3] / 3, 2) if qp > 0 else np.zeros(n)
    return Recording(t, out, "steady", {})


def test_a_lowered_load_above_the_pump_is_normal_only_on_load_sensing() -> None:
    # Boom lowering on a shared LS pump: the pump feeds the rod side (B, 15 bar) at its
    # margin (PP 35 bar) while the cap side meters the held load out at 110 bar.  On the
    # compensated single loop the pump sits at its setting far above every port, so a port
    # 75 bar above it for 1 s is an offset: the 100th violating sample, t = 0.99 s.
    rec = steady(300, -50.0, 35.0, 110.0, 15.0, 12.0)
    assert findings(rec, LS) == {}
    assert findings(rec, PC) == {("PA", "pump_below_port"): 0.99}


def test_a_fed_port_above_the_pump_is_still_named_on_load_sensing() -> None:
    # Raising: the pump feeds A; A reading 40 bar above PP cannot be (the pump holds the
    # fed port's load plus its margin), an offset on PA on either machine.
    rec = steady(300, 50.0, 60.0, 100.0, 5.0, 10.0)
    assert findings(rec, LS) == {("PA", "pump_below_port"): 0.99}
    assert findings(rec, PC) == {("PA", "pump_below_port"): 0.99}


def test_a_stalled_section_at_zero_flow_is_not_frozen_on_load_sensing() -> None:
    # The stick on its stop with the lever held: the LS pump stands its 20 bar margin above
    # the stalled port, no flow.  On the compensated loop a 20 bar drop across an open edge
    # means oil flows (it exceeds relation_margin_bar, 10), so 0.00 L/min for 1 s is a hung
    # meter: the 101st identical sample, t = 1.00 s.
    rec = steady(300, 60.0, 170.0, 150.0, 3.0, 0.0)
    assert findings(rec, LS) == {}
    assert findings(rec, PC) == {("QP", "frozen"): 1.0}


def test_zero_flow_across_a_drop_beyond_the_margin_is_frozen_on_load_sensing() -> None:
    # 60 bar across the open edge, 30 above the margin plus relation_margin_bar: oil flows,
    # whatever the pump system, so a flow pinned at zero is a frozen sensor on both.
    rec = steady(300, 60.0, 110.0, 50.0, 3.0, 0.0)
    assert findings(rec, LS) == {("QP", "frozen"): 1.0}
    assert findings(rec, PC) == {("QP", "frozen"): 1.0}


def test_the_pump_system_is_read_from_the_config() -> None:
    assert not load_config().gating.plausibility.pump.load_sensing  # the reference loop
    ex4 = load_config(resource_path("config", "excavator4.yaml")).gating.plausibility.pump
    assert ex4.load_sensing and ex4.ls_margin_bar == 20.0
    with pytest.raises(ConfigError, match="plausibility.pump_system must be"):
        typed(PlausibilityConfig, {"pump_system": "open_centre"}, "plausibility", "x.yaml")
    with pytest.raises(ConfigError, match="pump_system"):
        PumpSystem("open_centre")
