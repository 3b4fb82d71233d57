"""Loading datmo's cached numba kernels at a low fixed cost per process: every patch of numba's internals made
for speed, in one place, applied only on the numba releases they were written and tested against.

The range is NUMBA_RANGE (numba 0.68.1 up to, not including, 0.69): pyproject.toml bounds numba to it,
constraints.txt pins a release inside it and CI runs the tests there, once more with the patches off
(`make test-numba-plain`: DATMO_NUMBA_LIGHT=0, numba's own way). Outside the range, or with
DATMO_NUMBA_LIGHT=0, nothing here is applied and numba loads the kernels its way (about 0.5 s more a process,
outputs the same). The correctness patch (numba's cache keyed on every source file a kernel reads) is not here:
it is in numba_runtime (key_kernel_cache_on_sources) and holds whatever this module does.

The numba internals touched, and what breaks if they change (each patch checks what it relies on and leaves
numba alone when that is not there; a load that fails goes numba's way):
- `numba.core.caching.Cache.load_overload` (replaced for kernels defined under datmo_cli; `Cache._cache_file`,
  `_index_key`, `_impl.rebuild`, `_enabled`, `_guard_against_spurious_io_errors` are used as numba's own
  `_load_overload` uses them): loading without numba's registry refresh, which imports and installs every
  implementation numba has (a third of a one-scan `datmo track`). If the cache file's layout or the rebuild
  changes, a load fails and goes numba's way (slow, correct); if a kernel's code came to need something the
  refresh installs and loading does not, the kernel would fail at its first call (the kernel tests, light on).
- `numba.core.codegen.CPUCodeLibrary._unserialize`, `._shared_module` and `JitEngine.is_symbol_defined`,
  `._load_defined_symbols`, `._defined_symbols`: a cached kernel's LLVM bitcode (kept for inlining into kernels
  compiled later) parsed only when first needed. If these change shape the patch is not applied; if their
  meaning changes a kernel compiled after a light load could fail to link a symbol.
- `numba.core.environment._rebuild_env` (what unpickling a cached kernel's environments calls): the
  environment of one of numba's own functions whose module is not imported yet gets a stand-in globals dict
  rather than importing the module (numba.np.arrayobj, numba.cpython.unicode...: 25 ms). Only object mode
  reads an environment's globals, and no datmo kernel has object mode; if numba's nopython code came to read
  them, a kernel would fail at its first call (the kernel tests, light on).
- the `typeof` implementation numba registers for `numpy.ndarray`: a plain ndarray is typed without numba's
  `isinstance(val, np.ma.MaskedArray)`, which imports numpy.ma (10 ms); anything else goes to numba's. If
  numba's typing of arrays changes (a new Array attribute), dispatch would pick a wrong signature: the kernel
  tests would fail to find the cached kernels and compile.
- `numba.np.arraymath` imports scipy.linalg (0.3 s) to check for BLAS: while it is yet to be imported,
  `scipy.linalg.cython_blas` alone is loaded for the block (the check's answer is the same) and forgotten after.
- `numba.misc.coverage_support`, imported while numba is imported, imports coverage (65 ms) when it is
  installed: imported with coverage marked missing when no coverage run is in progress (an import hook).
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager

# the numba releases the patches were written and tested against: [low, high); pyproject.toml says the same
NUMBA_RANGE = ((0, 68, 1), (0, 69))
BLAS = "scipy.linalg.cython_blas"


def version_tuple(version: str) -> tuple[int, ...]:
    """The leading numbers of a release string ("0.68.1" -> (0, 68, 1); "0.69.0rc1" -> (0, 69, 0))."""
    out = []
    for part in version.split("."):
        digits = ""
        for ch in part:
            if not ch.isdigit():
                break
            digits += ch
        if not digits:
            break
        out.append(int(digits))
        if len(digits) != len(part):
            break
    return tuple(out)


def in_range(version: str) -> bool:
    """Whether a numba release is one the patches were tested against (NUMBA_RANGE)."""
    low, high = NUMBA_RANGE
    return low <= version_tuple(version) < high


def light_loading() -> bool:
    """Whether datmo's cached kernels load lightly: on the numba releases of NUMBA_RANGE, unless
    DATMO_NUMBA_LIGHT=0 asks for numba's own way."""
    import numba

    if os.environ.get("DATMO_NUMBA_LIGHT", "1") == "0":
        return False
    return in_range(numba.__version__)


def apply() -> bool:
    """Apply the light loading's patches when light_loading() says so (once; numba's CPU target and runtime
    are numba_runtime.prepare's). Returns whether they are applied."""
    if not light_loading():
        return False
    _load_cached_lightly()
    return True


def _load_cached_lightly() -> None:
    """Have datmo's cached kernels loaded without numba's registry refresh; any other kernel is loaded or
    compiled after it, as before.

    Before each load numba refreshes its typing and lowering registries (importing and installing every
    implementation it has: typed containers, random generators, cffi, jitclass...), which only compiling
    uses. Loading a cached kernel needs the runtime (prepare), the symbols its code links to (the C helpers
    and the runtime's, registered with the target; the hash secret's, by numba.cpython.hashing) and the
    modules of its environments, which unpickling imports. A datmo kernel that is not cached, or whose light
    load fails, goes numba's way: refresh, load or compile. Other packages' kernels always go numba's way.
    Either way one numba module, numba.np.arraymath, checks for BLAS when imported: scipy.linalg.cython_blas
    is then loaded on its own for the moment (see the module docstring)."""
    from numba.core import caching

    original = caching.Cache.load_overload
    if getattr(original, "datmo_light", False):
        return
    package = os.path.dirname(os.path.abspath(__file__)) + os.sep

    def load_overload(self, sig, target_context):
        code = getattr(getattr(self, "_py_func", None), "__code__", None)
        with _blas_alone():
            if code is not None and os.path.abspath(code.co_filename).startswith(package):
                try:
                    with self._guard_against_spurious_io_errors():
                        cres = _load_light(self, sig, target_context)
                    if cres is not None:
                        return cres
                except Exception:  # numba's way below
                    pass
            return original(self, sig, target_context)

    load_overload.datmo_light = True  # type: ignore[attr-defined]
    caching.Cache.load_overload = load_overload  # type: ignore[method-assign]
    _defer_shared_modules()
    _lazy_numba_environments()
    _plain_arrays_typed_directly()


def _lazy_numba_environments() -> None:
    """Unpickling a cached kernel rebuilds the environment of every function compiled into it, importing the
    function's module for its globals; for numba's own modules not imported yet, a stand-in globals dict
    ({"__name__": module}) instead (only object mode reads the globals; see the module docstring)."""
    from numba.core import environment

    original = environment._rebuild_env
    if getattr(original, "datmo_light", False):
        return

    def _rebuild_env(modname, consts, env_name):
        if not (isinstance(modname, str) and modname.startswith("numba.") and modname not in sys.modules):
            return original(modname, consts, env_name)
        env = environment.lookup_environment(env_name)
        if env is not None:
            return env
        env = environment.Environment({"__name__": modname})
        env.consts[:] = consts
        env.env_name = env_name
        environment.Environment._memo[env_name] = env
        return env

    _rebuild_env.datmo_light = True  # type: ignore[attr-defined]
    environment._rebuild_env = _rebuild_env


def _plain_arrays_typed_directly() -> None:
    """numba's typeof of a plain numpy.ndarray as numba computes it, without its masked-array check (which
    imports numpy.ma); any other array (a subclass, an unsupported dtype) goes to numba's own."""
    import numpy as np
    from numba.core import types
    from numba.core.typing import typeof
    from numba.np import numpy_support

    original = typeof.typeof_impl.dispatch(np.ndarray)
    if getattr(original, "datmo_light", False):
        return

    def _typeof_ndarray(val, c):
        if type(val) is not np.ndarray:
            return original(val, c)
        try:
            dtype = numpy_support.from_dtype(val.dtype)
        except Exception:
            return original(val, c)
        return types.Array(dtype, val.ndim, numpy_support.map_layout(val), readonly=not val.flags.writeable)

    _typeof_ndarray.datmo_light = True  # type: ignore[attr-defined]
    _typeof_ndarray.__wrapped__ = original  # type: ignore[attr-defined]
    typeof.typeof_impl.register(np.ndarray)(_typeof_ndarray)


_DEFER = threading.local()  # .entry: the entry point's name while a datmo kernel's code is being loaded


def _load_light(cache, sig, target_context):
    """A cached kernel as Cache._load_overload loads it (None when not cached), its code's bitcode parsed
    only when needed (_defer_shared_modules)."""
    if not cache._enabled:
        return None
    data = cache._cache_file.load(cache._index_key(sig, target_context.codegen()))
    if data is None:
        return None
    fndesc = data[1] if isinstance(data, tuple) and len(data) > 1 else None  # CompileResult._reduce's
    _DEFER.entry = getattr(fndesc, "llvm_cpython_wrapper_name", None)
    try:
        return cache._impl.rebuild(target_context, data)
    finally:
        _DEFER.entry = None


def _defer_shared_modules() -> None:
    """Loading a cached kernel, numba parses the LLVM bitcode stored beside its machine code (to inline it
    into kernels compiled later) and reads every symbol it defines: about half the load of a big kernel
    (track_block), and of no use to running it. In `_load_light` the bitcode is kept as it is and parsed
    the first time anything asks for the module, or for a symbol numba does not know yet (numba's own way,
    only later); the one symbol a load looks up, the kernel's entry point, which its code defines, is
    recorded at once. Nothing changes where numba's code is not as expected."""
    import llvmlite.binding as ll
    from numba.core import codegen

    library, engine = getattr(codegen, "JITCodeLibrary", None), getattr(codegen, "JitEngine", None)
    unserialize = codegen.CPUCodeLibrary.__dict__.get("_unserialize")
    if library is None or engine is None or not isinstance(unserialize, classmethod):
        return
    if not all(hasattr(engine, a) for a in ("is_symbol_defined", "_load_defined_symbols")):
        return
    original_unserialize, original_defined = unserialize.__func__, engine.is_symbol_defined

    class SharedModule:
        """CPUCodeLibrary._shared_module, parsed from its bitcode when first read."""

        def __get__(self, lib, owner=None):
            if lib is None:
                return self
            value = lib.__dict__.get("_datmo_shared", lib.__dict__.get("_shared_module"))
            if isinstance(value, bytes):
                value = lib.__dict__["_datmo_shared"] = ll.parse_bitcode(value)
                lib._codegen._engine._load_defined_symbols(value)
            return value

        def __set__(self, lib, value) -> None:
            lib.__dict__["_datmo_shared"] = value

    def _unserialize(cls, codegen_, state):
        name, kind, data = state
        entry = getattr(_DEFER, "entry", None)
        if kind != "object" or entry is None or not issubclass(cls, library):
            return original_unserialize(cls, codegen_, state)
        object_code, shared_bitcode = data
        self = codegen_.create_library(name)
        self.enable_object_caching()
        self._set_compiled_object(object_code)
        self._shared_module = bytes(shared_bitcode)  # parsed when first read (SharedModule)
        self._finalize_final_module()
        ee = self._codegen._engine
        ee.__dict__.setdefault("_datmo_pending", []).append(self)
        ee._defined_symbols.add(entry)
        return self

    def is_symbol_defined(self, name):
        pending = self.__dict__.get("_datmo_pending")
        while pending and name not in self._defined_symbols:
            _ = pending.pop()._shared_module  # parses it, recording its symbols
        return original_defined(self, name)

    codegen.CPUCodeLibrary._shared_module = SharedModule()
    codegen.CPUCodeLibrary._unserialize = classmethod(_unserialize)  # type: ignore[method-assign, assignment]
    engine.is_symbol_defined = is_symbol_defined


@contextmanager
def _blas_alone() -> Iterator[None]:
    """scipy.linalg.cython_blas loaded on its own for the block when numba.np.arraymath, which imports it
    to check for BLAS, is yet to be imported and scipy.linalg is not; forgotten after it."""
    if "numba.np.arraymath" in sys.modules or "scipy.linalg" in sys.modules:
        yield
        return
    loaded = _load_blas_alone()
    try:
        yield
    finally:
        if loaded is not None and sys.modules.get(BLAS) is loaded and "scipy.linalg" not in sys.modules:
            del sys.modules[BLAS]


def _load_blas_alone():
    """scipy.linalg.cython_blas loaded without its package (registered in sys.modules), or None when scipy
    is missing or the module cannot be found or loaded that way (numba then checks as it always does)."""
    import importlib.machinery
    import importlib.util
    from pathlib import Path

    try:
        spec = importlib.util.find_spec("scipy")
        if spec is None or not spec.submodule_search_locations:
            return None
        folder = Path(next(iter(spec.submodule_search_locations))) / "linalg"
        for suffix in importlib.machinery.EXTENSION_SUFFIXES:
            path = folder / f"cython_blas{suffix}"
            if path.is_file():
                break
        else:
            return None
        blas_spec = importlib.util.spec_from_file_location(BLAS, path)
        if blas_spec is None or blas_spec.loader is None:
            return None
        module = importlib.util.module_from_spec(blas_spec)
        sys.modules[BLAS] = module
        blas_spec.loader.exec_module(module)
        return module
    except Exception:  # any failure: numba imports scipy.linalg as usual
        sys.modules.pop(BLAS, None)
        return None


class _NumbaWithoutCoverage:
    """numba imports `coverage` (about 65 ms) when it is installed, to report the lines of the kernels it
    compiles to a coverage run in progress. With no coverage run in this process ("coverage" not imported
    yet: a run under coverage, pytest-cov's too, imports it first), numba's module for that
    (numba.misc.coverage_support) is imported with coverage marked missing, and so finds none in progress,
    as it would anyway; coverage itself stays importable. A finder on sys.meta_path, used once."""

    NAME = "numba.misc.coverage_support"

    def find_spec(self, name, path, target=None):
        if name != self.NAME:
            return None
        sys.meta_path.remove(self)
        numba = sys.modules.get("numba")  # being imported: its __version__ is set before this module is asked for
        if "coverage" in sys.modules or not in_range(getattr(numba, "__version__", "0")):
            return None
        if os.environ.get("DATMO_NUMBA_LIGHT", "1") == "0":
            return None
        import importlib.abc
        import importlib.util

        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None:
            return spec
        loader = spec.loader

        class Loader(importlib.abc.Loader):
            def create_module(self, spec):
                return loader.create_module(spec)

            def exec_module(self, module):
                sys.modules["coverage"] = None  # type: ignore[assignment]  # `import coverage` raises ImportError
                try:
                    loader.exec_module(module)
                finally:
                    if sys.modules.get("coverage", 0) is None:
                        del sys.modules["coverage"]

        spec.loader = Loader()
        return spec


def numba_without_coverage() -> None:
    """Spare numba's import of coverage when no coverage run is in progress (_NumbaWithoutCoverage), on the
    numba releases of NUMBA_RANGE and unless DATMO_NUMBA_LIGHT=0; call before numba is imported."""
    if "coverage" in sys.modules or "numba.misc.coverage_support" in sys.modules:
        return
    if not any(isinstance(f, _NumbaWithoutCoverage) for f in sys.meta_path):
        sys.meta_path.insert(0, _NumbaWithoutCoverage())
