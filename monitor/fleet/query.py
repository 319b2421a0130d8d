"""`monitor fleet query`: SQL over the results with DuckDB.

Views: ``logs`` and ``events`` over RESULTS' Parquet files, and ``episodes``, one row per
alarm episode unnested from the ``episodes`` JSON column of logs (no column: no rows).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from monitor.errors import ConfigError, InputFileError

_EPISODE = (
    '{"kind": "VARCHAR", "name": "VARCHAR", "check": "VARCHAR", "start_t": "DOUBLE", '
    '"end_t": "DOUBLE", "duration_s": "DOUBLE", "spn": "INTEGER", "fmi": "INTEGER", '
    '"open": "BOOLEAN"}'
)


def _sql_path(path: Path) -> str:
    return "'" + str(path.resolve()).replace("'", "''") + "'"


def connect(results: Path) -> Any:
    """An in-memory DuckDB connection with the views ``logs``, ``events``, ``episodes``."""
    import duckdb

    logs, events = results / "logs.parquet", results / "events.parquet"
    if not logs.is_file():
        raise InputFileError(f"{logs}: no such file (run `monitor fleet run` first)")
    con = duckdb.connect(":memory:")
    con.execute(f"CREATE VIEW logs AS SELECT * FROM read_parquet({_sql_path(logs)})")
    if events.is_file():
        con.execute(f"CREATE VIEW events AS SELECT * FROM read_parquet({_sql_path(events)})")
    cols = {r[0] for r in con.execute("DESCRIBE logs").fetchall()}
    if "episodes" in cols:
        # A whole machine's episodes name their loop (results from before: no loop column).
        loop = ", loop" if "loop" in cols else ""
        con.execute(
            "CREATE VIEW episodes AS SELECT machine, log, e.kind, e.name, e.check, e.start_t, "
            f"e.end_t, e.duration_s, e.spn, e.fmi, e.open{loop} FROM (SELECT machine, log{loop}, "
            f"unnest(from_json(episodes, '[{_EPISODE}]')) AS e FROM logs "
            "WHERE episodes IS NOT NULL)"
        )
    return con


def run_query(results: Path, sql: str) -> tuple[list[str], list[tuple]]:
    """Column names and rows of one SQL statement; a bad statement is one ConfigError."""
    import duckdb

    con = connect(results)
    try:
        cur = con.execute(sql)
        if cur.description is None:
            return [], []
        return [d[0] for d in cur.description], cur.fetchall()
    except duckdb.Error as exc:
        first = str(exc).strip().splitlines()[0]
        raise ConfigError(f"query: {first}") from None
    finally:
        con.close()


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def format_table(header: list[str], rows: list[tuple]) -> str:
    """A plain-text table (columns padded), with the row count below."""
    if not header:
        return "(no result)"
    cells = [[_cell(v) for v in r] for r in rows]
    widths = [max([len(h)] + [len(c[i]) for c in cells]) for i, h in enumerate(header)]
    line = "  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True))
    out = [line, "  ".join("-" * w for w in widths)]
    out += ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in cells]
    out.append(f"({len(rows)} row{'s' if len(rows) != 1 else ''})")
    return "\n".join(out)
