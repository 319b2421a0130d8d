"""The whole machine's shipped loop models with the full-lever statistic L fitted, their
networks and other thresholds as they are: what L would do on a loop before it is retrained.

    python benchmarks/excavator4_add_lever.py HELD_DIR OUT_DIR

HELD_DIR holds the held-out runs the shipped thresholds rest on (config/excavator4_train_
models.sh: ``monitor simulate --machine excavator4 --duration 600`` seeds 201-212, and
213-216 with ``--cycle lifting``, as ``held_SEED.csv``), and the runs one loop alone holds
out as ``held_LOOP_SEED.csv`` (the stick's: seeds 217-220 with ``--cycle dig-lift``, as
``held_stick_SEED.csv``).  ``--loops`` fits only those loops (the others' files are copied
as they are).  Every member of the statistic
family is fitted on them as ``monitor train`` fits it (``fit_statistics``); the line per
loop and member shows the file's threshold beside the refitted one (J's and B's equal
show that the held-out data is the training's), and only L is put into the copy.  OUT_DIR
gets the four model files and an ``excavator4.yaml`` that judges them
(``benchmarks/excavator4_loops.py --config OUT_DIR/excavator4.yaml``).
"""

from __future__ import annotations

import argparse
import copy
from pathlib import Path

import yaml

from monitor.config.settings import load_config
from monitor.model.lever import Lever
from monitor.model.modelfile import load_model, save_model
from monitor.model.statistic import HeldOut, registry
from monitor.offline.recordings import loop_recordings
from monitor.resources import resource_path
from monitor.training.settings import DGRNNSettings, TrainConfig
from monitor.training.statistics import fit_statistics
from monitor.training.train import normal_residuals


def _held_files(folder: Path, loops: list[str]) -> dict[str | None, list[Path]]:
    """The held-out runs of ``folder`` by the loop that alone holds them out (None: all)."""
    out: dict[str | None, list[Path]] = {None: [], **{loop: [] for loop in loops}}
    for f in sorted(folder.glob("held_*.csv")):
        owner = f.stem.split("_")[1]
        out[owner if owner in loops else None].append(f)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("held", type=Path, help="folder of held_SEED.csv runs")
    ap.add_argument("out", type=Path, help="folder for the models and config")
    ap.add_argument("--loops", nargs="+", metavar="NAME", help="fit L on these loops only")
    args = ap.parse_args()
    src = resource_path("config", "excavator4.yaml")
    cfg = load_config(src)
    names = [lc.name for lc in cfg.monitored_loops if lc.name in (args.loops or [lc.name])]
    files = _held_files(args.held, [lc.name for lc in cfg.monitored_loops])
    if not files[None]:
        ap.error(f"{args.held}: no held_SEED.csv")
    recs: dict[str, list] = {name: [] for name in names}
    for owner, paths in files.items():
        mine = [n for n in names if owner in (None, n)]
        for f in paths if mine else []:
            for name, rec in loop_recordings(f, cfg, mine).items():
                recs[name].append(rec)
    args.out.mkdir(parents=True, exist_ok=True)
    settings = TrainConfig(DGRNNSettings(preset="section"))
    for lc in cfg.monitored_loops:
        model = load_model(lc.model)
        if lc.name not in names:
            save_model(args.out / Path(lc.model).name, model)
            continue
        e = [normal_residuals(model, r) for r in recs[lc.name]]
        validation = model.training.get("validation", "held out")
        held = HeldOut(e, recs[lc.name], model.spec.outputs, recs[lc.name], validation)
        trial = copy.deepcopy(model)
        notes, support = fit_statistics(trial, held, settings, lambda _line: None)
        for cls in registry():
            mine, theirs = cls.get(model), cls.get(trial)
            was = None if mine is None else cls().use(mine).threshold_
            now = None if theirs is None else cls().use(theirs).threshold_
            print(f"{lc.name} {cls.name}: file {was}, refitted {now} ({notes[cls.key]})")
        Lever.put(model, Lever.get(trial))
        recorded = dict(model.training.get("support", {}))
        if "L" in support:
            recorded["L"] = support["L"]
        model.training = {**model.training, "lever": notes["lever"], "support": recorded}
        save_model(args.out / Path(lc.model).name, model)
    doc = yaml.safe_load(src.read_text())
    doc["dbc"] = str((src.parent / doc["dbc"]).resolve())
    doc["pump"]["model"] = str((src.parent / doc["pump"]["model"]).resolve())
    (args.out / "excavator4.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
