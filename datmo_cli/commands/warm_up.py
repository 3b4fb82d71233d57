"""`datmo warm-up`: compile (or load) every numba kernel now, ahead of the first run: for images and CI."""

from __future__ import annotations

import click

from .options import quiet_option


@click.command(name="warm-up")
@quiet_option
def command() -> None:
    """Compile every numba kernel and cache it, so that the first run starts at once.

    The first run after an install or an update compiles datmo's kernels before it starts (minutes on two
    cores); run this instead when building an image or setting up CI, where the cache is then kept (numba's
    cache: beside the package, or NUMBA_CACHE_DIR). With the cache complete it only loads them (a second or
    so). Says on stderr that it compiles, draws a progress bar in a terminal, and prints how long it took.

    Example: datmo warm-up
    """
    import time

    from ..base.numba_runtime import cache_looks_stale, say_compiling
    from ..base.progress import bar, say
    from ..passes.warm import warm_up

    t0 = time.perf_counter()
    compiled = cache_looks_stale()  # before anything is compiled
    say_compiling()  # said once a process (the command line's first step has said it)
    with bar("compiling the numba kernels" if compiled else "loading the numba kernels", None, unit="steps") as b:
        warm_up(b.update)
    seconds = time.perf_counter() - t0
    done = "compiled" if compiled else "loaded"
    say(f"{done} the numba kernels in {seconds:.1f} s; later runs load them from the cache")
