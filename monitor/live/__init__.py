"""The daemon: threads, loops, outputs on the bus, event log, black box, storage, disk writer,
systemd notify.
"""
