"""Output paths checked while the command line is parsed, before any long work starts.

Used as argparse ``type=``: a bad path is exit 2 with one line naming the option and the
path, instead of a diagnosis thrown away at its end.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path


def _writable_dir(d: Path) -> str | None:
    if not d.exists():
        return f"its folder {d} does not exist"
    if not d.is_dir():
        return f"{d} is not a folder"
    if not os.access(d, os.W_OK | os.X_OK):
        return f"its folder {d} is not writable"
    return None


def output_file(text: str) -> Path:
    """A file the command will write: not a folder, in a writable folder that exists."""
    p = Path(text)
    if p.is_dir():
        raise argparse.ArgumentTypeError(f"{p} is a folder, not a file to write")
    if p.exists() and not os.access(p, os.W_OK):
        raise argparse.ArgumentTypeError(f"{p} exists and is not writable")
    why = _writable_dir(p.parent if str(p.parent) else Path("."))
    if why:
        raise argparse.ArgumentTypeError(f"cannot write {p}: {why}")
    return p


def output_dir(text: str) -> Path:
    """A folder the command will write into (made if missing): its parent must be writable."""
    p = Path(text)
    if p.exists():
        why = _writable_dir(p)
    else:
        why = _writable_dir(p.parent if str(p.parent) else Path("."))
    if why:
        raise argparse.ArgumentTypeError(f"cannot write into {p}: {why}")
    return p
