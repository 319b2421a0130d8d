"""Which extra of ``pip install`` brings a missing module: a command that needs one says so
in one line (exit 2) instead of an ImportError traceback.

``pip install .`` is the controller's install (the daemon, replay, detect, watch, encode and
the demo); pyproject.toml's extras add the rest.
"""

from __future__ import annotations

#: top-level module -> the extra that installs it (pyproject.toml [project.optional-dependencies])
EXTRA_OF = {
    "distributed": "fleet",
    "dask": "fleet",
    "pyarrow": "fleet",
    "duckdb": "fleet",
    "plotly": "fleet",
    "jinja2": "fleet",
    "scipy": "analysis",
    "matplotlib": "analysis",
    "threadpoolctl": "analysis",
}


def missing_extra(exc: ModuleNotFoundError) -> str | None:
    """The one line for a module an extra installs, else None (a bug, left to propagate)."""
    top = (exc.name or "").split(".")[0]
    if top in ("numba", "llvmlite"):  # the controller's wheel: its kernels are compiled
        return (
            "needs numba (the controller's install carries only the daemon's and `monitor "
            "detect`'s kernels, compiled): pip install numba, or install this package from "
            "its sources"
        )
    extra = EXTRA_OF.get(top)
    if extra is None:
        return None
    return (
        f"needs the [{extra}] extra ({top} is not installed): "
        f"pip install 'hydraulic-monitor[{extra}]'"
    )


def require(*modules: str) -> None:
    """Raise ModuleNotFoundError (which ``main`` turns into the line above) for the first of
    ``modules`` not installed, before a command starts work that needs it later."""
    from importlib.util import find_spec

    for name in modules:
        if find_spec(name) is None:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
