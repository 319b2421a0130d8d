"""Detector speed on the shipped model and logs (pytest-benchmark; run with
``python -m pytest benchmarks --benchmark-enable``).  ``monitor bench`` measures the issue's
figures (20,000 patterns, 1-hour log, live daemon); these cases watch the same paths at the
shipped size, side by side: cut-off vs exact GRNN per tick, bulk vs frame-by-frame log
reading, and ``detect`` on a shipped 90 s log.
"""

from __future__ import annotations

import numpy as np
import pytest

from monitor.detection.offline import detect
from monitor.model.dgrnn import TickPredictor
from monitor.model.modelfile import load_model
from monitor.resources import resource_path
from monitor.sampling.bulk import recording_from_candump_bulk
from tests.naive_frames import recording_from_candump  # the frame-by-frame reference

MODEL = load_model(resource_path("config", "boom_default.model.npz"))
LOG = resource_path("replay", "spool_wear.log")


@pytest.mark.parametrize("exact", [False, True], ids=["cutoff", "exact"])
@pytest.mark.parametrize("p", [1, 10])
def test_tick_prediction(benchmark, p, exact):
    rec = recording_from_candump_bulk(LOG)
    spec = MODEL.spec
    z = MODEL.normalizer.transform(
        np.column_stack([rec[v] for v in spec.variables]), spec.variables
    )
    pred = TickPredictor(MODEL.dgrnn, p, exact=exact)
    window = np.ascontiguousarray(z[2000 : 2000 + pred.rows_needed])
    pred.predict(window)
    benchmark(pred.predict, window)


@pytest.mark.parametrize(
    "reader", [recording_from_candump_bulk, recording_from_candump], ids=["bulk", "frame-by-frame"]
)
def test_read_log(benchmark, reader):
    reader(LOG)
    benchmark.pedantic(reader, args=(LOG,), rounds=3, iterations=1)


def test_detect_shipped_log(benchmark):
    rec = recording_from_candump_bulk(LOG)
    detect(MODEL, rec)
    benchmark.pedantic(detect, args=(MODEL, rec), rounds=3, iterations=1)
