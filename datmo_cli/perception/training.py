"""Training and honest evaluation of the learned leg detector (`datmo train-legs`, `make legs-model`).

Data: labelled recordings (scans with the positions of the legs seen in each: leg_tracker's positive bags,
a geometry_msgs/PoseArray per scan in the laser frame, matched to scans by log time) and empty recordings
(scans with no people: every segment is a negative). Each scan is cut into clusters, by default as leg_tracker
does (`legs.gap_clusters`: a gap of more than 0.13 m between consecutive returns; the labels are the centroids of
exactly such clusters) or by datmo's own segmentation (`features.segment_run`); the choice is recorded in the
model's provenance["clusters"] (see `legs.model_clusters`). Each cluster gets the features of
`legs.cluster_features` and a label: a leg when a labelled leg lies within `MATCH_RADIUS_M` of its centroid.

Evaluation is leave-one-recording-out: each labelled recording is held out in turn together with one empty
recording (cycling through them), the model is trained on the others only, and its decision threshold is
chosen on the training recordings only (inner leave-one-out). Figures are per cluster, on clusters within
`METRIC_RANGE_M` of the scanner, beside the paper's circle rule on the same clusters.

scikit-learn is imported only inside the functions that fit (the `train` extra). Units: metres, sensor frame
of each scan (x forward, y left), times in ns.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..errors import DatmoError, GeometryError, InputError
from ..extras import require
from ..log.scan import ScanGeometry, ScanRun
from .params import FeatureParams

MATCH_RADIUS_M = 0.15  # a segment is a leg when a labelled leg is this close to its centroid
LABEL_WINDOW_NS = 50_000_000  # a scan takes the label message logged nearest to it, within this
METRIC_RANGE_M = 5.0  # figures count clusters whose centroid is at most this far from the scanner
CIRCLE_LEG_RADIUS_M = 0.13  # the paper's rule: a circle of at most this radius is a leg
DEFAULT_LABELS_TOPIC = "/leg_cluster_positions"
POSE_ARRAY_TYPES = ("geometry_msgs/msg/PoseArray", "geometry_msgs/PoseArray")
EMPTY_FALSE_BUDGET = 0.5  # false legs per empty scan allowed when choosing the threshold (the target)
SEGMENT_CLUSTERS = {"method": "segments"}  # datmo's own segments (features.segment_run)
GAP_CLUSTERS = {"method": "gap", "gap": 0.13, "min_points": 3}  # leg_tracker's clusters (legs.gap_clusters)
DEFAULT_CLUSTERS = GAP_CLUSTERS

#: progress(description, done, total)
Progress = Callable[[str, int, int], None]


def require_sklearn():
    """scikit-learn, or MissingExtraError naming the train extra."""
    return require("sklearn", for_="training a leg model")


# ------------------------------------------------------------------------------------------------ reading


@dataclass
class Recording:
    """One scanner's scans from one file. `legs[k]` holds scan k's labelled legs (K x 2, metres, laser frame);
    `legs` is None for an empty recording (no people: every segment is a negative)."""

    name: str
    path: Path
    topic: str
    run: ScanRun
    legs: list[np.ndarray] | None = None

    @property
    def labelled(self) -> bool:
        return self.legs is not None


def thinned(rec: Recording, step: int = 2) -> Recording:
    """`rec` as a scanner `step` times coarser would see it: every step-th beam (from the first), the angle
    increment step times as wide; the labels (laser frame) are unchanged."""
    import dataclasses

    g = rec.run.geometry
    ranges = rec.run.ranges[:, ::step]
    geometry = dataclasses.replace(g, angle_increment=g.angle_increment * step, n_beams=ranges.shape[1])
    return Recording(
        f"{rec.name} thinned {step}x", rec.path, rec.topic, ScanRun(rec.run.stamps, ranges, geometry), rec.legs
    )


@dataclass
class _Raw:
    """What a file holds on the topics read: scans (with log times) and PoseArray messages (log time, K x 2)."""

    topics: dict[str, tuple[str, int]]
    runs: dict[str, tuple[ScanRun, np.ndarray]] = field(default_factory=dict)
    poses: tuple[np.ndarray, list[np.ndarray]] | None = None


def _poses_xy(msg) -> np.ndarray:
    return np.array([[p.position.x, p.position.y] for p in msg.poses], np.float64).reshape(-1, 2)


def _run_of(
    label: str, topic: str, stamps: list[int], ranges: list[np.ndarray], geoms: list[ScanGeometry], log_times: list[int]
) -> tuple[ScanRun, np.ndarray]:
    if not ranges:
        raise InputError(f"{label}: {topic} has no messages")
    g0 = geoms[0]
    for i, g in enumerate(geoms):
        if not g.same_beams(g0):
            raise GeometryError(f"{label}: {topic} geometry changes at scan {i}: {g0.describe()} -> {g.describe()}")
    return ScanRun(np.array(stamps, np.int64), np.stack(ranges), g0), np.array(log_times, np.int64)


def _read_bag(path: Path, scan_topics: Callable[[dict], list[str]], pose_topic: str | None) -> _Raw:
    """Scans and poses of a ROS 1 bag or ROS 2 bag folder (rosbags' AnyReader)."""
    from ..log.importers.rosbag import open_bag, scan_geometry, scan_stamp

    label = str(path)
    reader, topics = open_bag(path)
    try:
        out = _Raw(topics)
        wanted = scan_topics(topics)
        want_poses = pose_topic is not None and topics.get(pose_topic, ("", 0))[0] in POSE_ARRAY_TYPES
        conns = [c for c in reader.connections if c.topic in wanted or (want_poses and c.topic == pose_topic)]
        scans = {t: ([], [], [], []) for t in wanted}
        pose_t, pose_xy = [], []
        for conn, log_time, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic in scans:
                s = scans[conn.topic]
                s[0].append(scan_stamp(msg, log_time))
                s[1].append(np.asarray(msg.ranges, np.float32))
                s[2].append(scan_geometry(msg))
                s[3].append(log_time)
            else:
                pose_t.append(log_time)
                pose_xy.append(_poses_xy(msg))
    except (InputError, DatmoError):
        raise
    except Exception as exc:  # corrupt chunks, unknown message definitions
        raise InputError(f"{label}: cannot read bag ({type(exc).__name__}: {exc})") from None
    finally:
        reader.close()
    out.runs = {t: _run_of(label, t, *s) for t, s in scans.items()}
    if want_poses:
        out.poses = (np.array(pose_t, np.int64), pose_xy)
    return out


def _read_mcap(path: Path, scan_topics: Callable[[dict], list[str]], pose_topic: str | None) -> _Raw:
    """Scans and poses of a single MCAP file (CDR, ROS 2 types)."""
    from ..log import mcapio, types

    head = mcapio.summary(path)
    topics = {c.topic: (c.msgtype, c.count) for c in head.channels.values()}
    out = _Raw(topics)
    wanted = scan_topics(topics)
    want_poses = pose_topic is not None and topics.get(pose_topic, ("", 0))[0] in POSE_ARRAY_TYPES
    log = mcapio.read_log(path, topics=wanted + ([pose_topic] if want_poses else []))
    for t in wanted:
        run = mcapio.run_from_log(log, t)
        log_times = np.array(log.messages[t][0], np.int64)
        zero = run.stamps == 0
        run.stamps[zero] = log_times[zero]
        out.runs[t] = (run, log_times)
    if want_poses:
        store = types.typestore()
        times, payloads = log.messages.get(pose_topic, ([], []))
        try:
            xy = [_poses_xy(store.deserialize_cdr(p, "geometry_msgs/msg/PoseArray")) for p in payloads]
        except Exception as exc:  # a payload the ROS 2 type store cannot decode
            raise InputError(f"{path}: bad geometry_msgs/PoseArray message on {pose_topic}: {exc}") from None
        out.poses = (np.array(times, np.int64), xy)
    return out


def _read(path: str | Path, scan_topics: Callable[[dict], list[str]], pose_topic: str | None) -> _Raw:
    from ..log.importers import detect_kind

    path = Path(path)
    kind = detect_kind(path)
    if kind in ("ros1", "ros2"):
        return _read_bag(path, scan_topics, pose_topic)
    if kind == "mcap":
        return _read_mcap(path, scan_topics, pose_topic)
    raise InputError(f"{path}: a {kind} log has no leg labels; give a ROS 1/ROS 2 bag or an MCAP file")


def match_labels(
    scan_log_times: np.ndarray, label_times: np.ndarray, labels: Sequence[np.ndarray], window_ns: int = LABEL_WINDOW_NS
) -> list[np.ndarray]:
    """Each scan's labelled legs: the label message logged nearest to the scan's log time, when within
    `window_ns` (else none: K = 0). Times in ns; labels K x 2 arrays (metres, laser frame)."""
    empty = np.zeros((0, 2))
    if len(label_times) == 0:
        return [empty for _ in scan_log_times]
    order = np.argsort(label_times, kind="stable")
    lt = np.asarray(label_times, np.int64)[order]
    t = np.asarray(scan_log_times, np.int64)
    j = np.clip(np.searchsorted(lt, t), 1, max(len(lt) - 1, 1))
    before = np.clip(j - 1, 0, len(lt) - 1)
    after = np.clip(j, 0, len(lt) - 1)
    near = np.where(np.abs(lt[before] - t) <= np.abs(lt[after] - t), before, after)
    ok = np.abs(lt[near] - t) <= window_ns
    return [
        np.asarray(labels[order[n]], np.float64).reshape(-1, 2) if k else empty
        for n, k in zip(near.tolist(), ok.tolist(), strict=True)
    ]


def read_labelled(path: str | Path, topic: str | None = None, labels_topic: str = DEFAULT_LABELS_TOPIC) -> Recording:
    """A labelled recording: scans on `topic` (the file's only LaserScan topic when None) and the legs of
    each scan from the geometry_msgs/PoseArray messages on `labels_topic` (laser frame, no header stamp:
    matched by log time, see match_labels). ROS 1 bags, ROS 2 bag folders and MCAP files.
    Raises InputError when the labels topic is missing or holds no leg at all."""
    from ..log.importers.rosbag import LASERSCAN_TYPES, choose_topic

    path = Path(path)
    chosen: list[str] = []

    def pick(topics: dict) -> list[str]:
        chosen.append(choose_topic(str(path), topics, topic, LASERSCAN_TYPES, "sensor_msgs/LaserScan", "--topic"))
        return chosen

    raw = _read(path, pick, labels_topic)
    if labels_topic not in raw.topics:
        raise InputError(
            f"{path}: no leg labels: no topic {labels_topic} (a labelled file needs "
            "geometry_msgs/PoseArray leg positions; choose the topic with --labels-topic)"
        )
    if raw.poses is None:
        raise InputError(f"{path}: {labels_topic} holds {raw.topics[labels_topic][0]}, not geometry_msgs/PoseArray")
    run, log_times = raw.runs[chosen[0]]
    legs = match_labels(log_times, *raw.poses)
    if not sum(len(x) for x in legs):
        raise InputError(
            f"{path}: no labelled leg on {labels_topic} within {LABEL_WINDOW_NS // 1_000_000} ms "
            f"of a scan on {chosen[0]}"
        )
    return Recording(f"{path.name}", path, chosen[0], run, legs)


def read_empty(path: str | Path, topic: str | None = None) -> list[Recording]:
    """Empty recordings (rooms with no people): one per LaserScan topic of the file, or `topic` alone."""
    from ..log.importers.rosbag import LASERSCAN_TYPES, choose_topic

    path = Path(path)

    def pick(topics: dict) -> list[str]:
        if topic is not None:
            return [choose_topic(str(path), topics, topic, LASERSCAN_TYPES, "sensor_msgs/LaserScan", "--topic")]
        found = sorted(t for t, (m, n) in topics.items() if m in LASERSCAN_TYPES and n)
        if not found:
            others = ", ".join(f"{t} ({m})" for t, (m, _) in sorted(topics.items())) or "no topics"
            raise InputError(f"{path}: no sensor_msgs/LaserScan topic (it has {others})")
        return found

    raw = _read(path, pick, None)
    several = len(raw.runs) > 1
    return [Recording(f"{path.name}:{t}" if several else path.name, path, t, run) for t, (run, _) in raw.runs.items()]


# -------------------------------------------------------------------------------------------- segments


@dataclass
class SegmentTable:
    """Every segment of one recording: features (M x F), label (a leg), candidate (legs.candidate_mask),
    scan index, centroid (M x 2, metres, sensor frame) and range (m), and the paper's circle rule
    (circle_leg: a circle of radius <= 0.13 m; circle_score: its r_acc, 0 for the others)."""

    name: str
    labelled: bool
    n_scans: int
    features: np.ndarray
    label: np.ndarray
    candidate: np.ndarray
    scan: np.ndarray
    centroid: np.ndarray
    circle_leg: np.ndarray
    circle_score: np.ndarray

    @property
    def range_m(self) -> np.ndarray:
        return np.hypot(self.centroid[:, 0], self.centroid[:, 1])

    def __len__(self) -> int:
        return len(self.label)


def segment_centroids(
    ranges: np.ndarray,
    angles: np.ndarray,
    seg_start: np.ndarray,
    seg_end: np.ndarray,
    seg_offsets: np.ndarray,
    range_min: float = 0.0,
    range_max: float = np.inf,
) -> np.ndarray:
    """The centroid (mean of the valid returns, metres, sensor frame) of every segment (M x 2); NaN for a
    segment without a valid return. ranges N x B, angles B (radians), segments as segment_run gives them."""
    ranges = np.asarray(ranges, np.float64)
    n_seg = len(seg_start)
    scan = np.repeat(np.arange(len(seg_offsets) - 1), np.diff(seg_offsets))
    lengths = np.asarray(seg_end, np.int64) - np.asarray(seg_start, np.int64)
    seg_of = np.repeat(np.arange(n_seg), lengths)
    beam = (
        np.arange(lengths.sum())
        - np.repeat(np.cumsum(lengths) - lengths, lengths)
        + np.repeat(np.asarray(seg_start, np.int64), lengths)
    )
    r = ranges[scan[seg_of], beam]
    ok = np.isfinite(r) & (r > range_min) & (r < range_max)
    x = np.where(ok, r * np.cos(angles[beam]), 0.0)
    y = np.where(ok, r * np.sin(angles[beam]), 0.0)
    n = np.bincount(seg_of, ok, minlength=n_seg)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.stack(
            [np.bincount(seg_of, x, minlength=n_seg) / n, np.bincount(seg_of, y, minlength=n_seg) / n], axis=1
        )


def label_segments(
    centroid: np.ndarray, scan: np.ndarray, legs: Sequence[np.ndarray], radius: float = MATCH_RADIUS_M
) -> np.ndarray:
    """True for each segment (centroid M x 2, scan index M) with a labelled leg of its scan (legs[k], K x 2)
    within `radius` metres of its centroid. Several segments may match one leg (a leg split in two) and one
    segment several legs (two legs merged)."""
    out = np.zeros(len(scan), bool)
    if not len(scan):
        return out
    order = np.argsort(scan, kind="stable")
    bounds = np.searchsorted(scan[order], np.arange(len(legs) + 1))
    for k, lk in enumerate(legs):
        a, b = bounds[k], bounds[k + 1]
        if a == b or not len(lk):
            continue
        idx = order[a:b]
        d = np.hypot(centroid[idx, None, 0] - lk[None, :, 0], centroid[idx, None, 1] - lk[None, :, 1])
        out[idx] = (d <= radius).any(axis=1)
    return out


def _paper_rule(p: FeatureParams) -> FeatureParams:
    """`p` without a learned leg detector (circles alone; no model file needed)."""
    import dataclasses

    names = {f.name for f in dataclasses.fields(p)}
    return dataclasses.replace(p, leg_model="paper") if "leg_model" in names else p


def recording_clusters(
    run: ScanRun, params: FeatureParams | None = None, clusters: dict | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(start, end, offsets) of the clusters of every scan of `run`: datmo's segments (features.segment_run with
    params) for clusters {"method": "segments"}, leg_tracker's gap clusters (legs.gap_clusters) for
    {"method": "gap", "gap": m, "min_points": n}; None: DEFAULT_CLUSTERS."""
    from . import legs
    from .features import _range_limits, segment_run

    c = DEFAULT_CLUSTERS if clusters is None else clusters
    if c.get("method") == "segments":
        return segment_run(run, params or FeatureParams())
    if c.get("method") == "gap":
        lo, hi = _range_limits(run)
        return legs.gap_clusters(
            run.ranges,
            run.geometry.angles(),
            lo,
            hi,
            float(c.get("gap", legs.GAP_M)),
            int(c.get("min_points", legs.GAP_MIN_POINTS)),
        )
    raise ValueError(f"unknown cluster method {c.get('method')!r}: 'segments' or 'gap'")


def segment_table(
    rec: Recording, params: FeatureParams | None = None, radius: float = MATCH_RADIUS_M, clusters: dict | None = None
) -> SegmentTable:
    """Cluster a recording (recording_clusters: datmo's segments or gap clusters) and tabulate its clusters
    (see SegmentTable); the circle rule runs on the same clusters."""
    from . import legs
    from .features import _range_limits, extract_run

    p = params or FeatureParams()
    run = rec.run
    start, end, offsets = recording_clusters(run, p, clusters)
    lo, hi = _range_limits(run)
    angles = run.geometry.angles()
    feats = np.asarray(legs.cluster_features(run.ranges, angles, start, end, offsets, lo, hi), np.float64)
    scan = np.repeat(np.arange(len(run)), np.diff(offsets))
    centroid = segment_centroids(run.ranges, angles, start, end, offsets, lo, hi)
    label = label_segments(centroid, scan, rec.legs, radius) if rec.labelled else np.zeros(len(scan), bool)
    rf = extract_run(run, _paper_rule(p), landmarks=False, segments=(start, end, offsets))
    circles = rf.circles
    circle_leg = np.zeros(len(scan), bool)
    circle_score = np.zeros(len(scan))
    if len(circles):
        c_scan = np.repeat(np.arange(len(run)), np.diff(rf.circle_offsets))
        idx = offsets[c_scan] + circles["segment"].astype(np.int64)
        small = circles["radius"] <= CIRCLE_LEG_RADIUS_M
        circle_leg[idx[small]] = True
        circle_score[idx[small]] = circles["r_acc"][small]
    return SegmentTable(
        rec.name,
        rec.labelled,
        len(run),
        feats,
        label,
        np.asarray(legs.candidate_mask(feats), bool),
        scan,
        centroid,
        circle_leg,
        circle_score,
    )


def tables_of(
    recordings: Sequence[Recording],
    params: FeatureParams | None = None,
    radius: float = MATCH_RADIUS_M,
    progress: Progress | None = None,
    clusters: dict | None = None,
) -> list[SegmentTable]:
    """segment_table of each recording, reporting progress("segments", done, total)."""
    out = []
    for i, rec in enumerate(recordings):
        if progress is not None:
            progress("segments", i, len(recordings))
        out.append(segment_table(rec, params, radius, clusters))
    if progress is not None:
        progress("segments", len(recordings), len(recordings))
    return out


# ------------------------------------------------------------------------------------------------- folds


@dataclass(frozen=True)
class Fold:
    """One split by recording: indices into the labelled and the empty recordings. Train and test never share
    a recording."""

    test_labelled: int
    test_empty: int | None
    train_labelled: tuple[int, ...]
    train_empty: tuple[int, ...]


def leave_one_out_folds(n_labelled: int, n_empty: int) -> list[Fold]:
    """Fold i holds out labelled recording i and empty recording i mod n_empty (cycling), and trains on every
    other recording. No folds with fewer than two labelled recordings (nothing would be left to train on).
    With one empty recording, it is held out in turn and training has no empty recording."""
    if n_labelled < 2:
        return []
    out = []
    for i in range(n_labelled):
        j = i % n_empty if n_empty else None
        out.append(
            Fold(i, j, tuple(k for k in range(n_labelled) if k != i), tuple(k for k in range(n_empty) if k != j))
        )
    return out


# ----------------------------------------------------------------------------------------------- metrics


@dataclass
class Figures:
    """Per-cluster figures of one held-out pair (labelled recording, empty recording) at one threshold.
    precision/recall/ap: on the labelled recording's clusters within METRIC_RANGE_M; false_per_scan: clusters
    called legs per scan of the empty recording within METRIC_RANGE_M (None without one)."""

    precision: float
    recall: float
    ap: float
    false_per_scan: float | None
    legs: int
    clusters: int
    empty_scans: int


def precision_recall(y: np.ndarray, called: np.ndarray) -> tuple[float, float]:
    """Precision and recall of boolean calls against boolean labels (1.0 precision when nothing is called)."""
    tp = int(np.sum(y & called))
    n_called, n_pos = int(called.sum()), int(y.sum())
    return (tp / n_called if n_called else 1.0), (tp / n_pos if n_pos else float("nan"))


def average_precision(y: np.ndarray, score: np.ndarray) -> float:
    """Average precision (the area under the precision-recall steps, as scikit-learn computes it: ties share
    a step); NaN without positives. Pure numpy so evaluation needs no scikit-learn."""
    y = np.asarray(y, bool)
    if not y.any():
        return float("nan")
    order = np.argsort(-np.asarray(score, np.float64), kind="stable")
    s, yy = np.asarray(score)[order], y[order]
    last = np.r_[np.flatnonzero(np.diff(s)), len(s) - 1]  # the last index of each group of tied scores
    tp = np.cumsum(yy)[last]
    fp = (last + 1) - tp
    precision = tp / (tp + fp)
    recall = tp / y.sum()
    return float(np.sum(np.diff(np.r_[0.0, recall]) * precision))


def figures(
    labelled: SegmentTable,
    score: np.ndarray,
    threshold: float,
    empty: SegmentTable | None = None,
    empty_score: np.ndarray | None = None,
) -> Figures:
    """Figures (see Figures) of scores on a held-out labelled table (and an empty one); a cluster is called a
    leg when its score >= threshold."""
    near = labelled.range_m <= METRIC_RANGE_M
    y, s = labelled.label[near], np.asarray(score)[near]
    p, r = precision_recall(y, s >= threshold)
    fps = None
    scans = 0
    if empty is not None:
        e_near = empty.range_m <= METRIC_RANGE_M
        scans = empty.n_scans
        fps = float(np.sum(np.asarray(empty_score)[e_near] >= threshold)) / max(scans, 1)
    return Figures(p, r, average_precision(y, s), fps, int(y.sum()), int(near.sum()), scans)


def circle_figures(labelled: SegmentTable, empty: SegmentTable | None = None) -> Figures:
    """The paper's circle rule on the same clusters: a leg when a circle of radius <= 0.13 m was found on the
    segment; its r_acc ranks the circles for AP (0 for the others)."""
    score = np.where(labelled.circle_leg, np.maximum(labelled.circle_score, 1e-9), 0.0)
    e_score = None if empty is None else np.where(empty.circle_leg, 1.0, 0.0)
    return figures(labelled, score, 1e-9, empty, e_score)


# ------------------------------------------------------------------------------------------------ fitting


@dataclass(frozen=True)
class EstimatorSpec:
    """A scikit-learn tree ensemble and how its training rows are chosen and weighted.

    kind: "extra_trees", "random_forest" or "gradient_boosting". Training rows: candidate segments
    (legs.candidate_mask) of the training recordings within train_range_m of the scanner (None: all);
    the unlabelled clusters of labelled recordings are negatives too (people outside the labelling box
    among them, the price of more hard negatives) with weight unlabelled_weight; empty_weight multiplies the
    weight of empty recordings' rows; class_weight "balanced" weighs legs and non-legs equally in total;
    ignore_features: FEATURE_NAMES columns held constant in training, so no tree uses them; negative_fraction:
    the share of non-leg rows kept (at random, weighted up by its inverse) to train faster."""

    kind: str = "gradient_boosting"
    n_estimators: int = 200
    max_depth: int | None = 5
    min_samples_leaf: int = 3
    max_features: float | str | None = 0.5
    learning_rate: float = 0.1
    class_weight: str | None = "balanced"
    train_range_m: float | None = None
    empty_weight: float = 1.0
    unlabelled_weight: float = 1.0
    ignore_features: tuple[str, ...] = ("n_points",)
    negative_fraction: float = 0.3
    seed: int = 0

    def build(self):
        require_sklearn()
        from sklearn.ensemble import ExtraTreesClassifier, GradientBoostingClassifier, RandomForestClassifier

        if self.kind == "gradient_boosting":
            return GradientBoostingClassifier(
                n_estimators=self.n_estimators,
                max_depth=self.max_depth,
                learning_rate=self.learning_rate,
                min_samples_leaf=self.min_samples_leaf,
                max_features=self.max_features,
                subsample=0.8,
                random_state=self.seed,
            )
        cls = {"extra_trees": ExtraTreesClassifier, "random_forest": RandomForestClassifier}.get(self.kind)
        if cls is None:
            raise ValueError(f"unknown estimator kind {self.kind!r}")
        return cls(
            n_estimators=self.n_estimators,
            max_depth=self.max_depth,
            min_samples_leaf=self.min_samples_leaf,
            max_features=self.max_features,
            random_state=self.seed,
            n_jobs=1,
        )

    def for_threshold(self) -> EstimatorSpec:
        """The spec of the inner models that only score recordings for choosing the threshold: a forest of a
        quarter of the trees (at least 10; a forest's probabilities keep their expectation with fewer trees,
        and the inner folds are most of the fitting time); boosting unchanged (its scores depend on the count)."""
        import dataclasses

        if self.kind == "gradient_boosting":
            return self
        return dataclasses.replace(self, n_estimators=max(10, self.n_estimators // 4))

    def to_dict(self) -> dict:
        out = asdict(self)
        out["ignore_features"] = list(self.ignore_features)
        return out


def training_rows(tables: Sequence[SegmentTable], spec: EstimatorSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(X, y, sample weight) of the candidate segments of `tables` (see EstimatorSpec)."""
    xs, ys, ws = [], [], []
    for t in tables:
        keep = t.candidate.copy()
        if spec.train_range_m is not None:
            keep &= t.range_m <= spec.train_range_m
        xs.append(t.features[keep])
        ys.append(t.label[keep])
        if t.labelled:
            ws.append(np.where(t.label[keep], 1.0, spec.unlabelled_weight))
        else:
            ws.append(np.full(int(keep.sum()), spec.empty_weight))
    X = np.concatenate(xs) if xs else np.zeros((0, 0))
    y = np.concatenate(ys) if ys else np.zeros(0, bool)
    w = np.concatenate(ws) if ws else np.zeros(0)
    if spec.negative_fraction < 1.0:  # a random share of the non-legs, weighted up to stand for the rest
        rng = np.random.default_rng(spec.seed)
        drop = ~y & (rng.random(len(y)) >= spec.negative_fraction)
        w = np.where(drop, 0.0, np.where(y, w, w / spec.negative_fraction))
    X, y, w = X[w > 0], y[w > 0], w[w > 0]
    if spec.ignore_features:
        from .legs import FEATURE_NAMES

        X = X.copy()
        X[:, [FEATURE_NAMES.index(n) for n in spec.ignore_features]] = 0.0  # constant: no tree splits on it
    if spec.class_weight == "balanced" and y.any() and (~y).any():
        w = w * np.where(y, 0.5 * w.sum() / w[y].sum(), 0.5 * w.sum() / w[~y].sum())
    return X, y.astype(np.int64), w


def fit(tables: Sequence[SegmentTable], spec: EstimatorSpec):
    """The estimator of `spec` fitted on the candidate segments of `tables`."""
    X, y, w = training_rows(tables, spec)
    if not y.any() or y.all():
        raise InputError("the training data need both legs and other segments")
    est = spec.build()
    est.fit(X.astype(np.float32), y, sample_weight=w)
    return est


def to_model(estimator, threshold: float = 0.5, provenance: dict | None = None):
    """The legs.LegModel of a fitted estimator (what run time evaluates)."""
    from .leg_model import from_sklearn

    return from_sklearn(estimator, float(threshold), provenance or {})


def scores(model, table: SegmentTable) -> np.ndarray:
    """Leg probability of every segment of `table` by the run-time evaluator (0 for non-candidates)."""
    return model.probabilities(table.features)


# ---------------------------------------------------------------------------------------------- threshold


def choose_threshold(
    y: np.ndarray,
    score: np.ndarray,
    empty_score: np.ndarray | None = None,
    empty_scans: int = 0,
    budget: float = EMPTY_FALSE_BUDGET,
) -> float:
    """The threshold (a segment is a leg when its score >= it) of highest F1 on labelled clusters (y, score),
    among those giving at most `budget` false legs per empty scan on empty clusters (empty_score over
    empty_scans scans); the lowest threshold meeting the budget when none scores. Scores in [0, 1]."""
    y = np.asarray(y, bool)
    s = np.asarray(score, np.float64)
    cand = np.unique(np.r_[s[s > 0], 1.0])  # thresholds worth trying: each distinct positive score
    order = np.sort(s)
    n_at_or_above = len(s) - np.searchsorted(order, cand, side="left")
    tp = len(s[y]) - np.searchsorted(np.sort(s[y]), cand, side="left")
    f1 = 2.0 * tp / np.maximum(n_at_or_above + y.sum(), 1)
    ok = np.ones(len(cand), bool)
    if empty_score is not None and empty_scans:
        e = np.sort(np.asarray(empty_score, np.float64))
        ok = (len(e) - np.searchsorted(e, cand, side="left")) / empty_scans <= budget
    if not ok.any():
        return 1.0
    f1 = np.where(ok, f1, -1.0)
    return float(cand[int(np.argmax(f1))])


# ------------------------------------------------------------------------------------- cross-validation


@dataclass
class HeldOut:
    """Figures on one held-out pair of recordings, of the model trained without them (at the threshold chosen
    on its training recordings) and of the paper's circle rule."""

    labelled: str
    empty: str | None
    threshold: float
    learned: Figures
    circle: Figures
    thinned_recall: float | None = None  # on the held-out recording thinned 2x
    recall_by_range: tuple[float | None, ...] = ()  # per RANGE_BINS_M bin, at the threshold

    def to_dict(self) -> dict:
        return {
            "labelled": self.labelled,
            "empty": self.empty,
            "threshold": self.threshold,
            "learned": asdict(self.learned),
            "circle": asdict(self.circle),
        }


def _step(progress: Progress | None, total: int) -> Callable[[], None]:
    done = [0]
    if progress is not None:
        progress("training", 0, total)

    def step() -> None:
        done[0] += 1
        if progress is not None:
            progress("training", done[0], total)

    return step


def _near(t: SegmentTable) -> np.ndarray:
    return t.range_m <= METRIC_RANGE_M


def tuned_threshold(
    lab: Sequence[SegmentTable],
    emp: Sequence[SegmentTable],
    spec: EstimatorSpec,
    step: Callable[[], None] = lambda: None,
    budget: float = EMPTY_FALSE_BUDGET,
    extra: Sequence[SegmentTable] = (),
) -> float:
    """The threshold for a model trained on (lab, emp), chosen on those recordings alone: each is scored by a
    model trained without it (inner leave-one-out, as leave_one_out_folds), and choose_threshold picks on
    the pooled out-of-fold scores of clusters within METRIC_RANGE_M (inner models: spec.for_threshold()). With
    one labelled recording there is no inner fold: the model's own training scores are used (optimistic).
    `extra` recordings (simulated ones) are in every training set and never scored."""
    folds = leave_one_out_folds(len(lab), len(emp))
    ys, ss, es, scans = [], [], [], 0
    if not folds:
        model = to_model(fit(list(lab) + list(emp) + list(extra), spec))
        step()
        folds_scored = [(t, scores(model, t)) for t in list(lab) + list(emp)]
    else:
        folds_scored = []
        inner = spec.for_threshold()
        for f in folds:
            model = to_model(
                fit([lab[i] for i in f.train_labelled] + [emp[j] for j in f.train_empty] + list(extra), inner)
            )
            step()
            folds_scored.append((lab[f.test_labelled], scores(model, lab[f.test_labelled])))
            if f.test_empty is not None:
                folds_scored.append((emp[f.test_empty], scores(model, emp[f.test_empty])))
    for t, s in folds_scored:
        near = _near(t)
        if t.labelled:
            ys.append(t.label[near])
            ss.append(s[near])
        else:
            es.append(s[near])
            scans += t.n_scans
    return choose_threshold(np.concatenate(ys), np.concatenate(ss), np.concatenate(es) if es else None, scans, budget)


def _fits(n_lab: int, n_emp: int) -> int:
    """Model fits of tuned_threshold plus the model itself, for n_lab labelled recordings."""
    return (n_lab if n_lab >= 2 else 1) + 1


RANGE_BINS_M = (0.0, 2.0, 3.0, 4.0, 5.0)


def recall_by_range(table: SegmentTable, score: np.ndarray, threshold: float) -> tuple[float | None, ...]:
    """Recall at `threshold` of the labelled legs in each range bin of RANGE_BINS_M (None: no leg there)."""
    r = table.range_m
    out = []
    for lo, hi in zip(RANGE_BINS_M[:-1], RANGE_BINS_M[1:], strict=True):
        legs = table.label & (r >= lo) & (r < hi)
        out.append(float(np.mean(np.asarray(score)[legs] >= threshold)) if legs.any() else None)
    return tuple(out)


def cross_validate(
    lab: Sequence[SegmentTable],
    emp: Sequence[SegmentTable],
    spec: EstimatorSpec,
    progress: Progress | None = None,
    *,
    step: Callable[[], None] | None = None,
    extra: Sequence[SegmentTable] = (),
    thin: Sequence[SegmentTable] = (),
) -> list[HeldOut]:
    """Leave-one-recording-out figures (see leave_one_out_folds): for each fold a model trained on the other
    recordings (and `extra`, always), its threshold tuned on them alone, scored on the held-out pair beside
    the circle rule, with its recall by range; `thin[i]`, when given, is labelled recording i thinned
    (`thinned`): the held-out one's recall at the same threshold is scored too. Empty list with fewer than two
    labelled recordings."""
    folds = leave_one_out_folds(len(lab), len(emp))
    if step is None:
        step = _step(progress, cv_fits(len(lab), len(emp)))
    out = []
    for f in folds:
        tr_lab = [lab[i] for i in f.train_labelled]
        tr_emp = [emp[j] for j in f.train_empty]
        threshold = tuned_threshold(tr_lab, tr_emp, spec, step, extra=extra)
        model = to_model(fit(tr_lab + tr_emp + list(extra), spec))
        step()
        test = lab[f.test_labelled]
        empty = emp[f.test_empty] if f.test_empty is not None else None
        test_scores = scores(model, test)
        learned = figures(test, test_scores, threshold, empty, None if empty is None else scores(model, empty))
        thin_recall = None
        if thin:
            t = thin[f.test_labelled]
            thin_recall = figures(t, scores(model, t), threshold).recall
        out.append(
            HeldOut(
                test.name,
                None if empty is None else empty.name,
                threshold,
                learned,
                circle_figures(test, empty),
                thin_recall,
                recall_by_range(test, test_scores, threshold),
            )
        )
    return out


def fold_model(
    lab: Sequence[SegmentTable],
    emp: Sequence[SegmentTable],
    fold: Fold,
    spec: EstimatorSpec | None = None,
    extra: Sequence[SegmentTable] = (),
    clusters: dict | None = None,
    tune: bool = False,
):
    """A model trained as the shipped one without `fold`'s held-out recordings, as a LegModel run time can use
    (its provenance names the clusters it scores), to track the held-out recordings with. Its threshold is
    tuned on the rest only with `tune` (tracking does not use it: it takes legs by TrackingParams.leg_probability);
    else 0.5."""
    spec = spec or EstimatorSpec()
    tr_lab = [lab[i] for i in fold.train_labelled]
    tr_emp = [emp[j] for j in fold.train_empty]
    threshold = tuned_threshold(tr_lab, tr_emp, spec, extra=extra) if tune else 0.5
    c = dict(DEFAULT_CLUSTERS if clusters is None else clusters)
    return to_model(
        fit(tr_lab + tr_emp + list(extra), spec),
        threshold,
        {"clusters": c, "note": f"fold model: {lab[fold.test_labelled].name} held out"},
    )


def cv_fits(n_lab: int, n_emp: int) -> int:
    """How many models cross_validate fits."""
    return sum(_fits(n_lab - 1, n_emp) for _ in leave_one_out_folds(n_lab, n_emp))


def mean_figures(held_out: Sequence[HeldOut]) -> dict:
    """Means over held-out pairs of each figure, learned and circle rule ({} without folds)."""
    if not held_out:
        return {}
    out = {}
    for which in ("learned", "circle"):
        rows = [asdict(getattr(h, which)) for h in held_out]
        out[which] = {
            k: float(np.nanmean([r[k] for r in rows if r[k] is not None]))
            for k in ("precision", "recall", "ap", "false_per_scan")
            if any(r[k] is not None for r in rows)
        }
    out["threshold"] = float(np.mean([h.threshold for h in held_out]))
    return out


# ------------------------------------------------------------------------------------------ final model


@dataclass
class TrainingResult:
    """The model trained on every recording (threshold and provenance inside) and the held-out figures that
    estimate how it does on recordings it has not seen (empty with one labelled recording)."""

    model: object  # legs.LegModel
    held_out: list[HeldOut]
    mean: dict
    threshold: float
    tables: list[SegmentTable] = field(default_factory=list, repr=False)


THRESHOLD_RULE = (
    f"highest F1 on the training recordings' inner leave-one-recording-out scores (clusters within "
    f"{METRIC_RANGE_M:g} m) with at most {EMPTY_FALSE_BUDGET:g} false legs per empty scan"
)


def total_fits(n_lab: int, n_emp: int) -> int:
    """Models train_leg_model fits: the cross-validation's and the final model's."""
    return cv_fits(n_lab, n_emp) + _fits(n_lab, n_emp)


def _sources(recordings: Sequence[Recording]) -> list[dict]:
    from ..log.mcapio import sha256_of

    out, seen = [], {}
    for r in recordings:
        key = str(r.path)
        if key not in seen:
            seen[key] = {
                "file": r.path.name,
                "path": key,
                "sha256": sha256_of(r.path),
                "role": "labelled" if r.labelled else "empty",
                "topics": [],
                "scans": 0,
                "legs": 0,
            }
            out.append(seen[key])
        entry = seen[key]
        entry["topics"].append(r.topic)
        entry["scans"] += len(r.run)
        entry["legs"] += int(sum(len(x) for x in r.legs)) if r.labelled else 0
    return out


def train_leg_model(
    labelled: Sequence[Recording],
    empty: Sequence[Recording],
    spec: EstimatorSpec | None = None,
    params: FeatureParams | None = None,
    progress: Progress | None = None,
    labels_topic: str = DEFAULT_LABELS_TOPIC,
    clusters: dict | None = None,
    extra: Sequence[Recording] = (),
) -> TrainingResult:
    """Cross-validate (see cross_validate), then train on every recording with the threshold tuned on them
    all (see tuned_threshold); the model's provenance holds the data files and their SHA-256, the features,
    the estimator, the threshold and its rule, the held-out figures, scikit-learn's version, the date and the
    clusters the model scores (clusters, default DEFAULT_CLUSTERS; see legs.model_clusters). `extra`
    labelled recordings (simulated ones: datmo_cli.simulated) are in every training set, never held out or scored."""
    sklearn = require_sklearn()

    from .. import __version__
    from .legs import CANDIDATE_MAX_WIDTH, CANDIDATE_MIN_POINTS, FEATURE_NAMES

    if not labelled:
        raise InputError("no labelled recording: give at least one file with leg labels")
    spec = spec or EstimatorSpec()
    p = params or FeatureParams()
    clusters = dict(DEFAULT_CLUSTERS if clusters is None else clusters)
    tables = tables_of(list(labelled) + list(empty) + list(extra), p, progress=progress, clusters=clusters)
    lab, emp = tables[: len(labelled)], tables[len(labelled) : len(labelled) + len(empty)]
    more = tables[len(labelled) + len(empty) :]
    if not any(t.label.any() for t in lab):
        raise InputError(
            f"no segment lies within {MATCH_RADIUS_M:g} m of a labelled leg: are the labels in the scans' frame?"
        )
    step = _step(progress, total_fits(len(lab), len(emp)))
    held_out = cross_validate(lab, emp, spec, step=step, extra=more)
    threshold = tuned_threshold(lab, emp, spec, step, extra=more)
    estimator = fit(lab + emp + more, spec)
    step()
    mean = mean_figures(held_out)
    provenance = {
        "tool": f"datmo {__version__} train-legs",
        "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "sklearn_version": sklearn.__version__,
        "data": _sources(list(labelled) + list(empty)),
        "simulated": [{"name": r.name, "scans": len(r.run), "legs": int(sum(len(g) for g in r.legs))} for r in extra],
        "feature_names": list(FEATURE_NAMES),
        "candidate_rule": {"min_points": CANDIDATE_MIN_POINTS, "max_width_m": CANDIDATE_MAX_WIDTH},
        "estimator": {"class": type(estimator).__name__, **spec.to_dict()},
        "segmentation": {"c0": p.c0, "min_points": p.min_points},
        "clusters": clusters,
        "labels": {"topic": labels_topic, "match_radius_m": MATCH_RADIUS_M, "window_ms": LABEL_WINDOW_NS / 1e6},
        "threshold": {"value": threshold, "rule": THRESHOLD_RULE},
        "held_out": {
            "scheme": "leave one labelled recording out, with one empty recording in turn",
            "metric_range_m": METRIC_RANGE_M,
            "mean": mean,
            "folds": [h.to_dict() for h in held_out],
        },
    }
    model = to_model(estimator, threshold, provenance)
    return TrainingResult(model, held_out, mean, threshold, tables)
