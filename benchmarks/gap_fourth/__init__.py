"""A fourth plant for the sim-to-real benchmark of `monitor gap`, written apart.

Written from the user documentation only (docs/, `monitor gap --help`, the paper and
textbooks), never from monitor/, tests/ or the other benchmark plants: see README.md.
"""
