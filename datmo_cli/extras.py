"""Optional dependencies: the heavy packages a few commands need, installed with pyproject.toml's extras.

Every import of one goes through `require` first, so a missing package is one line naming the extra to
install, e.g. "datmo train-legs needs scikit-learn, which is not installed: pip install 'datmo[train]'".
`make install` (the dev extra) installs them all.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from .errors import DatmoError

# module -> (the distribution pip installs, the extra that brings it)
EXTRAS = {
    "sklearn": ("scikit-learn", "train"),
    "distributed": ("dask[distributed]", "dask"),
    "dask": ("dask[distributed]", "dask"),
    "fsspec": ("fsspec", "dask"),
    "pyarrow": ("pyarrow", "parquet"),
    "foxglove": ("foxglove-sdk", "live"),
    "websockets": ("websockets", "live"),
    "cyclonedds": ("cyclonedds", "node"),
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
        raise MissingExtraError(f"{for_} needs {package}, which is not installed: pip install 'datmo[{extra}]'") \
            from None
