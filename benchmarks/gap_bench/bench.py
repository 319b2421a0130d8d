"""Withheld-effect benchmark of ``monitor gap``: generate, diagnose blind, score.

    python benchmarks/gap_bench/bench.py --out /tmp/gapbench            # full table
    python benchmarks/gap_bench/bench.py --out /tmp/g --per-effect 1 --none 2 \
        --unexplained 1 --pairs 0 --duration 60                          # quick look

Recordings go to OUT/recordings, labels to OUT/labels/labels.json (apart from the data);
the diagnosis runs as ``python -m monitor gap`` in a subprocess per recording, which sees
only the recording.  Then the results are scored against the labels: top-1 and top-2 per
effect, confusion matrix, ``none`` and ``unexplained`` accuracy, median held-out gap
reduction of correct verdicts, median diagnosis time.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from collections import Counter, defaultdict
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from generate import EFFECTS, cases, generate  # noqa: E402


def _diagnose_one(rec: Path, out: Path) -> tuple[float, str]:
    start = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "monitor", "gap", "--real", str(rec), "--json", str(out), "--quiet"],
        capture_output=True,
        text=True,
        check=False,
    )
    if proc.returncode != 0:
        out.write_text(json.dumps({"error": proc.stderr.strip(), "verdict": "error"}))
    said = proc.stdout.strip().splitlines()[-1] if proc.stdout.strip() else proc.stderr.strip()
    return time.perf_counter() - start, said


def diagnose_blind(
    data_dir: Path, results_dir: Path, progress=print, jobs: int = 1, reuse: bool = False
) -> dict[str, float]:
    """Run ``monitor gap`` on every recording (``jobs`` at a time); wall time per recording.

    With ``reuse``, recordings that already have a result are skipped (a resumed run).
    """
    results_dir.mkdir(parents=True, exist_ok=True)
    todo = [
        r
        for r in sorted(data_dir.glob("*.csv"))
        if not (reuse and (results_dir / (r.stem + ".json")).exists())
    ]
    times = {}
    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        futures = {pool.submit(_diagnose_one, r, results_dir / (r.stem + ".json")): r for r in todo}
        for fut in as_completed(futures):
            rec = futures[fut]
            times[rec.name], said = fut.result()
            progress(f"{rec.name}: {said} ({times[rec.name]:.0f} s)")
    return times


def score(labels: dict, results_dir: Path, times: dict[str, float] | None = None) -> dict:
    per = defaultdict(lambda: {"n": 0, "top1": 0, "top2": 0})
    confusion: dict[str, Counter] = defaultdict(Counter)
    reductions = []
    by_gen = defaultdict(lambda: [0, 0])
    pair_also = [0, 0]
    none_as_effect = 0
    spurious_also = 0  # a second effect named where there is at most one
    missing = []
    for name, lab in sorted(labels.items()):
        path = results_dir / (Path(name).stem + ".json")
        if not path.exists():  # a run stopped early: score what finished, say what did not
            missing.append(name)
            continue
        res = json.loads(path.read_text())
        verdict = res["verdict"]
        truth = lab["truth"]
        confusion[truth if lab["kind"] != "pair" else f"{truth}+{lab['second']}"][verdict] += 1
        ranked = [r["effect"] for r in res.get("ranking", [])][:2]
        named = {verdict, res.get("also")}
        if lab["kind"] == "pair":
            ok1 = verdict in (truth, lab["second"])
            ok2 = ok1 or bool({truth, lab["second"]} & set(ranked))
            pair_also[0] += int(ok1 and res.get("also") in (truth, lab["second"]))
            pair_also[1] += 1
            key = "pair"
        else:
            spurious_also += int(res.get("also") is not None)
            ok1 = verdict == truth
            ok2 = ok1 or truth in named or (lab["kind"] == "effect" and truth in ranked)
            key = truth
        if lab["kind"] == "none" and verdict in EFFECTS:
            none_as_effect += 1
        per[key]["n"] += 1
        per[key]["top1"] += int(ok1)
        per[key]["top2"] += int(ok2)
        by_gen[lab["generator"]][0] += int(ok1)
        by_gen[lab["generator"]][1] += 1
        if ok1 and lab["kind"] in ("effect", "pair"):
            reductions.append(res["shrink"]["heldout_reduction"])
    eff = [k for k in per if k in EFFECTS]
    n_eff = sum(per[k]["n"] for k in eff)
    return {
        "per_label": {k: dict(v) for k, v in per.items()},
        "top1_effects": sum(per[k]["top1"] for k in eff) / max(n_eff, 1),
        "top2_effects": sum(per[k]["top2"] for k in eff) / max(n_eff, 1),
        "none_accuracy": per["none"]["top1"] / max(per["none"]["n"], 1),
        "none_mistaken_for_effect": none_as_effect,
        "unexplained_accuracy": per["unexplained"]["top1"] / max(per["unexplained"]["n"], 1),
        "pair_also_correct": f"{pair_also[0]}/{pair_also[1]}",
        "spurious_also": spurious_also,
        "by_generator_top1": {g: f"{a}/{n}" for g, (a, n) in by_gen.items()},
        "median_heldout_reduction_correct": float(np.median(reductions)) if reductions else None,
        "median_diagnosis_s": float(np.median(list(times.values()))) if times else None,
        "confusion": {k: dict(v) for k, v in confusion.items()},
        "n_recordings": len(labels) - len(missing),
        "not_diagnosed": missing,
    }


def table(s: dict) -> str:
    lines = [f"{s['n_recordings']} recordings diagnosed"]
    if s["not_diagnosed"]:
        lines[0] += f"; not diagnosed (run stopped): {', '.join(s['not_diagnosed'])}"
    lines += ["", "| truth | n | top-1 | top-2 |", "|---|---|---|---|"]
    for k, v in sorted(s["per_label"].items()):
        lines.append(f"| {k} | {v['n']} | {v['top1']}/{v['n']} | {v['top2']}/{v['n']} |")
    lines += [
        "",
        f"effects top-1 {100 * s['top1_effects']:.0f} %, top-2 {100 * s['top2_effects']:.0f} %; "
        f"none {100 * s['none_accuracy']:.0f} % (mistaken for an effect: "
        f"{s['none_mistaken_for_effect']}); unexplained {100 * s['unexplained_accuracy']:.0f} %; "
        f"pairs with the right second effect {s['pair_also_correct']}; a second effect named "
        f"without a pair: {s['spurious_also']}",
        f"top-1 by generator: {s['by_generator_top1']}",
        f"median held-out gap reduction (correct verdicts): "
        f"{s['median_heldout_reduction_correct']}; median diagnosis "
        f"{s['median_diagnosis_s']} s",
        "",
        "confusion (truth -> verdicts):",
    ]
    for k, v in sorted(s["confusion"].items()):
        lines.append(f"  {k}: " + ", ".join(f"{vk} {n}" for vk, n in sorted(v.items())))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--per-effect", type=int, default=2, help="recordings per effect")
    p.add_argument("--none", type=int, default=4)
    p.add_argument("--unexplained", type=int, default=3)
    p.add_argument("--pairs", type=int, default=3)
    p.add_argument("--duration", type=float, default=120.0, help="recording length (s)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--jobs", type=int, default=1, help="diagnoses run at once (default 1)")
    p.add_argument(
        "--resume",
        action="store_true",
        help="keep the recordings and results already in OUT, diagnose the rest",
    )
    p.add_argument("--score-only", action="store_true", help="rescore existing results")
    a = p.parse_args(argv)
    data, labels_path, results = (
        a.out / "recordings",
        a.out / "labels" / "labels.json",
        a.out / "results",
    )
    times = None
    if not a.score_only:
        if not (a.resume and labels_path.exists()):
            plan = cases(a.per_effect, a.none, a.unexplained, a.pairs)
            generate(data, labels_path, plan, a.duration, a.seed)
            run = {"date": time.strftime("%Y-%m-%d"), "seed": a.seed, "duration_s": a.duration}
            (a.out / "run.json").write_text(json.dumps(run))
        times_path = a.out / "times.json"
        times = json.loads(times_path.read_text()) if a.resume and times_path.exists() else {}
        times.update(diagnose_blind(data, results, jobs=a.jobs, reuse=a.resume))
        times_path.write_text(json.dumps(times, indent=1))
    elif (a.out / "times.json").exists():
        times = json.loads((a.out / "times.json").read_text())
    s = score(json.loads(labels_path.read_text()), results, times)
    run_path = a.out / "run.json"  # the generating run's seed, not this call's default
    run = {"date": time.strftime("%Y-%m-%d"), "seed": a.seed, "duration_s": a.duration}
    s.update(json.loads(run_path.read_text()) if run_path.exists() else run)
    (a.out / "summary.json").write_text(json.dumps(s, indent=2))
    print(table(s))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
