"""RESULTS/: durable per-log parts while a run goes, compacted atomically into Parquet.

Each finished log is written at once as ``parts/<key>.json`` (temporary file, fsync, rename),
so a killed client loses nothing finished.  ``compact`` merges the parts into logs.parquet and
events.parquet (write to a temporary file, then ``os.replace``) keeping one row per
(log, sha256), and only then removes the parts: a kill at any point leaves either the part or
the row, and never two rows for one log.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from monitor.fleet.loops import add_findings

LOG_SCHEMA = pa.schema(
    [
        ("machine", pa.string()),
        ("log", pa.string()),
        ("sha256", pa.string()),
        ("verdict", pa.string()),
        ("alarm", pa.bool_()),
        ("fault", pa.string()),
        ("sensor_fault", pa.bool_()),
        ("max_j_ratio", pa.float64()),
        ("p95_j_ratio", pa.float64()),
        ("judged_s", pa.float64()),
        ("first_alarm_t", pa.float64()),
        ("frames", pa.int64()),
        ("rejected", pa.string()),
        ("model", pa.string()),
        ("error", pa.string()),
        ("max_j", pa.float64()),
        ("eps0", pa.float64()),
        ("samples", pa.int64()),
        # max(J / eps0, B / b0, L / l0, H / h0): the level the alarm compares with 1 (results
        # written before it existed read it as null; the health index then falls back to
        # max_j_ratio).
        ("max_level", pa.float64()),
        # median J / eps0 of the log: what the prognosis trends (null in older results).
        ("p50_j_ratio", pa.float64()),
        # median J of the log / median J of the model's own normal data (out of sample): the
        # drift from commissioning, whatever eps0 is (null for models without it).
        ("p50_j_drift", pa.float64()),
        # JSON text: the log's alarm episodes (monitor.fleet.episodes), each with kind, start_t,
        # end_t, duration_s, name, check, votes, spn, fmi (null in older results).
        ("episodes", pa.string()),
        # judged with a model not commissioned on this machine (the default model of a
        # machine without commissioning): its hydraulic alarms withheld (null in older results)
        ("reference_model", pa.bool_()),
    ]
)


def log_schema() -> pa.Schema:
    """``LOG_SCHEMA`` and a ratio column for every other statistic of the family
    (``max_b_ratio``, ...; null for a model without it)."""
    from monitor.fleet.pipeline import statistics

    names = [column for _, _, column in statistics()]
    more = [(c, pa.float64()) for c in names if c not in LOG_SCHEMA.names]
    return pa.schema([*LOG_SCHEMA, *more, LOOP_FIELD, *MACHINE_FIELDS])


#: The loop a row judges: a whole machine's log has a row per loop of the config's
#: ``loops:`` (`monitor detect --loop`); null for a log judged as one loop (`monitor detect`
#: without --loop).  Last, so the columns before it are those of fleets before it.
LOOP_FIELD = pa.field("loop", pa.string())

#: After ``loop`` (null in one-loop fleets and in results written before them): why a row
#: is not judged (the pump's: its rule off, or no commissioning data); when the window of
#: the pump's first alarm began (s from the log's first sample); and the machine's finding
#: on the row's log (``monitor.detection.machine``): the source it names (a loop or
#: ``pump``, null: no alarm) and this row's part in it (``named``, ``secondary``,
#: ``explained_by_pump``; null: no alarm of its own).
MACHINE_FIELDS = (
    pa.field("not_judged_why", pa.string()),
    pa.field("alarm_since_t", pa.float64()),
    pa.field("finding", pa.string()),
    pa.field("finding_role", pa.string()),
)


EVENT_SCHEMA = pa.schema(
    [
        ("machine", pa.string()),
        ("log", pa.string()),
        ("sha256", pa.string()),
        ("t", pa.float64()),
        ("time", pa.string()),
        ("state", pa.string()),
        ("J", pa.float64()),
        ("threshold", pa.float64()),
        ("fault", pa.string()),
        ("event", pa.string()),
        LOOP_FIELD,
    ]
)

#: A row's key: (log, loop or "", sha256 or "").
Key = tuple[str, str, str]


def _key(log: str, sha256: str | None, loop: str | None = None) -> Key:
    return (log, loop or "", sha256 or "")


def row_key(row: dict[str, Any]) -> Key:
    """The key of a row of logs.parquet (or of a part), old rows without ``loop`` too."""
    return _key(row["log"], row["sha256"], row.get("loop"))


def _write_atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    with tmp.open("wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


#: The key of trained-from.json that says whether each statistic is on and why.
STATISTICS_KEY = "statistics"


def trained_statistics(results: Path, machine: str) -> dict[str, str] | None:
    """Whether each statistic of ``machine``'s commissioned model is on and why, from
    RESULTS/models/<machine>.trained-from.json; None for a machine without it (the default
    model, or results from before the record was kept)."""
    try:
        path = results / "models" / f"{machine}.trained-from.json"
        known = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    stats = known.get(STATISTICS_KEY) if isinstance(known, dict) else None
    if not isinstance(stats, dict):
        return None
    # The family's order (J, B, L, H), not the file's sorted keys.
    from monitor.fleet.pipeline import statistics

    order = [name for name, _, _ in statistics()]
    return dict(sorted(stats.items(), key=lambda kv: order.index(kv[0]) if kv[0] in order else 99))


def on_off_text(stats: dict[str, str]) -> str:
    """``statistics on: J; off: B, L, H`` for a fleet table (the reasons go below it)."""
    on = [n for n, why in stats.items() if why.startswith("on")]
    off = [n for n, why in stats.items() if not why.startswith("on")]
    return f"statistics on: {', '.join(on) or '-'}" + (f"; off: {', '.join(off)}" if off else "")


class ResultStore:
    """The results folder of one fleet run."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.parts = root / "parts"
        self.models = root / "models"
        self.parts.mkdir(parents=True, exist_ok=True)
        self.models.mkdir(parents=True, exist_ok=True)

    def cached_model(self, machine: str, manifest: dict[str, Any]) -> bytes | None:
        """The model stored for ``machine`` if it was trained from exactly ``manifest``
        (its commissioning files' hashes, reference model and settings), else None."""
        npz, meta = self._model_paths(machine)
        try:
            known = json.loads(meta.read_text(encoding="utf-8"))
            known.pop(STATISTICS_KEY, None)  # what training decided, not what it was given
            return npz.read_bytes() if known == manifest else None
        except (OSError, ValueError, AttributeError):
            return None

    def save_model(
        self,
        machine: str,
        data: bytes,
        manifest: dict[str, Any] | None,
        statistics: dict[str, str] | None = None,
    ) -> None:
        """The model file, then (last, so a killed run never vouches for a model it did not
        finish) what it was trained from; None: not a commissioned model, nothing to reuse.
        ``statistics``: whether each statistic is on and why (kept beside the manifest)."""
        npz, meta = self._model_paths(machine)
        meta.unlink(missing_ok=True)
        _write_atomic(npz, data)
        if manifest is not None:
            record = manifest if statistics is None else {**manifest, STATISTICS_KEY: statistics}
            _write_atomic(meta, json.dumps(record, sort_keys=True).encode())

    def _model_paths(self, machine: str) -> tuple[Path, Path]:
        # A whole machine's pump (``M01.pump``): its pump model file, M01.pump.json.
        model = f"{machine}.json" if machine.endswith(".pump") else f"{machine}.model.npz"
        return self.models / model, self.models / f"{machine}.trained-from.json"

    def done(self) -> set[Key]:
        """(log, loop, sha256) of every log (loop) with a row, in logs.parquet or a part."""
        keys = {row_key(r) for r in self._rows_parquet()}
        return keys | {row_key(p["row"]) for p in self._parts()}

    def add(self, row: dict[str, Any], events: list[dict[str, Any]]) -> None:
        """One finished log (or loop of a log), durable when this returns."""
        loop = f"\0{row['loop']}" if row.get("loop") else ""
        key = f"{row['log']}\0{row['sha256']}{loop}"
        name = hashlib.sha256(key.encode()).hexdigest()[:32]
        data = json.dumps({"row": row, "events": events}).encode("utf-8")
        _write_atomic(self.parts / f"{name}.json", data)

    def pending(self) -> int:
        """Finished logs not merged into the tables yet (an unfinished run's)."""
        return len(list(self.parts.glob("*.json")))

    def rows(self) -> list[dict[str, Any]]:
        """The rows of logs.parquet (none before the first finished run)."""
        return self._rows_parquet()

    def _parts(self) -> list[dict[str, Any]]:
        out = []
        for p in sorted(self.parts.glob("*.json")):
            try:
                out.append(json.loads(p.read_text(encoding="utf-8")))
            except (OSError, json.JSONDecodeError):
                continue  # only a torn temporary can be unreadable, and those are .tmp
        return out

    def _rows_parquet(self) -> list[dict[str, Any]]:
        path = self.root / "logs.parquet"
        return pq.read_table(path).to_pylist() if path.exists() else []

    def _events_parquet(self) -> list[dict[str, Any]]:
        path = self.root / "events.parquet"
        return pq.read_table(path).to_pylist() if path.exists() else []

    def compact(self) -> int:
        """Merge the parts into logs.parquet and events.parquet; the number of rows."""
        parts = self._parts()
        rows = {row_key(r): r for r in self._rows_parquet()}
        events = [e for e in self._events_parquet()]
        for p in parts:
            row = p["row"]
            key = row_key(row)
            if row["sha256"] is None or key not in rows:
                events = [e for e in events if row_key(e) != key]
                events += [self._event(row, e) for e in p["events"]]
            rows[key] = row
        # A log that changed (new hash) keeps one row (per loop): its newest.
        latest: dict[tuple[str, str], dict[str, Any]] = {}
        for r in rows.values():
            latest[(r["log"], r.get("loop") or "")] = r
        keep = {row_key(r) for r in latest.values()}
        out = [latest[k] for k in sorted(latest)]
        add_findings(out)  # each whole machine's log: which alarm names the fault
        table = pa.Table.from_pylist(out, log_schema())
        ev = [e for e in events if row_key(e) in keep]
        ev.sort(key=lambda e: (e["log"], e.get("loop") or "", e["t"]))
        self._write_table(self.root / "logs.parquet", table)
        self._write_table(self.root / "events.parquet", pa.Table.from_pylist(ev, EVENT_SCHEMA))
        for done in self.parts.glob("*.json"):
            done.unlink()
        return table.num_rows

    @staticmethod
    def _event(row: dict[str, Any], e: dict[str, Any]) -> dict[str, Any]:
        return {
            "machine": row["machine"],
            "log": row["log"],
            "sha256": row["sha256"],
            "t": e["t"],
            "time": e.get("time"),
            "state": e["state"],
            "J": e.get("J"),
            "threshold": e.get("threshold"),
            "fault": e.get("fault"),
            "event": json.dumps(e),
            "loop": row.get("loop"),
        }

    @staticmethod
    def _write_table(path: Path, table: pa.Table) -> None:
        tmp = path.with_name(f".{path.name}.tmp")
        pq.write_table(table, tmp)
        with tmp.open("rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
