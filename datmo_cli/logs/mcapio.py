"""MCAP logs in one name: the topics (log.topics), reading (log.mcap_reader: the record scanner; log.channels: a
topic's messages, scans and odometry as arrays), writing (log.mcap_writer) and provenance (log.provenance).

The code lives in those modules; this one gathers their public names so that callers say `mcapio.read_run`,
`mcapio.LogWriter`, `mcapio.TOPIC_SCAN` and a test can replace one of them here.
"""

from __future__ import annotations

from .channels import (
    check_scan_channel,
    decode_scan_block,
    decoding,
    odometry_from_log,
    read_messages,
    read_odometry,
    read_run,
    run_from_log,
    several_channels,
)
from .mcap_reader import (
    MAGIC,
    MAX_CHUNK_BYTES,
    Channel,
    CorruptLogWarning,
    LogContents,
    TruncatedLogWarning,
    iter_messages,
    iter_stretches,
    read_log,
    summary,
)
from .mcap_writer import LogWriter
from .odometry_msgs import decode_odometry, encode_odometry
from .provenance import Provenance, sha256_of
from .scan import encode_scan, encode_scans
from .topics import (
    PRODUCER,
    QOS_YAML,
    QOS_YAML_LATCHED,
    TOPIC_FEATURES,
    TOPIC_GROUND_TRUTH,
    TOPIC_LANDMARKS,
    TOPIC_MARKERS_FEATURES,
    TOPIC_MARKERS_TRACKS,
    TOPIC_ODOM,
    TOPIC_SCAN,
    TOPIC_SEGMENTS,
    TOPIC_TELEGRAM,
    TOPIC_TF,
    TOPIC_TF_STATIC,
    TOPIC_TRACKS,
)

__all__ = [
    "MAGIC",
    "MAX_CHUNK_BYTES",
    "PRODUCER",
    "QOS_YAML",
    "QOS_YAML_LATCHED",
    "TOPIC_FEATURES",
    "TOPIC_GROUND_TRUTH",
    "TOPIC_LANDMARKS",
    "TOPIC_MARKERS_FEATURES",
    "TOPIC_MARKERS_TRACKS",
    "TOPIC_ODOM",
    "TOPIC_SCAN",
    "TOPIC_SEGMENTS",
    "TOPIC_TELEGRAM",
    "TOPIC_TF",
    "TOPIC_TF_STATIC",
    "TOPIC_TRACKS",
    "Channel",
    "CorruptLogWarning",
    "LogContents",
    "LogWriter",
    "Provenance",
    "TruncatedLogWarning",
    "check_scan_channel",
    "decode_odometry",
    "decode_scan_block",
    "decoding",
    "encode_odometry",
    "encode_scan",
    "encode_scans",
    "iter_messages",
    "iter_stretches",
    "odometry_from_log",
    "read_log",
    "read_messages",
    "read_odometry",
    "read_run",
    "run_from_log",
    "several_channels",
    "sha256_of",
    "summary",
]
