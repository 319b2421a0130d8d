"""``monitor bench``: the performance measurements of issue 7, side by side in one run.

``data`` builds the inputs (simulated runs, models of a given size, a long candump log),
``grnn_bench`` times GRNN queries (cut-off kd-tree vs plain numba loop vs pyGRNN),
``live`` runs the daemon on a virtual bus in its own process, ``detect_bench`` times
``monitor detect`` against python-can + cantools + pyGRNN, ``footprint`` measures memory and
start-up, ``suite`` runs them all and judges each against its goal, ``report`` writes the
table.
"""
