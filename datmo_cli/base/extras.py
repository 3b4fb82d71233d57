"""Optional dependencies: the heavy packages a few commands need, installed with pyproject.toml's extras.

A plain `pip install datmo-cli` holds what record, import, segment, features, track, run, report, info and
export (CSV, NDJSON) need. Every import of an optional package goes through `require` first, so a missing one
is one line naming the extra to install, e.g. "training a leg model needs scikit-learn, which is not installed:
pip install 'datmo-cli[train]'". `pip install 'datmo-cli[all]'` installs every extra; `make install` (the dev
extra) installs them all and the test tools.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from .errors import DatmoError

DISTRIBUTION = "datmo-cli"  # the name on the package index (`datmo` there is an unrelated project)

# module -> (the distribution pip installs, the extra that brings it)
EXTRAS = {
    "motmetrics": ("motmetrics", "eval"),
    "trackeval": ("trackeval", "eval"),
    "scipy": ("scipy", "eval"),
    "matplotlib": ("matplotlib", "plot"),
    "sklearn": ("scikit-learn", "train"),
    "distributed": ("dask[distributed]", "dask"),
    "dask": ("dask[distributed]", "dask"),
    "fsspec": ("fsspec", "dask"),
    "pyarrow": ("pyarrow", "parquet"),
    "foxglove": ("foxglove-sdk", "live"),
    "websockets": ("websockets", "live"),
    "cyclonedds": ("cyclonedds", "node"),
    "pandas": ("pandas", "pandas"),
}


class MissingExtraError(DatmoError):
    """An optional package a command needs is not installed; the message names the extra to install."""


def require(module: str, for_: str) -> ModuleType:
    """Import `module` (a key of EXTRAS, or a submodule of one: "pyarrow.parquet") and return it, or raise
    MissingExtraError saying that `for_` (what needs it: "writing Parquet") needs it and how to install it."""
    package, extra = EXTRAS[module.partition(".")[0]]
    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingExtraError(
            f"{for_} needs {package}, which is not installed: pip install '{DISTRIBUTION}[{extra}]'"
        ) from None
