"""The ``sensor_calibration`` effect: one signal reads gain x true + offset, nothing else moves."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.cli import main
from monitor.errors import ConfigError
from monitor.sim.cycles import make_cycle
from monitor.sim.effects import Effect, parse_effect
from monitor.sim.machine import load_machine
from monitor.sim.sensors import dbc_resolutions, quantise
from monitor.sim.simulate import simulate

M = load_machine()
CMDS = make_cycle("boom", 20.0, seed=5)
COLUMNS = (
    "SpoolCmd",
    "PumpDispCmd",
    "EngineSpeed",
    "OilTemp",
    "PP",
    "PA",
    "PB",
    "QP",
    "RodPos",
    "SpoolPos",
    "RodPosTrue",
    "RodVel",
)


@pytest.fixture(scope="module")
def nominal():
    return simulate(CMDS, M, seed=None)


def _others_identical(a, b, signal: str) -> None:
    for name in COLUMNS:
        if name != signal:
            assert np.array_equal(a[name], b[name]), name


def test_pressure_gain_and_offset_scale_that_signal_only(nominal):
    effect = parse_effect("sensor_calibration:signal=PA,gain=1.1,offset=2")
    rec = simulate(CMDS, M, effects=[effect], seed=None)
    _others_identical(nominal, rec, "PA")
    # Noise-free, both readings are the true PA x quantised to the DBC step r: the nominal
    # one within r/2 of x, the miscalibrated one within r/2 of 1.1 x + 2 bar, so the
    # difference from 1.1 x nominal + 2 is at most 1.1 r/2 + r/2 (no clipping: PA < 240 bar).
    r = dbc_resolutions()["PA"][0]
    err = np.abs(rec["PA"] - (1.1 * nominal["PA"] + 2.0))
    assert err.max() <= 1.05 * r + 1e-9
    assert np.ptp(nominal["PA"]) > 50.0  # the cycle exercises the gain


def test_flow_offset_alone_adds_the_offset(nominal):
    # Only the offset given: the gain is 1 (the effect's 1.1 is for neither given).
    rec = simulate(
        CMDS, M, effects=[parse_effect("sensor_calibration:signal=QP,offset=-1.5")], seed=None
    )
    _others_identical(nominal, rec, "QP")
    r = dbc_resolutions()["QP"][0]
    # The flow sensor clips at 0 L/min: a dead-headed pump reads 0, not -1.5.
    expected = np.clip(nominal["QP"] - 1.5, 0.0, 60.0)
    assert np.abs(rec["QP"] - expected).max() <= r + 1e-9
    assert rec["QP"].min() == 0.0


def test_the_default_is_a_gain_of_1_1_and_an_offset_alone_has_gain_1() -> None:
    assert Effect.make("sensor_calibration").params == {"gain": 1.1, "offset": 0.0}
    assert Effect.make("sensor_calibration", offset=3.0).params == {"gain": 1.0, "offset": 3.0}
    assert Effect.make("sensor_calibration", gain=0.9).params == {"gain": 0.9, "offset": 0.0}


def test_rodpos_reading_is_exactly_gain_true_plus_offset_clipped_and_quantised(nominal):
    rec = simulate(
        CMDS,
        M,
        effects=[parse_effect("sensor_calibration:signal=RodPos,gain=1.05,offset=-5")],
        seed=None,
    )
    _others_identical(nominal, rec, "RodPos")
    # The true rod position is in the output (RodPosTrue), so the reading is known exactly:
    # gain x true + offset, clipped to the sensor's 0..500 mm, on the DBC's grid.
    expected = quantise("RodPos", np.clip(1.05 * rec["RodPosTrue"] - 5.0, 0.0, 500.0))
    assert np.array_equal(rec["RodPos"], expected)


def test_with_noise_the_other_signals_keep_their_noise_bit_for_bit():
    plain = simulate(CMDS, M, seed=3)
    rec = simulate(CMDS, M, effects=[parse_effect("sensor_calibration:signal=PB,gain=0.9")], seed=3)
    _others_identical(plain, rec, "PB")
    assert not np.array_equal(plain["PB"], rec["PB"])
    assert rec.meta["effects"]["sensor_calibration"] == {"signal": "PB", "gain": 0.9, "offset": 0.0}


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("sensor_calibration:signal=XP", "not one of PP, PA, PB, QP, RodPos"),
        ("sensor_calibration:signal=QP,gain=2", "outside 0.5..1.5"),
        ("sensor_calibration:signal=QP,offset=12", "outside -10..10 for QP"),
        ("sensor_calibration:signal=PA,offset=-25", "outside -20..20 for PA"),
        ("sensor_calibration:signal=PA,gain=abc", "is not a number"),
        ("sensor_calibration:signal=PA,scale=1", "no parameter 'scale'"),
    ],
)
def test_bad_sensor_calibrations_are_refused_with_one_line(text, words, tmp_path, capsys):
    with pytest.raises(ConfigError, match=words):
        parse_effect(text)
    assert (
        main(["simulate", "--duration", "1", "--effect", text, "--out", str(tmp_path / "x.csv")])
        == 2
    )
    err = capsys.readouterr().err.strip()
    assert words in err and "\n" not in err


def test_help_lists_signal_gain_and_offset_with_units_and_ranges(capsys):
    assert main(["simulate", "--help"]) == 0
    text = capsys.readouterr().out
    for words in (
        "sensor_calibration",
        "signal [name]",
        "PP|PA|PB|QP|RodPos",
        "gain [-]",
        "range 0.5..1.5",
        "offset [signal unit]",
        "L/min (QP; within +-10)",
    ):
        assert words in text
