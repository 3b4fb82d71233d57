"""datmo: detection and tracking of moving objects in 2D laser-scanner logs."""

__version__ = "0.1.0"

from .base.numba_light import numba_without_coverage as _numba_without_coverage
from .base.numba_runtime import choose_cache as _choose_cache

_choose_cache()  # a writable numba cache (else a private temporary one) before any kernel is declared
_numba_without_coverage()  # numba imported later skips coverage unless a coverage run is in progress
