"""`monitor gap --loop NAME`: one loop's signals read from a recording of several loops, and
the loops the single-loop simulator cannot stand for refused with one line."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from monitor.cli import main
from monitor.codec.frames import FrameCodec
from monitor.codec.logwrite import write_candump
from monitor.config.settings import load_config
from monitor.gap.data.loop import gap_loop, read_gap_loop
from monitor.io.csvio import write_csv
from monitor.offline.recordings import wide_recording
from monitor.resources import resource_path
from monitor.sim.cycles import make_cycle
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate

CONTRACT = ("SpoolCmd", "PumpDispCmd", "EngineSpeed", "OilTemp", "PP", "PA", "PB", "QP", "RodPos")


def _stick_yaml(tmp_path):
    """The reference loop's simulator YAML with a stick's cylinder (60/35/450 mm) and load."""
    data = yaml.safe_load(resource_path("config", "simulator.yaml").read_text())
    data["cylinder"].update(bore_mm=60, rod_mm=35, stroke_mm=450)
    data["load"].update(mass_kg=250, gravity_load_n=3500)
    path = tmp_path / "stick_sim.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _two_loops(tmp_path, pump_system="pressure_compensated"):
    """A config of two loops, boom and stick, on dbc/excavator4.dbc, each loop on a pump of
    its own (pressure compensated) unless ``pump_system`` says otherwise."""
    stick = {s: f"Stick_{s}" for s in ("SpoolCmd", "PumpDispCmd", "PP", "PA", "PB", "QP", "RodPos")}
    cfg = {
        "dbc": str(resource_path("dbc", "excavator4.dbc")),
        "model": str(resource_path("config", "boom_excavator4.model.npz")),
        "plausibility": {"pump_system": pump_system},
        "loops": [
            {"name": "boom", "model": str(resource_path("config", "boom_excavator4.model.npz"))},
            {
                "name": "stick",
                "model": str(resource_path("config", "stick_excavator4.model.npz")),
                "signals": stick,
                "alarm_message": "MON_Alarm_Stick",
                "machine": str(_stick_yaml(tmp_path)),
            },
        ],
    }
    path = tmp_path / "two.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


@pytest.fixture(scope="module")
def two_pumps(tmp_path_factory):
    """Each loop simulated on its own by the single-loop simulator (boom: the reference,
    stick: its own YAML), on one time base with one engine and oil, written as one CSV and
    one candump log of both loops' signals."""
    d = tmp_path_factory.mktemp("loops")
    cfg_path = _two_loops(d)
    cfg = load_config(cfg_path)
    boom_cmd = make_cycle("boom", 12.0, 1)
    stick_cmd = make_cycle("boom", 12.0, 2)
    for shared in ("EngineSpeed", "OilTemp"):
        stick_cmd.columns[shared] = boom_cmd[shared]
    boom = simulate(boom_cmd, load_machine(), seed=1)
    stick = simulate(stick_cmd, load_machine(_stick_yaml(d)), seed=2)
    wide = wide_recording(cfg, {"boom": boom, "stick": stick})
    write_csv(d / "whole.csv", wide)
    write_candump(d / "whole.log", wide, codec=FrameCodec.from_dbc(cfg.dbc))
    return cfg_path, cfg, d, boom, stick


def test_a_loop_of_a_several_loop_csv_reads_back_as_the_simulator_wrote_it(two_pumps):
    _, cfg, d, boom, stick = two_pumps
    for name, sim in (("stick", stick), ("boom", boom)):
        rec = read_gap_loop(d / "whole.csv", cfg, name)
        assert sorted(rec.columns) == sorted(CONTRACT)
        np.testing.assert_allclose(rec.t, sim.t, atol=1e-6)
        for signal in CONTRACT:
            # The CSV keeps 10 significant digits.
            np.testing.assert_allclose(rec[signal], sim[signal], rtol=1e-9, atol=1e-9)


def test_a_loop_of_a_several_loop_candump_reads_back_within_the_dbc_resolution(two_pumps):
    _, cfg, d, _, stick = two_pumps
    rec = read_gap_loop(d / "whole.log", cfg, "stick")
    n = min(len(rec), len(stick))
    assert n >= len(stick) - 1
    # Pressures, flow and commands go through the DBC's 0.01 scaling (rounded), RodPos
    # its 0.1 mm; OilTemp is sent at 1 Hz, so it is left out here.
    for signal, lsb in (("PP", 0.01), ("PA", 0.01), ("PB", 0.01), ("QP", 0.01), ("RodPos", 0.1)):
        np.testing.assert_allclose(rec[signal][:n], stick[signal][:n], atol=lsb / 2 + 1e-9)
    np.testing.assert_allclose(rec["SpoolCmd"][:n], stick["SpoolCmd"][:n], atol=0.01)


def test_the_loops_own_simulator_yaml_is_the_one_it_is_diagnosed_against(two_pumps):
    _, cfg, *_ = two_pumps
    assert gap_loop(cfg, "stick").machine.cylinder.stroke_m == pytest.approx(0.45)
    assert gap_loop(cfg, "boom").machine is None  # the shipped reference loop then


def test_gap_diagnoses_the_loop_against_its_machine_unless_config_names_another(two_pumps):
    from argparse import Namespace

    from monitor.cli.gap import _read_loop

    cfg_path, _, d, _, stick = two_pumps
    args = Namespace(loops_config=cfg_path, loop="stick", config=None, real=d / "whole.csv")
    machine, rec = _read_loop(args)
    assert machine.cylinder.stroke_m == pytest.approx(0.45)  # the loop's machine: key
    np.testing.assert_allclose(rec["PA"], stick["PA"], rtol=1e-9, atol=1e-9)
    args.config = resource_path("config", "simulator.yaml")
    assert _read_loop(args)[0].cylinder.stroke_m == pytest.approx(0.5)  # --config wins


def _gap(tmp_path, *args):
    real, out = str(tmp_path / "absent.csv"), str(tmp_path / "g.json")
    return main(["gap", "--real", real, "--json", out, *args])


def test_the_swing_motor_is_refused_with_one_line_and_exit_3(tmp_path, capsys):
    # Refused before the recording is read: the file does not even exist.
    assert _gap(tmp_path, "--loop", "swing") == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "swing is a motor" in err[0]
    assert not (tmp_path / "g.json").exists()


def test_a_loop_on_a_shared_load_sensing_pump_is_refused_with_one_line_and_exit_3(tmp_path, capsys):
    assert _gap(tmp_path, "--loop", "stick") == 3  # the shipped excavator4.yaml: load sensing
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "shares a load-sensing pump with boom, bucket, swing" in err[0]
    cfg = _two_loops(tmp_path, pump_system="load_sensing")
    assert _gap(tmp_path, "--loop", "boom", "--loops-config", str(cfg)) == 3
    assert "shares a load-sensing pump with stick " in capsys.readouterr().err


def test_a_bad_loop_name_is_one_line_naming_the_loops_and_exit_2(tmp_path, capsys):
    assert _gap(tmp_path, "--loop", "arm") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("monitor gap: error: --loop 'arm': no such loop in ")
    assert err[0].endswith("loops: boom, stick, bucket, swing")


def test_loops_config_without_loop_is_a_user_error(tmp_path, capsys):
    assert _gap(tmp_path, "--loops-config", str(resource_path("config", "excavator4.yaml"))) == 2
    assert "give --loop NAME" in capsys.readouterr().err


def test_a_whole_machine_recording_without_loop_is_one_line_asking_for_it(two_pumps, capsys):
    _, _, d, *_ = two_pumps
    for name in ("whole.csv", "whole.log"):
        args = ["gap", "--real", str(d / name), "--json", str(d / "g.json")]
        assert main(args) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1
        assert "a whole-machine recording (it carries the stick loops' signals" in err[0]
        assert err[0].endswith("give --loop NAME")
    assert not (d / "g.json").exists()
