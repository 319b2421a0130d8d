"""Fixtures shared by the test modules, and the environment of the monitor processes they start."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

# Tests start `python -m monitor ...` processes; in a checkout that is not pip-installed these
# must import this tree's package, whatever their working directory.
os.environ["PYTHONPATH"] = os.pathsep.join(
    p for p in (str(REPO), os.environ.get("PYTHONPATH", "")) if p
)


@pytest.fixture(scope="session")
def shipped_config():
    """config/monitor.yaml as shipped (DBC, model and gating defaults)."""
    from monitor.config.settings import load_config

    return load_config()


@pytest.fixture(scope="session")
def model(shipped_config):
    """The shipped model, loaded once for the whole session (read-only in every test)."""
    from monitor.model.modelfile import load_model

    return load_model(shipped_config.model)
