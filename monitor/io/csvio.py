"""The contract CSV: ``t`` (s) and the physical signals, one row per sample.

The contract is in docs/reference/contracts.md.

Reading is strict about the file's shape (header, field count, numbers, a time column
``monitor.io.timebase`` can trust; rows at another rate are resampled to 100 Hz) and
lenient about the data: an empty field is a missing sample (NaN), which downstream tools treat
as a stale sensor, not a file error.  Every error names file, line and column.
"""

from __future__ import annotations

import csv
import logging
import math
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from monitor.errors import InputFileError
from monitor.io.recording import Recording
from monitor.io.timebase import check_time, resample, resample_note
from monitor.signals import CSV_COLUMNS

log = logging.getLogger("monitor")

_MISSING = ("", "nan", "NaN", "NAN")

#: Longest line a CSV may have (a contract row is some 100 characters; text columns may add
#: notes): a longer one, such as a binary file's, is refused before it is read whole.
MAX_LINE_CHARS = 1_000_000


def _lines(fh: TextIO, p: Path) -> Iterator[str]:
    """The lines of ``fh`` for ``csv.reader``, each checked as it is read: none longer than
    ``MAX_LINE_CHARS``, no NUL byte (a binary file)."""
    line_no = 0
    while line := fh.readline(MAX_LINE_CHARS + 2):  # and a CR LF
        line_no += 1
        if len(line.rstrip("\r\n")) > MAX_LINE_CHARS:
            raise InputFileError(
                f"{p}:{line_no}: line longer than {MAX_LINE_CHARS} "
                "characters (a binary or corrupt file?)"
            )
        if "\x00" in line:
            raise InputFileError(f"{p}:{line_no}: NUL bytes, not a text file")
        yield line


def _shown(text: str) -> str:
    """``text`` quoted for a message, cut to 60 characters (a field may hold 128 k)."""
    return repr(text if len(text) <= 60 else text[:57] + "...")


def _bad_value_error(
    path: Path, name: str, values: list[str], lines: list[int]
) -> InputFileError | None:
    """Locate the first value of a column that is not a number (slow path, errors only)."""
    for value, line in zip(values, lines, strict=True):
        text = value.strip()
        if text in _MISSING:
            continue
        try:
            x = float(text)
        except ValueError:
            return InputFileError(
                f"{path}:{line}: column {_shown(name)}: {_shown(value)} is not a number"
            )
        if math.isinf(x):
            return InputFileError(
                f"{path}:{line}: column {_shown(name)}: {_shown(value)} is not finite"
            )
    return None


def _to_float(path: Path, name: str, values: list[str], lines: list[int]) -> np.ndarray:
    # Fast path: numpy parses the whole column in C; only when it fails do we walk the
    # column in Python to name the offending line.
    cleaned = [v if v.strip() not in _MISSING else "nan" for v in values]
    try:
        arr = np.array(cleaned, dtype=np.float64)
    except ValueError:
        arr = None
    if arr is None or np.isinf(arr).any():
        err = _bad_value_error(path, name, values, lines)
        if err is not None:
            raise err
        # pragma: no cover
        raise InputFileError(f"{path}: column {_shown(name)}: unreadable numbers")
    return arr


#: Rows held as text at a time: each block becomes float64 columns before the next is read,
#: so reading costs the columns kept (8 bytes a value), not the file's lines as strings.
BLOCK_ROWS = 16_384


def _header(reader: Any, p: Path, required: Sequence[str] = CSV_COLUMNS) -> list[str]:
    """The header row of ``reader`` (a ``csv.reader``), checked (duplicates, ``required``
    columns) before any data row is read."""
    try:
        header = [h.strip() for h in next(reader)]
    except StopIteration:
        raise InputFileError(f"{p}:1: empty file, expected a CSV header") from None
    except csv.Error as exc:
        raise InputFileError(f"{p}:1: {exc}") from None
    line = reader.line_num
    dupes = sorted({h for h in header if header.count(h) > 1})
    if dupes:
        raise InputFileError(f"{p}:{line}: duplicate column(s) {_shown(', '.join(dupes))}")
    missing = [c for c in required if c not in header]
    if missing:
        raise InputFileError(
            f"{p}:{line}: missing required column(s) {', '.join(missing)}"
            f" (header: {_shown(','.join(header))})"
        )
    return header


def _rows(
    reader: Any, p: Path, header: list[str], required: Sequence[str] = CSV_COLUMNS
) -> tuple[dict[str, np.ndarray], np.ndarray, list[str]]:
    """(float64 column per kept column, file line of each row, text columns dropped), the
    rows converted ``BLOCK_ROWS`` at a time; blank lines skipped."""
    ncol = len(header)
    parts: dict[str, list[np.ndarray]] = {name: [] for name in header}
    line_parts: list[np.ndarray] = []
    dropped: set[str] = set()
    rows: list[list[str]] = []
    lines: list[int] = []
    try:
        for row in reader:
            if len(row) != ncol:
                if not row or (len(row) == 1 and not row[0].strip()):
                    continue  # blank line
                raise InputFileError(
                    f"{p}:{reader.line_num}: {len(row)} fields, the header has {ncol}"
                )
            rows.append(row)
            lines.append(reader.line_num)
            if len(rows) == BLOCK_ROWS:
                _convert(p, header, rows, lines, parts, dropped, required)
                line_parts.append(np.array(lines, dtype=np.int64))
                rows, lines = [], []
    except csv.Error as exc:
        raise InputFileError(f"{p}:{reader.line_num}: {exc}") from None
    if rows:
        _convert(p, header, rows, lines, parts, dropped, required)
        line_parts.append(np.array(lines, dtype=np.int64))
    if not line_parts:
        raise InputFileError(f"{p}: no data rows after the header")
    columns = {name: np.concatenate(v) for name, v in parts.items() if name not in dropped}
    return columns, np.concatenate(line_parts), [h for h in header if h in dropped]


def _convert(
    p: Path,
    header: list[str],
    rows: list[list[str]],
    lines: list[int],
    parts: dict[str, list[np.ndarray]],
    dropped: set[str],
    required: Sequence[str] = CSV_COLUMNS,
) -> None:
    """One block of rows onto ``parts``; a column holding text is dropped (``dropped``)
    unless it is required (``InputFileError`` naming its line)."""
    must = set(required)
    for name, values in zip(header, zip(*rows, strict=True), strict=True):
        if name in dropped:
            continue
        try:
            parts[name].append(_to_float(p, name, list(values), lines))
        except InputFileError:
            if name in must:
                raise
            dropped.add(name)  # an extra text column: tools ignore what they do not need
            parts[name].clear()


def read_csv(path: str | Path, required: Sequence[str] = CSV_COLUMNS) -> Recording:
    """Read a contract CSV into a ``Recording`` (``t`` in s, signals in contract units).

    Required columns are ``required`` (default ``monitor.signals.CSV_COLUMNS``; a
    whole-machine CSV read for one loop requires that loop's DBC signal names) in any
    order, ``t`` always; other numeric
    columns (such as ``RodPos``) are kept; extra columns holding text (labels, notes)
    are left out and listed in ``meta["dropped_columns"]``.  Blank lines are skipped.
    Raises ``InputFileError`` naming file, line and column for missing required columns,
    text where a number belongs, a wrong number of fields, a missing ``t`` or one that
    ``check_time`` refuses.  Rows at another rate than 100 Hz are resampled to it
    (``meta["resampled_from_hz"]``, and a warning saying so).
    """
    p = Path(path)
    try:
        with p.open(newline="", encoding="utf-8-sig") as fh:
            reader = csv.reader(_lines(fh, p))
            required = ("t", *(c for c in required if c != "t"))
            header = _header(reader, p, required)
            columns, lines, dropped = _rows(reader, p, header, required)
    except UnicodeDecodeError as exc:
        raise InputFileError(f"{p}: not a UTF-8 text file ({exc.reason})") from None
    except OSError as exc:
        raise InputFileError(f"{p}: cannot read: {exc.strerror or exc}") from None
    t = columns.pop("t")
    if np.isnan(t).any():
        i = int(np.flatnonzero(np.isnan(t))[0])
        raise InputFileError(f"{p}:{lines[i]}: column 't': time is missing")
    base = check_time(t, str(p), lines)
    meta: dict[str, object] = {"format": "csv"}
    if base.resample:
        n_rows = t.size
        t, columns = resample(t, columns, base.step_s)
        meta["resampled_from_hz"] = base.rate_hz
        log.warning(resample_note(str(p), n_rows, base.step_s, t.size))
    if dropped:
        meta["dropped_columns"] = dropped
    return Recording(t=t, columns=columns, source=str(p), meta=meta)


def _format_column(values: np.ndarray, fmt: str) -> list[str]:
    out = [fmt % v for v in values.tolist()]
    for i in np.flatnonzero(np.isnan(values)).tolist():
        out[i] = ""  # a missing sample is an empty field
    return out


def write_csv(path: str | Path, rec: Recording, extra_columns: Sequence[str] | None = None) -> None:
    """Write ``rec`` as a contract CSV.

    Columns: ``t`` and the contract signals first, then ``extra_columns`` (default: every
    other column of the recording, in its order; ``()`` for the contract columns only).
    ``t`` is written with 6 decimals (1 us) and signals with 10 significant digits, far
    below the DBC resolution (0.01), so a write/read round trip is exact for our purposes.
    NaN is written as an empty field.
    """
    rec.require()
    if extra_columns is None:
        extras = [n for n in rec.columns if n not in CSV_COLUMNS]
    else:
        extras = list(extra_columns)
        for name in extras:
            rec[name]  # raises InputFileError naming the missing column
    names = [*CSV_COLUMNS, *[n for n in extras if n not in CSV_COLUMNS]]
    p = Path(path)
    try:
        with p.open("w", newline="", encoding="utf-8") as fh:
            fh.write(",".join(names) + "\n")
            # BLOCK_ROWS rows formatted at a time: the text of a day's rows is not held whole.
            for a in range(0, len(rec), BLOCK_ROWS):
                cut = slice(a, a + BLOCK_ROWS)
                formatted = [_format_column(rec.t[cut], "%.6f")]
                formatted += [_format_column(rec[n][cut], "%.10g") for n in names[1:]]
                fh.writelines(",".join(row) + "\n" for row in zip(*formatted, strict=True))
    except OSError as exc:
        raise InputFileError(f"{p}: cannot write: {exc.strerror or exc}") from None
