"""SAE J1939 diagnostics of the monitor: DM1 (active DTCs) broadcast, DM2 on request.

``dtc``: the J1939-73 byte layout (DTC, lamps, DM payload) and the default SPN/FMI numbers;
``transport``: J1939-21 frame IDs, single frames and BAM; ``dm1``: when to send what.
Kept import-free so ``monitor.config.settings`` can take its defaults from ``dtc``.
"""
