"""What each array of a model file claims, checked before numpy believes it.

``np.load`` allocates the shape an ``.npy`` member's header declares before it reads a byte
of data: a 1 kB file whose header claims 8 TiB ends in a MemoryError traceback (or, where
the kernel overcommits, in a read that fills the memory).  Here every known member's header
is read alone and its size (shape x item size) must be the data the member holds.  The file
itself must be a regular file: a FIFO at the model's path would hang the start.
"""

from __future__ import annotations

import math
import os
import stat
import zipfile
from collections.abc import Container
from pathlib import Path

import numpy as np
from numpy.lib import format as npy

_READERS = {(1, 0): npy.read_array_header_1_0, (2, 0): npy.read_array_header_2_0}


def check_npz_headers(path: Path, names: Container[str]) -> None:
    """ValueError unless ``path`` is a regular file and each member in ``names`` holds as
    many data bytes as its header claims (nothing is allocated from a header)."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise ValueError("not a regular file")
    finally:
        os.close(fd)
    with zipfile.ZipFile(path) as zf:
        for info in zf.infolist():
            name = info.filename.removesuffix(".npy")
            if name not in names:
                continue
            with zf.open(info) as fh:
                version = npy.read_magic(fh)
                reader = _READERS.get(version)
                if reader is None:
                    raise ValueError(f"array {name}: .npy format {version} not expected")
                shape, _, dtype = reader(fh)
                data_bytes = info.file_size - fh.tell()
            claimed = math.prod(shape) * np.dtype(dtype).itemsize
            if claimed != data_bytes:
                raise ValueError(
                    f"array {name}: its header claims shape {shape} "
                    f"({claimed:,} bytes), the file holds {data_bytes:,}"
                )
