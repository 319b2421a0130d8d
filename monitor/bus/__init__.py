"""The CAN side: opening a python-can bus, the receive thread and its recovery, replaying logs."""
