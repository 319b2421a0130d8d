"""`monitor fleet run` commissions by `monitor train`'s support rule: a machine whose
commissioning folder holds enough sessions gets the bias statistic, and the fleet's record
says so."""

from __future__ import annotations

import json
import shutil
import subprocess

import pytest

from monitor.fleet.simulate import FleetPlan, simulate_fleet
from monitor.model.modelfile import load_model
from monitor.model.threshold import MIN_BLOCKS
from monitor.training.support import MIN_SESSIONS
from tests.fleet_support import env, fleet_cmd, rows

# One healthy machine (no wear): a 4-minute commissioning run warming 30-60 degC and three
# 4-minute days at their own oil temperatures, each a session of its own.
PLAN = FleetPlan(machines=1, days=3, seed=5, log_s=240.0, commissioning_s=240.0, wear_max=0.0)


@pytest.fixture(scope="module")
def commissioned(tmp_path_factory):
    """The machine commissioned on its run and its three days (4 sessions, 16 min: 16
    blocks of 60 s, enough for 4 cross-fitted folds), its third day judged."""
    where = tmp_path_factory.mktemp("support")
    fleet = where / "fleet"
    simulate_fleet(fleet, PLAN, say=lambda _m: None)
    m = fleet / "M01"
    for day in ("day01.log", "day02.log", "day03.log"):
        shutil.copy(m / "logs" / day, m / "commissioning" / day)
    (m / "logs" / "day01.log").unlink()
    (m / "logs" / "day02.log").unlink()
    out = where / "results"
    proc = subprocess.run(
        fleet_cmd(str(fleet), "--out", str(out), "--workers", "1"),
        capture_output=True,
        text=True,
        env=env(),
    )
    assert proc.returncode == 0, proc.stderr
    return out


def test_enough_sessions_in_commissioning_earn_b_and_the_fleets_record_says_on(commissioned):
    out = commissioned
    record = json.loads((out / "models" / "M01.trained-from.json").read_text())
    model = load_model(out / "models" / "M01.model.npz")
    support = model.training["support"]["B"]
    # What the rule rests on, against its stated numbers: enough independent windows of
    # B's 60 s, held out over at least 2 sessions (all 4 commissioning recordings are
    # cross-fitted), and a threshold that holds from one half to the other where the
    # halves are long enough to tell.
    assert support["window_s"] == 60.0
    assert support["independent_windows"] >= MIN_BLOCKS, support
    assert support["parts"] == 4 >= MIN_SESSIONS, support
    moved = support["transfer"]
    assert not moved["checked"] or moved["ratio"] <= 1.0, moved
    assert record["statistics"]["B"] == "on", record["statistics"]
    assert model.bias is not None
    # The log is judged with B: its column has a value (it is null without B).
    (row,) = rows(out)
    assert row["max_b_ratio"] is not None, row
