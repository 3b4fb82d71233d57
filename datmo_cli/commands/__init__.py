"""One module per CLI command; each defines a single Click command."""

# types hands Click's context meta to progress.command_meta (the commands' shared state, e.g. --quiet)
from . import types as _types  # noqa: F401
