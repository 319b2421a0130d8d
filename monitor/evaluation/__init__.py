"""Evaluations: simulated fault runs (`monitor eval-sim`) and the real test rig (`monitor eval-
uci`).
"""
