"""A detection and fleet benchmark on a boom-loop plant written apart from monitor/.

Its author read only the user-facing contracts (signal names, CSV columns, the fleet layout,
the CLI); the plant's formulations are its own. See README.md beside this file.
"""
