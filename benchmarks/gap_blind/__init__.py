"""Blind sim-to-real benchmark: a boom-loop plant written apart from ``monitor.sim``.

Seeds 1-99 are development seeds anyone may run.  The blind seed is chosen by the lead at
scoring time and is never used in development.  Generation is deterministic for a seed.
"""
