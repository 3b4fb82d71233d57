"""What to say of a file given for an MCAP log that is not one: the kind of log it is (a CARMEN log, a g2o file,
a ROS 1 bag, judged by its first bytes as `datmo import` judges them) and the command that converts it."""

from __future__ import annotations

import zlib
from pathlib import Path

_KINDS = {"carmen": "a CARMEN log", "g2o": "a g2o file"}


def not_mcap(path: Path, head: bytes) -> str:
    """What follows "not an MCAP file" for a file that starts with `head`: the kind of log it is and how to
    convert it (`datmo import`), or " (bad magic bytes)" for content of no known kind."""
    import shlex

    from .importers.carmen_parse import sniff_text

    if head.startswith(b"\x1f\x8b"):  # gzip: a compressed text log, as datmo import takes them
        try:
            head = zlib.decompressobj(16 + zlib.MAX_WBITS).decompress(head, 65536)
        except zlib.error:
            return " (bad magic bytes)"
    kind = "a ROS 1 bag" if head.startswith(b"#ROSBAG V2.0") else _KINDS.get(sniff_text(head) or "")
    if kind is None:
        return " (bad magic bytes)"
    return f": it is {kind}; convert it with `datmo import {shlex.quote(str(path))} -o LOG.mcap` first"
