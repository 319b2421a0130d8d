"""Hydraulic fault monitor: DGRNN detection on CAN, a loop simulator and sim-to-real diagnosis."""

__version__ = "0.1.0"
