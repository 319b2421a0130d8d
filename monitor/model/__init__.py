"""The healthy model: GRNN and DGRNN kernels, the cut-off index, residual and J, threshold, model
file, training envelope.
"""
