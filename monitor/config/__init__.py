"""Typed configuration of the daemon and the offline tools: YAML loading and validation at the
edge.
"""
