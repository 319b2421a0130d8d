"""The diagnosis as named stages (``pipeline.py``), each returning a frozen record
(``records.py``) that the next stage takes."""

from monitor.gap.diagnose.fitting import FIT_BUDGET_S, FIT_STEP_FACTOR, HELDOUT_STEP_FACTOR
from monitor.gap.diagnose.pipeline import diagnose
from monitor.gap.diagnose.records import Diagnosis

__all__ = ["FIT_BUDGET_S", "FIT_STEP_FACTOR", "HELDOUT_STEP_FACTOR", "Diagnosis", "diagnose"]
