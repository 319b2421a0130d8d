"""Judging samples: operating state, plausibility, gating, the alarm machine, the per-tick and
offline detectors.
"""
