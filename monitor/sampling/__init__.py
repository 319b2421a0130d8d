"""Decoded frames to rows: the 100 Hz sampler (live and bulk), the ring of rows, reading a
recording.
"""
