"""``monitor simulate`` as other tools call it: files out, one-line errors, exit codes."""

from __future__ import annotations

import numpy as np
import pytest
from naive_frames import recording_from_candump

from monitor.cli import main
from monitor.io.csvio import read_csv


def test_simulate_csv_has_the_contract_columns_and_rodpos(tmp_path, capsys):
    out = tmp_path / "run.csv"
    assert main(["simulate", "--duration", "5", "--seed", "1", "--out", str(out)]) == 0
    rec = read_csv(out)
    assert len(rec) == 501 and rec.t[-1] == pytest.approx(5.0)
    for name in (
        "SpoolCmd",
        "PumpDispCmd",
        "EngineSpeed",
        "OilTemp",
        "PP",
        "PA",
        "PB",
        "QP",
        "RodPos",
    ):
        assert np.all(np.isfinite(rec[name]))
    assert "wrote 501 rows" in capsys.readouterr().err


def test_simulate_oil_temp_holds_or_warms_the_oil_linearly(tmp_path):
    out = tmp_path / "warm.csv"
    assert main(["simulate", "--duration", "5", "--oil-temp", "25:55", "--out", str(out)]) == 0
    rec = read_csv(out)
    # OilTemp is sampled and held once a second (the sensor's period): 25, 31, ... 55.
    assert rec["OilTemp"][0] == pytest.approx(25.0) and rec["OilTemp"][-1] == pytest.approx(55.0)
    assert np.all(np.diff(rec["OilTemp"]) >= 0)
    assert main(["simulate", "--duration", "2", "--oil-temp", "45", "--out", str(out)]) == 0
    assert np.all(read_csv(out)["OilTemp"] == 45.0)


def test_simulate_log_decodes_back_to_the_same_signals(tmp_path):
    csv, log = tmp_path / "run.csv", tmp_path / "run.log"
    args = [
        "--duration",
        "4",
        "--seed",
        "2",
        "--fault",
        "spool_wear:0.6@1+1",
        "--effect",
        "sensor_lag:delay_ms=20",
    ]
    assert main(["simulate", *args, "--out", str(csv)]) == 0
    assert main(["simulate", *args, "--out", str(log)]) == 0
    a = read_csv(csv)
    b = recording_from_candump(log)
    n = min(len(a), len(b))
    for name in ("PP", "PA", "QP", "SpoolCmd", "RodPos"):
        assert np.allclose(a[name][5:n], b[name][5:n], atol=0.006), name


@pytest.mark.parametrize(
    "args, fragment",
    [
        (["--duration", "-1"], "--duration: must be within 0.01..7200 s, got -1"),
        (["--duration", "5", "--fault", "piston_wear:2"], "outside 0..1"),
        (["--duration", "5", "--fault", "broken_pump:0.5"], "unknown fault 'broken_pump'"),
        (["--duration", "5", "--effect", "magic"], "unknown effect 'magic'"),
        (["--duration", "5", "--effect", "valve_deadband:overlap_pct=80"], "outside 0..30"),
        (["--duration", "5", "--fault", "piston_wear:0.5@10"], "after the end"),
        (["--duration", "5", "--oil-temp", "25:200"], "must be within -20..120 degC, got 200"),
        (["--duration", "5", "--oil-temp", "25:40:55"], "expected C or C:C_END in degC"),
    ],
)
def test_simulate_user_errors_exit_2_with_one_line(tmp_path, capsys, args, fragment):
    assert main(["simulate", *args, "--out", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert fragment in err and "\n" not in err and "Traceback" not in err
    assert not (tmp_path / "x.csv").exists()


def test_simulate_bad_suffix_and_bad_config(tmp_path, capsys):
    assert main(["simulate", "--duration", "1", "--out", str(tmp_path / "x.txt")]) == 2
    bad = tmp_path / "sim.yaml"
    bad.write_text("load:\n  mass_kg: heavy\n")
    assert (
        main(
            ["simulate", "--duration", "1", "--config", str(bad), "--out", str(tmp_path / "x.csv")]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert "load.mass_kg must be a number" in err


def test_simulate_help_lists_faults_effects_and_parameter_units(capsys):
    assert main(["simulate", "--help"]) == 0
    text = capsys.readouterr().out
    for word in (
        "piston_wear",
        "spool_stroke",
        "spool_wear",
        "entrained_air",
        "oil_viscosity",
        "cylinder_friction",
        "spool_dynamics",
        "valve_deadband",
        "pump_control_dynamics",
        "hose_compliance",
        "sensor_lag",
        "load_variation",
        "delay_ms [ms]",
        "natural_freq_hz [Hz]",
        "range 0..100",
    ):
        assert word in text


def test_a_day_of_simulation_is_refused_before_any_work(capsys) -> None:
    """A run is held in memory (6 h peaked at 2.29 GB): --duration beyond 7,200 s is a usage
    error while the command line is parsed (checked on the parser alone, so that the
    previous release, which accepted it, fails here instead of simulating a day)."""
    from monitor.cli import build_parser

    parser = build_parser("simulate")
    with pytest.raises(SystemExit) as exc:
        parser.parse_args(["simulate", "--duration", "86400", "--out", "x.csv"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.endswith(
        "argument --duration: must be within 0.01..7200 s, got 86400 (the run "
        "is held in memory, some 0.3 GB a simulated hour; simulate longer spans "
        "as several runs with other seeds)"
    )
    assert parser.parse_args(["simulate", "--duration", "7200", "--out", "x.csv"]).duration == 7200
