"""Two loops, each on a pump of its own, in one candump log: what `monitor gap --loop` can
stand for (docs/benchmarks: the gap tool on one loop of a whole machine).

    python benchmarks/gap_two_loops.py OUT
    monitor gap --real OUT/whole.log --loop stick --loops-config OUT/two.yaml --json a.json
    monitor gap --real OUT/stick_alone.csv --config OUT/stick_sim.yaml --json b.json

Writes OUT/stick_sim.yaml (the reference loop's simulator YAML with a stick's cylinder,
60/35 x 450 mm, and load, 250 kg and 3.5 kN), OUT/two.yaml (a monitor config of two loops,
boom and stick, on dbc/excavator4.dbc, pressure compensated), OUT/whole.log (both loops,
each simulated alone for 120 s, seeds 11 and 12, one engine and oil) and
OUT/stick_alone.csv (the stick's simulation as a contract CSV).
"""

from __future__ import annotations

import sys
from pathlib import Path

import yaml

from monitor.codec.frames import FrameCodec
from monitor.codec.logwrite import write_candump
from monitor.config.settings import load_config
from monitor.io.csvio import write_csv
from monitor.offline.recordings import wide_recording
from monitor.resources import resource_path
from monitor.sim.cycles import make_cycle
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate

STICK = ("SpoolCmd", "PumpDispCmd", "PP", "PA", "PB", "QP", "RodPos")


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    sim = yaml.safe_load(resource_path("config", "simulator.yaml").read_text())
    sim["cylinder"].update(bore_mm=60, rod_mm=35, stroke_mm=450)
    sim["load"].update(mass_kg=250, gravity_load_n=3500)
    (out / "stick_sim.yaml").write_text(yaml.safe_dump(sim))
    model = str(resource_path("config", "boom_excavator4.model.npz"))
    cfg = {
        "dbc": str(resource_path("dbc", "excavator4.dbc")),
        "model": model,
        "plausibility": {"pump_system": "pressure_compensated"},
        "loops": [
            {"name": "boom", "model": model},
            {
                "name": "stick",
                "model": str(resource_path("config", "stick_excavator4.model.npz")),
                "signals": {s: f"Stick_{s}" for s in STICK},
                "alarm_message": "MON_Alarm_Stick",
                "machine": str(out / "stick_sim.yaml"),
            },
        ],
    }
    (out / "two.yaml").write_text(yaml.safe_dump(cfg))
    boom_cmd, stick_cmd = make_cycle("boom", 120.0, 11), make_cycle("boom", 120.0, 12)
    for shared in ("EngineSpeed", "OilTemp"):
        stick_cmd.columns[shared] = boom_cmd[shared]
    boom = simulate(boom_cmd, load_machine(), seed=11)
    stick = simulate(stick_cmd, load_machine(out / "stick_sim.yaml"), seed=12)
    monitor_cfg = load_config(out / "two.yaml")
    wide = wide_recording(monitor_cfg, {"boom": boom, "stick": stick})
    write_candump(out / "whole.log", wide, codec=FrameCodec.from_dbc(monitor_cfg.dbc))
    write_csv(out / "stick_alone.csv", stick)
    print(f"wrote {out}/two.yaml, stick_sim.yaml, whole.log, stick_alone.csv")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(Path(sys.argv[1]))
