"""Getting numba ready to load cached kernels at a low fixed cost per process, and somewhere to cache them.

`choose_cache` (run when datmo_cli is imported, before numba is) finds numba a writable cache: numba caches a
kernel beside its source (a __pycache__ folder) or in the user's cache folder (~/.cache/numba), and with
neither writable (a read-only install run by a user without a writable HOME) every `@njit(cache=True)`
raised "cannot cache function ...: no locator available" at import. Then the cache goes to a private folder
in the temporary folder (NUMBA_CACHE_DIR), or, with no writable temporary folder either, kernels are compiled
in each process and not cached.

`prepare` gets numba's CPU target and runtime ready once a process and applies the light loading of
datmo's cached kernels (numba_light: every patch of numba's internals made for speed, applied only on the numba
releases it was tested against). What stays here works on any numba: where the cache goes, whether it looks
stale (`cache_looks_stale`, without importing numba), the line that says kernels compile, and the correctness
part: numba's cache stamp of a datmo kernel keyed on every source file a kernel reads
(`key_kernel_cache_on_sources`, which patches numba's `_SourceFileBackedLocatorMixin.get_source_stamp`; with a
numba without that hook, numba's own stamp: an edit to state.py alone would then not recompile, and
tests/test_numba_cache_stamp.py fails).
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

KERNEL_PACKAGES = ("perception", "tracking", "sim")  # the sub-packages whose modules hold cached kernels


def choose_cache() -> str | None:
    """Make sure numba has somewhere to cache datmo's kernels (module docstring): nothing to do when NUMBA_CACHE_DIR
    is set, the JIT is off, every kernel package's __pycache__ is writable or the user's cache folder is; else
    NUMBA_CACHE_DIR becomes a private folder (mode 0700, owned by this user) in the temporary folder, whose path
    is returned; with none, caching is turned off (numba compiles in each process). A few stat calls; numba is
    imported only in that last case."""
    if os.environ.get("NUMBA_CACHE_DIR") or os.environ.get("NUMBA_DISABLE_JIT", "0") != "0":
        return None
    package = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    if all(_usable(os.path.join(package, p, "__pycache__")) for p in KERNEL_PACKAGES) or _usable(_user_cache()):
        return None
    folder = _private_temp()
    if folder is None:
        _without_cache()
        return None
    os.environ["NUMBA_CACHE_DIR"] = folder
    config = sys.modules.get("numba.core.config")
    if config is not None:  # numba read the environment already: tell it too
        config.CACHE_DIR = folder
    return folder


def _usable(path: str) -> bool:
    """Whether a folder could be used for a cache: it is a writable folder, or the nearest part of its path that
    exists is one (numba makes the rest)."""
    while not os.path.lexists(path):
        parent = os.path.dirname(path)
        if parent == path:
            return False
        path = parent
    return os.path.isdir(path) and os.access(path, os.W_OK | os.X_OK)


def _user_cache() -> str:
    """numba's user-wide cache folder (its appdirs' user_cache_dir for "numba")."""
    if sys.platform == "darwin":
        return os.path.expanduser("~/Library/Caches/numba")
    if sys.platform.startswith("win"):
        return os.path.join(os.environ.get("LOCALAPPDATA", os.path.expanduser("~")), "numba", "Cache")
    return os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "numba")


def _private_temp() -> str | None:
    """A cache folder in the temporary folder only this user can write (numba's cache files are loaded as
    pickles: another user's would run their code): datmo-numba-cache-UID, kept between runs, or a fresh one
    when that name is taken by something else; None when there is no writable temporary folder."""
    import stat
    import tempfile

    try:
        uid = os.getuid() if hasattr(os, "getuid") else None
        path = os.path.join(tempfile.gettempdir(), f"datmo-numba-cache-{uid if uid is not None else 'user'}")
        try:
            os.mkdir(path, 0o700)
        except FileExistsError:
            pass
        st = os.lstat(path)
        if (
            stat.S_ISDIR(st.st_mode)
            and (uid is None or st.st_uid == uid)
            and not st.st_mode & 0o077
            and os.access(path, os.W_OK | os.X_OK)
        ):
            return path
        return tempfile.mkdtemp(prefix="datmo-numba-cache-")
    except (OSError, FileNotFoundError):
        return None


def _without_cache() -> None:
    """Kernels declared with cache=True compile without a cache when numba finds nowhere to keep one."""
    from numba.core import caching, dispatcher

    original = dispatcher.Dispatcher.enable_caching
    if getattr(original, "datmo_fallback", False):
        return

    def enable_caching(self) -> None:
        try:
            original(self)
        except RuntimeError:  # "cannot cache function ...: no locator available"
            self._cache = caching.NullCache()

    enable_caching.datmo_fallback = True
    dispatcher.Dispatcher.enable_caching = enable_caching


_READY = False
_LOCK = threading.Lock()


def prepare() -> None:
    """Get numba ready to load datmo's cached kernels, once: its CPU target and runtime, and a light way to
    load them (numba_light)."""
    global _READY
    if _READY:
        return
    with _LOCK:  # threads of one Dask worker may start stages at once
        if _READY:
            return
        say_compiling()  # before numba's import: the line comes at once
        import numba.cpython.hashing  # noqa: F401  # its import gives compiled code the hash secret's symbols
        from numba.core.registry import cpu_target
        from numba.core.runtime import rtsys

        rtsys.initialize(cpu_target.target_context)  # the runtime (NRT) every kernel allocates with
        from . import numba_light

        numba_light.apply()  # the light loading, on the numba releases it was tested against
        _READY = True


def _cache_folder(folder: str) -> str:
    """Where numba keeps the cache of the kernels of the modules in `folder`: NUMBA_CACHE_DIR when set, else the
    folder's __pycache__ when it is writable, else the user's cache folder (numba's locators, in that order; the
    two outside the package under the name numba gives them: the folder's name and the SHA-1 of its path)."""
    import hashlib

    given = os.environ.get("NUMBA_CACHE_DIR")
    subpath = f"{os.path.basename(folder)}_{hashlib.sha1(folder.encode()).hexdigest()}"
    if given:
        return os.path.join(os.path.abspath(given), subpath)
    tree = os.path.join(folder, "__pycache__")
    if _usable(tree):
        return tree
    return os.path.join(_user_cache(), subpath)


def cache_looks_stale() -> bool:
    """Whether a stage would compile kernels rather than load them from numba's cache, judged from the index
    files (*.nbi) where numba keeps datmo's cache (_cache_folder: the package's __pycache__ folders,
    NUMBA_CACHE_DIR or the user's cache folder) without importing numba: none at all (the first run after an
    install), or a module edited after its kernels were last cached (numba keys its cache on the source's time
    and size). A kernel never yet called in a module whose others are cached is not seen; it compiles when
    first called."""
    if os.environ.get("NUMBA_DISABLE_JIT", "0") != "0":
        return False
    package = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    newest: dict[str, float] = {}
    for name in KERNEL_PACKAGES:
        folder = os.path.join(package, name)
        try:
            entries = list(os.scandir(_cache_folder(folder)))
        except OSError:
            continue
        for e in entries:
            if e.name.endswith(".nbi"):
                source = os.path.join(folder, e.name.split(".", 1)[0] + ".py")
                newest[source] = max(newest.get(source, 0.0), e.stat().st_mtime)
    if not newest:
        return True
    try:
        return any(os.stat(source).st_mtime > cached for source, cached in newest.items())
    except OSError:
        return True


# ------------------------------------------------------------------------------------ compiling notice
# Saying that numba is compiling: the first run after an install compiles the kernels (minutes) before a stage's
# first progress report, which otherwise comes within milliseconds. One process compiling every kernel of
# warm.warm_up with a cold cache, on the project's 2-core VM: 137 s user + 15 s system CPU (the hall's stages
# nearly all of it; scan matching 11 s, the simulator 5 s), which is its wall time on an idle core; a VM shared
# with other jobs takes longer, a desktop less.
COMPILE_SECONDS = 150
NOTICE = f"compiling the numba kernels (once after an install or an update: about {COMPILE_SECONDS / 60:.1f} min)"
_SAID = False


def say_compiling(force: bool = False) -> bool:
    """Say on stderr, once a process, terminal or not, that the kernels are about to compile (cache_looks_stale;
    `force`: without asking it), with how long that takes and how to do it ahead (`datmo warm-up`); not under
    --quiet, nor with DATMO_COMPILE_NOTICE=0 in the environment. Returns whether the line was written."""
    global _SAID
    if _SAID or os.environ.get("DATMO_COMPILE_NOTICE") == "0" or not (force or cache_looks_stale()):
        return False
    _SAID = True
    progress = sys.modules.get("datmo_cli.base.progress")  # loaded by any command (its --quiet); not imported here
    if progress is not None and progress.quiet():
        return False
    sys.stderr.write(f"datmo: {NOTICE}; cached for the next runs (`datmo warm-up` compiles them ahead)\n")
    sys.stderr.flush()
    return True


def _timer(delay: float, action: Callable[[], None]) -> threading.Timer:
    timer = threading.Timer(delay, action)
    timer.daemon = True
    timer.start()
    return timer


@contextmanager
def said_if_slow(delay: float = 2.0) -> Iterator[None]:
    """Print NOTICE on stderr when the block is still running after `delay` s (a cache hit loads the kernels
    in about a second; only a compilation takes longer)."""
    import sys

    def notice() -> None:
        sys.stderr.write(f"{NOTICE}...\n")
        sys.stderr.flush()

    timer = _timer(delay, notice)
    try:
        yield
    finally:
        timer.cancel()


@contextmanager
def compile_notice(bar, task, delay: float = 2.0, *, armed: bool = True) -> Iterator[Callable[[int, int], None]]:
    """A progress callback (done, total) for `task` of the rich Progress `bar`. A report of 0 done starts a
    stage (and `armed` starts one at entry); when the stage's next report is more than `delay` s away,
    the task's description gets NOTICE appended until that report comes."""
    lock = threading.Lock()
    state = {"timer": None, "label": None}

    def late() -> None:
        with lock:
            if state["timer"] is None:
                return
            label = next((t.description for t in bar.tasks if t.id == task), "")
            state["label"] = label
            bar.update(task, description=f"{label}: {NOTICE}")

    def arm() -> None:
        state["timer"] = _timer(delay, late)

    def disarm() -> None:
        timer = state["timer"]
        if timer is not None:
            timer.cancel()
            state["timer"] = None
        if state["label"] is not None:
            bar.update(task, description=state["label"])
            state["label"] = None

    def report(done: int, total: int) -> None:
        with lock:
            disarm()
            bar.update(task, completed=done, total=total)
            if done == 0:
                arm()

    if armed:
        arm()
    try:
        yield report
    finally:
        with lock:
            disarm()


# ------------------------------------------------------------------------------- what a cached kernel read
# numba keys a cached kernel on its own source file's time and size only, but a datmo kernel also compiles in
# the constants it imports (tracking/state.py's column and parameter indices, the message codes of logs/vocabulary
# read from msg/*.msg) and the kernels of other modules it calls. An edit there alone (a checkout that changes
# state.py but not _kernels.py) would load code compiled against the old values: silently wrong results. So the
# stamp of every datmo kernel also covers every file any kernel reads (KERNEL_SOURCES): one changes, all recompile.
KERNEL_SOURCES = ("tracking/*.py", "perception/*.py", "sim/*.py", "logs/vocabulary.py", "base/libm.py", "msg/*.msg")
_KEYED = False
_SOURCES_STAMP: tuple | None = None


def sources_stamp(package: str | None = None) -> tuple:
    """(relative path, mtime ns, size) of every file of KERNEL_SOURCES under the package folder, sorted; read once
    a process."""
    global _SOURCES_STAMP
    if _SOURCES_STAMP is not None and package is None:
        return _SOURCES_STAMP
    import glob

    root = package or os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = []
    for pattern in KERNEL_SOURCES:
        for path in sorted(glob.glob(os.path.join(root, pattern))):
            st = os.stat(path)
            out.append((os.path.relpath(path, root), st.st_mtime_ns, st.st_size))
    stamp = tuple(out)
    if package is None:
        _SOURCES_STAMP = stamp
    return stamp


def key_kernel_cache_on_sources() -> None:
    """Make numba's cache stamp of every kernel defined under datmo_cli cover KERNEL_SOURCES as well as its own
    file (see above), once a process; call before the kernels are declared (each kernel module does). Other
    packages' kernels keep numba's stamp. A numba without the hook this patches keeps its own (and datmo's
    tests say so)."""
    global _KEYED
    if _KEYED:
        return
    _KEYED = True
    try:
        from numba.core import caching

        mixin = caching._SourceFileBackedLocatorMixin
        original = mixin.get_source_stamp
    except (ImportError, AttributeError):
        return
    package = os.path.dirname(os.path.dirname(os.path.abspath(__file__))) + os.sep

    def get_source_stamp(self):
        stamp = original(self)
        if not os.path.abspath(getattr(self, "_py_file", "")).startswith(package):
            return stamp
        return stamp, sources_stamp()

    mixin.get_source_stamp = get_source_stamp
