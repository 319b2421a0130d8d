"""Where J rose on the outsider's plant: for every normal log of a scored detect_blind seed
that alarmed, the J window at its peak split by output and spool regime.

    python -m benchmarks.detect_blind_why --work W/s3 [--type pm15] [--md why.md]

Reads what `python -m benchmarks.detect_blind.score` left in ``--work`` (``data/key.json``,
the models and the summaries) and runs the logs again through the monitor's own detector,
so the split is of the J that alarmed.  J(k) is the mean of e^2 over the last N + 1 judged
samples (eq. 9, averaged over outputs); a sample's e^2 of one output is put to that output
and to the sample's regime (``hold`` within +-5 % of lever, ``raise`` above, ``lower``
below), and each share is its sum over the window / the window's sum.  With each log its
payload, operator style and oil temperatures from the key: what the commissioning run did
not show.  Lives apart from benchmarks/detect_blind (written without our code), because it
reads the monitor's internals.

    python -m benchmarks.detect_blind_why --work W/s3 --separation [--md sep.md]

asks instead whether any threshold could have told the faults from the normal logs: per
machine, the largest level (each statistic / its threshold, as the detector compares with
1) of any of its normal logs, against each fault run's largest level after its onset.  A
run above every normal log would be detected without a false alarm by some threshold of
that machine; one below is missed by every threshold on the level that keeps the normal
logs quiet, however it is set (held out, cross-fitted, conformal, per machine): the
statistic or the residual has to change.  Runs never judged after their onset count as
not separable.  "By regime" asks the same of J's window sum split by each sample's regime
(J = J_hold + J_raise + J_lower, each / eps0): a run is separable so when one part after
its onset exceeds that part in every normal log, as thresholds per regime would judge it.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

REGIMES = ("hold", "raise", "lower")


def regime_of(spool_pct: np.ndarray, hold_pct: float) -> np.ndarray:
    """0 hold, 1 raise, 2 lower per sample (the order of ``REGIMES``)."""
    s = np.asarray(spool_pct, dtype=np.float64)
    return np.where(s > hold_pct, 1, np.where(s < -hold_pct, 2, 0))


def window_shares(
    e: np.ndarray, spool_pct: np.ndarray, end: int, window_n: int, hold_pct: float = 5.0
) -> np.ndarray:
    """(regimes, outputs) shares of J's window ending at sample ``end``: the N + 1 last
    judged samples (rows of ``e`` without NaN) up to it, as eq. 9 sums them.  The shares add
    up to 1 (all 0 when the window holds no residual)."""
    e = np.asarray(e, dtype=np.float64)
    judged = np.flatnonzero(np.isfinite(e[: end + 1]).all(axis=1))[-(window_n + 1) :]
    sq = e[judged] ** 2
    reg = regime_of(np.asarray(spool_pct)[judged], hold_pct)
    out = np.zeros((len(REGIMES), e.shape[1]))
    for r in range(len(REGIMES)):
        out[r] = sq[reg == r].sum(axis=0)
    total = out.sum()
    return out / total if total > 0 else out


def _detect(work: Path, entry: dict):  # noqa: ANN202 - (model, recording, Detection)
    """The log run through the monitor's own detector with its machine's scored model."""
    from monitor.config.settings import load_config
    from monitor.detection.offline import detect
    from monitor.io.csvio import read_csv
    from monitor.model.modelfile import load_model

    model = load_model(work / "models" / (machine_of(entry).replace("/", "_") + ".npz"))
    rec = read_csv(work / "data" / entry["path"])
    cfg = load_config()
    return model, rec, detect(model, rec, cfg.alarm, cfg.horizon, gating=cfg.gating)


def machine_of(entry: dict) -> str:
    """``types/pm15/pm15_m0`` of a key entry's path."""
    return "/".join(entry["path"].split("/")[:3])


def _peak(work: Path, entry: dict) -> dict | None:
    """The log's peak J / threshold, its time and the window's shares; None when it never
    judged a full window."""
    from monitor.model.bias import HOLD_PCT
    from monitor.model.residual import J, leave_out_stops

    model, rec, det = _detect(work, entry)
    if det.level is None or not np.isfinite(det.level).any():
        return None
    k = int(np.nanargmax(det.level))
    j = J.get(model)
    e = leave_out_stops(det.residual, rec) if j.stops else det.residual
    shares = window_shares(e, rec["SpoolCmd"], k, j.window_n, HOLD_PCT)
    return {
        "level": float(det.level[k]),
        "t_s": float(rec.t[k] - rec.t[0]),
        "shares": shares,
        "outputs": model.spec.outputs,
    }


def rows(work: Path, tname: str | None) -> list[dict]:
    key = json.loads((work / "data" / "key.json").read_text())
    out = []
    for entry in key["files"]:
        if entry["kind"] != "normal" or (tname and f"/{tname}/" not in f"/{entry['path']}"):
            continue
        summary = (work / "detect" / entry["path"]).with_suffix(".summary.json")
        if not summary.exists() or not json.loads(summary.read_text()).get("alarm"):
            continue
        peak = _peak(work, entry)
        if peak is not None:
            out.append({**entry, **peak})
    return out


def table(found: list[dict]) -> str:
    lines = [
        "| log | payload | style | oil degC | peak J / eps0 at s | largest shares "
        "| hold / raise / lower |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in found:
        sh, names = r["shares"], r["outputs"]
        cells = sorted(
            (
                (sh[g, o], f"{names[o]} {REGIMES[g]}")
                for g in range(sh.shape[0])
                for o in range(sh.shape[1])
            ),
            reverse=True,
        )[:3]
        by_regime = " / ".join(f"{v:.0%}" for v in sh.sum(axis=1))
        lines.append(
            f"| {r['path']} | {r['payload']:.2f} | {r['style']} | "
            f"{r['temp_start_c']:.0f}-{r['temp_end_c']:.0f} | {r['level']:.2f} at {r['t_s']:.0f} | "
            + ", ".join(f"{name} {v:.0%}" for v, name in cells)
            + f" | {by_regime} |"
        )
    return "\n".join(lines) + "\n"


def largest_level(level: np.ndarray | None, t_s: np.ndarray, from_s: float) -> float | None:
    """The largest finite level at or after ``from_s`` (seconds from the log's start); None
    when nothing there was judged."""
    if level is None:
        return None
    lv = np.asarray(level, dtype=np.float64)[np.asarray(t_s) >= from_s]
    lv = lv[np.isfinite(lv)]
    return float(lv.max()) if lv.size else None


def separable(normal: list[float | None], fault: float | None) -> bool:
    """A fault run some threshold tells from every normal log of its machine: its largest
    level after the onset above every normal log's largest (never judged: not separable)."""
    top = max((v for v in normal if v is not None), default=0.0)
    return fault is not None and fault > top


def regime_parts(
    e: np.ndarray, spool_pct: np.ndarray, window_n: int, hold_pct: float = 5.0
) -> np.ndarray:
    """(regimes, samples): the part of J (eq. 9) each regime's samples contribute; the parts
    add up to J, and a sample J does not judge (NaN) pauses every part's window alike."""
    from monitor.model.residual import window_j

    e = np.asarray(e, dtype=np.float64)
    judged = np.isfinite(e).all(axis=1)
    reg = regime_of(spool_pct, hold_pct)
    parts = []
    for r in range(len(REGIMES)):
        part = e.copy()
        part[judged & (reg != r)] = 0.0
        parts.append(window_j(part, window_n))
    return np.array(parts)


def separable_by_regime(normal: list[list[float | None]], fault: list[float | None]) -> bool:
    """Some regime's part of J after the onset above that part in every normal log."""
    for r, v in enumerate(fault):
        top = max((n[r] for n in normal if n[r] is not None), default=0.0)
        if v is not None and v > top:
            return True
    return False


def separation(work: Path, tname: str | None) -> dict[str, dict]:
    """Per machine: each normal log's and each fault run's largest level and largest part of
    J / eps0 per regime (fault runs after their onset), by log name."""
    from monitor.model.bias import HOLD_PCT
    from monitor.model.residual import J, leave_out_stops

    key = json.loads((work / "data" / "key.json").read_text())
    out: dict[str, dict] = {}
    for entry in key["files"]:
        kind = entry["kind"]
        if kind not in ("normal", "fault") or (tname and f"/{tname}/" not in f"/{entry['path']}"):
            continue
        model, rec, det = _detect(work, entry)
        t_s = rec.t - rec.t[0]
        onset = float(entry.get("onset_s", 0.0)) if kind == "fault" else 0.0
        j = J.get(model)
        e = leave_out_stops(det.residual, rec) if j.stops else det.residual
        parts = regime_parts(e, rec["SpoolCmd"], j.window_n, HOLD_PCT) / j.eps0
        by_regime = [largest_level(p, t_s, onset) for p in parts]
        logs = out.setdefault(machine_of(entry), {"normal": {}, "fault": {}})
        logs[kind][Path(entry["path"]).stem] = (
            entry,
            largest_level(det.level, t_s, onset),
            by_regime,
        )
    return out


def separation_table(found: dict[str, dict]) -> str:
    """One row per fault run: its machine's largest normal level, its own after the onset,
    and whether a threshold could separate them; then the count per type and severity."""
    lines = [
        "| machine | largest normal (log) | fault run | largest after onset | separable "
        "| by regime |",
        "|---|---|---|---|---|---|",
    ]
    yes = {True: "yes", False: "no"}
    count: dict[tuple[str, float], list[tuple[bool, bool]]] = {}
    for machine, logs in sorted(found.items()):
        normal = {n: v for n, (_e, v, _p) in logs["normal"].items()}
        parts = [p for _e, _v, p in logs["normal"].values()]
        judged = {n: v for n, v in normal.items() if v is not None}
        top = max(judged, key=judged.__getitem__) if judged else None
        top_cell = f"{judged[top]:.2f} ({top})" if top else "none judged"
        for name, (entry, v, p) in sorted(logs["fault"].items()):
            ok = (separable(list(normal.values()), v), separable_by_regime(parts, p))
            count.setdefault((machine.split("/")[1], entry["severity"]), []).append(ok)
            cell = "not judged" if v is None else f"{v:.2f}"
            lines.append(
                f"| {machine} | {top_cell} | {name} | {cell} | {yes[ok[0]]} | {yes[ok[1]]} |"
            )
    lines += ["", "| type | severity | separable | by regime |", "|---|---|---|---|"]
    for (t, sev), oks in sorted(count.items()):
        n, a, b = len(oks), sum(o[0] for o in oks), sum(o[1] for o in oks)
        lines.append(f"| {t} | {sev:g} | {a}/{n} | {b}/{n} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.detect_blind_why", description=__doc__.split("\n\n")[0]
    )
    ap.add_argument("--work", type=Path, required=True, help="a scored seed's --work folder")
    ap.add_argument("--type", dest="tname", help="pm05 or pm15 (default: both)")
    ap.add_argument("--md", type=Path, help="write the table here (default: stdout)")
    ap.add_argument(
        "--separation",
        action="store_true",
        help="whether any threshold tells each fault run from its machine's normal logs",
    )
    args = ap.parse_args(argv)
    if not (args.work / "data" / "key.json").exists():
        print(f"error: {args.work}: no data/key.json (score this seed first)", file=sys.stderr)
        return 2
    if args.separation:
        return _write(separation_table(separation(args.work, args.tname)), args.md)
    found = rows(args.work, args.tname)
    what = f" of type {args.tname}" if args.tname else ""
    text = table(found) if found else f"no normal log{what} in {args.work} alarmed\n"
    return _write(text, args.md)


def _write(text: str, md: Path | None) -> int:
    if md:
        md.write_text(text)
    else:
        print(text, end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
