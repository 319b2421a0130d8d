"""Building a model from normal recordings (`monitor train`), with fault signatures from the
simulator.
"""
