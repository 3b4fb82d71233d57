"""A learned leg detector: geometric features of each scan segment and a tree ensemble's leg probability.

The features are those of Arras, Mozos and Burgard (2007) and Leigh et al. (2015, leg_tracker), computed by
numba kernels (_leg_kernels.py) over the points of each segment, sensor frame (x forward, y left), metres and
radians. The ensemble (a random forest / extra trees or gradient boosting, trained offline with scikit-learn)
is shipped as plain node arrays in one .npz (LegModel) and evaluated by a numba kernel, so run time needs
neither scikit-learn nor pickles.

Candidate rule (`candidate_mask`): a segment of fewer than CANDIDATE_MIN_POINTS points or wider than
CANDIDATE_MAX_WIDTH (first to last point) cannot be a leg; `leg_probabilities` gives it 0 without evaluating
the ensemble. Train on candidates only (apply `candidate_mask` to the training rows), so the model never
has to learn what the rule already decides.

Clusters: a model scores the clusters it was trained on, named by its provenance["clusters"]: datmo's segments
({"method": "segments"}, also models without the key) or leg_tracker's gap clusters (`gap_clusters`, {"method":
"gap", "gap": 0.13, "min_points": 3}); `model_clusters` gives them for a scan block.
"""

from __future__ import annotations

import io
import json
import math
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError

FEATURE_NAMES: tuple[str, ...] = (
    "n_points",  # valid returns in the segment
    "width",  # m, first to last point
    "linearity",  # m, RMS orthogonal residual of the total-least-squares line
    "circularity",  # m, RMS radial residual of the algebraic (Kasa) circle; = linearity if collinear
    "radius",  # m, that circle's radius, clipped to RADIUS_CLIP (also when collinear)
    "std",  # m, sqrt(sum |p - centroid|^2 / (n - 1))
    "median_deviation",  # m, mean |p - median point| (component-wise median)
    "boundary_length",  # m, sum of consecutive point distances
    "boundary_regularity",  # m, standard deviation of consecutive point distances
    "mean_curvature",  # 1/m, mean over interior triples of 1/circumradius, + when bulging toward the sensor
    "mean_inscribed_angle",  # rad, mean angle at interior points between the first and last point (pi: a line)
    "inscribed_angle_std",  # rad, standard deviation of those angles
    "distance",  # m, range of the centroid
    "subtended_angle",  # rad, |angle of last point's beam - angle of first point's beam|
    "occluded_start",  # 1.0 when the beam before the first point is a valid return nearer by > margin
    "occluded_end",  # 1.0 when the beam after the last point is a valid return nearer by > margin
    "jump_start",  # m, range of the nearest valid return before the first point minus the first
    # point's (+ when that return lies behind), clipped to +-JUMP_CLIP; +JUMP_CLIP: none
    "jump_end",  # m, the same beyond the last point
    "neighbour_distance",  # m, centroid to the nearest other candidate's centroid in the scan, <= NEIGHBOUR_CLIP
    "density",  # n_points * angle step * distance / width (~1 for a surface facing the sensor),
    # <= DENSITY_CLIP (also for zero width): independent of the scanner's resolution
    "relative_curvature",  # mean_curvature * width: scale-free (2 for a half circle)
)
RADIUS_CLIP = 1.0  # m: the radius feature's bound (degenerate or nearly straight segments)
JUMP_CLIP = 3.0  # m (the kernels' constants, repeated here for readers)
NEIGHBOUR_CLIP = 2.0  # m
DENSITY_CLIP = 10.0
GAP_M = 0.13  # m: leg_tracker's cluster gap (gap_clusters)
GAP_MIN_POINTS = 3
OCCLUSION_MARGIN = 0.1  # m
CANDIDATE_MAX_WIDTH = 0.8  # m
CANDIDATE_MIN_POINTS = 3
FORMAT_VERSION = 1
KINDS = ("forest", "boosting")
DEFAULT_MODEL_PATH = Path(__file__).resolve().parent / "models" / "legs.npz"


def candidate_mask(features: np.ndarray) -> np.ndarray:
    """Rows of features (M, len(FEATURE_NAMES)) that may be legs: n_points >= CANDIDATE_MIN_POINTS and
    width <= CANDIDATE_MAX_WIDTH (m). Other rows get probability 0 in leg_probabilities; train on these only."""
    f = np.asarray(features, np.float64).reshape(-1, len(FEATURE_NAMES))
    return (f[:, 0] >= CANDIDATE_MIN_POINTS) & (f[:, 1] <= CANDIDATE_MAX_WIDTH)


def _scan_arrays(ranges, angles) -> tuple[np.ndarray, np.ndarray]:
    """ranges (N, B) as contiguous float32 and angles (B,) as contiguous float64, or ValueError."""
    ranges = np.ascontiguousarray(ranges, np.float32)
    if ranges.ndim != 2:
        raise ValueError(f"ranges must be (N, B), got shape {ranges.shape}")
    angles = np.ascontiguousarray(angles, np.float64)
    if angles.shape != (ranges.shape[1],):
        raise ValueError(f"angles must have shape ({ranges.shape[1]},), got {angles.shape}")
    return ranges, angles


def _scan_inputs(ranges, angles, seg_start, seg_end, seg_offsets):
    from . import _leg_kernels as LK

    ranges, angles = _scan_arrays(ranges, angles)
    N, B = ranges.shape
    start = np.ascontiguousarray(seg_start, np.int64)
    end = np.ascontiguousarray(seg_end, np.int64)
    offsets = np.ascontiguousarray(seg_offsets, np.int64)
    if start.ndim != 1 or end.shape != start.shape:
        raise ValueError("seg_start and seg_end must be 1-D arrays of the same length")
    if offsets.shape != (N + 1,):
        raise ValueError(f"seg_offsets must be N + 1 = {N + 1} non-decreasing indices from 0 to {len(start)}")
    problem = LK.check_segments(start, end, offsets, B)
    if problem == 1:
        raise ValueError(f"seg_offsets must be N + 1 = {N + 1} non-decreasing indices from 0 to {len(start)}")
    if problem == 2:
        raise ValueError(f"segments must be beam ranges [start, end) within 0..{B}")
    cos_a, sin_a = _trig(angles)
    return ranges, angles, cos_a, sin_a, start, end, offsets


_TRIG: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}


def _trig(angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin of the beam angles, computed once per scan geometry (a few kept)."""
    key = angles.tobytes()
    hit = _TRIG.get(key)
    if hit is None:
        if len(_TRIG) >= 8:
            _TRIG.clear()
        hit = _TRIG[key] = (np.cos(angles), np.sin(angles))
    return hit


def _limits(range_min: float, range_max: float) -> tuple[float, float]:
    lo = float(range_min) if math.isfinite(range_min) else 0.0
    hi = float(range_max) if math.isfinite(range_max) and range_max > lo else math.inf
    return lo, hi


def _angle_step(angles: np.ndarray) -> float:
    """The scan's beam spacing (rad, positive): first to last beam over the gaps between them."""
    return abs(float(angles[-1]) - float(angles[0])) / (len(angles) - 1) if len(angles) > 1 else 0.0


def gap_clusters(
    ranges, angles, range_min: float, range_max: float, gap: float = GAP_M, min_points: int = GAP_MIN_POINTS
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """leg_tracker's clusters of every scan: consecutive valid returns (finite, strictly between range_min and
    range_max) more than `gap` metres apart start a new cluster, an invalid return ends one, and clusters of
    fewer than `min_points` returns are dropped. ranges (N, B) metres, angles (B,) radians. Returns (start,
    end, offsets) int64 as features.segment_run does: scan k's clusters are beam ranges [start, end) of
    start/end[offsets[k]:offsets[k + 1]], in beam order (every beam inside a cluster is a valid return)."""
    from . import _leg_kernels as LK

    ranges, angles = _scan_arrays(ranges, angles)
    N, B = ranges.shape
    cos_a, sin_a = _trig(angles)
    lo, hi = _limits(range_min, range_max)
    counts = np.zeros(N, np.int64)
    none = np.zeros(0, np.int64)
    LK._gap_pass(ranges, cos_a, sin_a, lo, hi, float(gap), int(min_points), none, none, counts)
    offsets = np.zeros(N + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    start = np.empty(offsets[-1], np.int64)
    end = np.empty(offsets[-1], np.int64)
    if len(start):
        LK._gap_pass(ranges, cos_a, sin_a, lo, hi, float(gap), int(min_points), start, end, counts)
    return start, end, offsets


def model_clusters(
    ranges, angles, range_min: float, range_max: float, model: LegModel | None, seg_start, seg_end, seg_offsets
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The clusters `model` scores (its provenance["clusters"]): gap_clusters of the scans for a model trained
    on them ({"method": "gap", "gap": m, "min_points": n}), else (method "segments", no such key, or no model)
    the given segments (seg_start, seg_end, seg_offsets as int64 arrays). Inputs as in cluster_features."""
    spec = (model.provenance.get("clusters") if model is not None else None) or {"method": "segments"}
    if spec.get("method") == "gap":
        return gap_clusters(
            ranges,
            angles,
            range_min,
            range_max,
            float(spec.get("gap", GAP_M)),
            int(spec.get("min_points", GAP_MIN_POINTS)),
        )
    if spec.get("method") != "segments":
        raise ValueError(f"unknown cluster method {spec.get('method')!r} in the leg model's provenance")
    return (np.asarray(seg_start, np.int64), np.asarray(seg_end, np.int64), np.asarray(seg_offsets, np.int64))


def cluster_features(ranges, angles, seg_start, seg_end, seg_offsets, range_min: float, range_max: float) -> np.ndarray:
    """Features of every segment, shape (M, len(FEATURE_NAMES)) float64, in the order of seg_start.

    ranges (N, B) metres; angles (B,) radians, sensor frame (x forward, y left), beam i at angles[i]. Scan k's
    segments are seg_start/seg_end[seg_offsets[k]:seg_offsets[k + 1]], beam ranges [start, end) (as
    features.segment_run gives them). Returns count when finite and strictly between range_min and
    range_max; other beams inside a segment are skipped, and a segment with no valid return gets zeros.
    """
    from . import _leg_kernels as LK

    ranges, angles, cos_a, sin_a, start, end, offsets = _scan_inputs(ranges, angles, seg_start, seg_end, seg_offsets)
    lo, hi = _limits(range_min, range_max)
    out = np.zeros((len(start), LK.N_FEATURES), np.float64)
    if len(start):
        LK.block_features(
            ranges,
            cos_a,
            sin_a,
            angles,
            start,
            end,
            offsets,
            lo,
            hi,
            RADIUS_CLIP,
            OCCLUSION_MARGIN,
            CANDIDATE_MAX_WIDTH,
            CANDIDATE_MIN_POINTS,
            False,
            _angle_step(angles),
            out,
        )
    return out


@dataclass
class LegModel:
    """A binary tree ensemble as flat node arrays (all trees concatenated; children are global indices).

    Per node: feature (-1 at leaves), threshold (x goes left when float32(x[feature]) <= threshold), left,
    right, value (leaf value). roots: each tree's root node. kind "forest": probability = mean over trees of
    the leaf's positive-class fraction; "boosting": sigmoid(base + scale * sum of leaf values). threshold_p
    is the decision threshold shipped with the model; provenance a JSON-able dict (data, parameters, scores).
    Treat a model as read-only: the kernel's packed arrays are derived once, at construction.
    """

    feature: np.ndarray
    threshold: np.ndarray
    left: np.ndarray
    right: np.ndarray
    value: np.ndarray
    roots: np.ndarray
    kind: str = "forest"
    base: float = 0.0
    scale: float = 1.0
    threshold_p: float = 0.5
    feature_names: tuple[str, ...] = FEATURE_NAMES
    provenance: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.feature = np.ascontiguousarray(self.feature, np.int64)
        self.threshold = np.ascontiguousarray(self.threshold, np.float64)
        self.left = np.ascontiguousarray(self.left, np.int64)
        self.right = np.ascontiguousarray(self.right, np.int64)
        self.value = np.ascontiguousarray(self.value, np.float64)
        self.roots = np.ascontiguousarray(self.roots, np.int64)
        self.feature_names = tuple(str(n) for n in self.feature_names)
        self.base = float(self.base)
        self.scale = float(self.scale)
        self.threshold_p = float(self.threshold_p)
        problem = self._problem()
        if problem:
            raise ValueError(f"invalid leg model: {problem}")
        # what the kernel walks: (feature, left, right) side by side, and one float per node (threshold of an
        # inner node, value of a leaf): two cache lines per visited node instead of five
        inner = self.feature >= 0
        self._nodes = np.ascontiguousarray(
            np.column_stack([np.where(inner, self.feature, -1), self.left, self.right]), np.int64
        )
        self._split = np.where(inner, self.threshold, self.value)
        kind = 0 if self.kind == "forest" else 1  # _leg_kernels.KIND_FOREST / KIND_BOOSTING
        self._args = (self._nodes, self._split, self.roots, kind, self.base, self.scale)

    def _problem(self) -> str:
        n = len(self.feature)
        if self.kind not in KINDS:
            return f"kind {self.kind!r} is not one of {KINDS}"
        if any(a.ndim != 1 or len(a) != n for a in (self.threshold, self.left, self.right, self.value)):
            return "node arrays differ in length"
        if self.roots.ndim != 1 or len(self.roots) == 0:
            return "no trees"
        if self.roots.min() < 0 or self.roots.max() >= n:
            return "a root is not a node"
        inner = self.feature >= 0
        idx = np.arange(n)
        if np.any(self.feature[inner] >= len(self.feature_names)):
            return "a node splits on a feature the model does not name"
        # children after their parent (scikit-learn's depth-first numbering) so every descent ends at a leaf
        for child in (self.left, self.right):
            if np.any(child[inner] <= idx[inner]) or np.any(child[inner] >= n):
                return "a node's child is not a later node"
        if not (np.all(np.isfinite(self.value)) and np.isfinite(self.base) and np.isfinite(self.scale)):
            return "non-finite leaf values"
        if not 0.0 <= self.threshold_p <= 1.0:
            return f"threshold_p {self.threshold_p} is outside [0, 1]"
        return ""

    @property
    def n_trees(self) -> int:
        return len(self.roots)

    def _kernel_args(self) -> tuple:
        """What the ensemble kernel takes after the features: nodes, split, roots, kind, base, scale."""
        return self._args

    def probabilities(self, features: np.ndarray) -> np.ndarray:
        """Leg probability (M,) float64 of each row of features (M, len(feature_names)); rows outside
        candidate_mask get 0."""
        from . import _leg_kernels as LK

        f = np.ascontiguousarray(features, np.float64)
        if f.ndim != 2 or f.shape[1] != len(self.feature_names):
            raise ValueError(f"features must be (M, {len(self.feature_names)}), got shape {f.shape}")
        out = np.empty(len(f), np.float64)
        LK.ensemble(f, CANDIDATE_MAX_WIDTH, CANDIDATE_MIN_POINTS, *self._kernel_args(), out)
        return out

    def save(self, path: str | Path, *, force: bool = True) -> None:
        """Write the model to one .npz at `path` (exactly that name; via a temporary file renamed, see
        outputs.atomic_output: an existing regular file is replaced only with `force`)."""
        from ..outputs import atomic_output

        with atomic_output(path, force=force, what="model") as f:
            self._write(f)

    def _write(self, f) -> None:
        np.savez_compressed(
            f,
            format_version=np.int64(FORMAT_VERSION),
            feature=self.feature,
            threshold=self.threshold,
            left=self.left,
            right=self.right,
            value=self.value,
            roots=self.roots,
            kind=np.str_(self.kind),
            base=np.float64(self.base),
            scale=np.float64(self.scale),
            threshold_p=np.float64(self.threshold_p),
            feature_names=np.array(self.feature_names, np.str_),
            provenance=np.str_(json.dumps(self.provenance, sort_keys=True)),
        )

    @classmethod
    def load(cls, path: str | Path) -> LegModel:
        """Read a model written by save. InputError naming the file when it is missing, corrupt or made for
        other features than FEATURE_NAMES. Nothing is loaded before the arrays' declared shapes are read from
        the file and found within a model's size (at most 256 MiB of arrays: a file declaring more, whatever its
        own size, is refused before any memory is spent); then every array must have a model's type and shape
        (integer node indices, finite thresholds and leaf values, a JSON object of provenance)."""
        import math

        from ..input_files import check

        most = 256 << 20  # bytes of arrays a leg model may declare (the packaged one: about 0.5 MB)
        path = Path(path)
        if not path.exists():
            raise InputError(f"{path}: no such leg model file")
        check(path)  # a folder, FIFO or device: one line saying what it is
        try:
            declared = 0
            with zipfile.ZipFile(path) as zf:
                for info in zf.infolist():
                    with zf.open(info) as member:
                        version = np.lib.format.read_magic(member)
                        if version not in ((1, 0), (2, 0)):
                            raise ValueError(f"{info.filename}: .npy format {version[0]}.{version[1]}")
                        read_header = (
                            np.lib.format.read_array_header_1_0
                            if version == (1, 0)
                            else np.lib.format.read_array_header_2_0
                        )
                        shape, _, dtype = read_header(member)
                    declared += math.prod(shape) * dtype.itemsize
                    if declared > most:
                        raise InputError(
                            f"{path}: not a leg model file ({info.filename} and the arrays before "
                            f"it declare {declared:,} bytes, more than a leg model takes ({most:,}))"
                        )
            with np.load(path, allow_pickle=False) as z:
                data = {k: z[k] for k in z.files}
        except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, io.UnsupportedOperation) as exc:
            raise InputError(f"{path}: not a leg model file ({exc})") from None
        missing = [
            k
            for k in (
                "format_version",
                "feature",
                "threshold",
                "left",
                "right",
                "value",
                "roots",
                "kind",
                "base",
                "scale",
                "threshold_p",
                "feature_names",
                "provenance",
            )
            if k not in data
        ]
        if missing:
            raise InputError(f"{path}: not a leg model file (missing {', '.join(missing)})")
        arrays = ("feature", "left", "right", "roots", "threshold", "value", "feature_names")
        for key, kind in (
            ("format_version", "i"),
            ("feature", "i"),
            ("left", "i"),
            ("right", "i"),
            ("roots", "i"),
            ("threshold", "f"),
            ("value", "f"),
            ("base", "f"),
            ("scale", "f"),
            ("threshold_p", "f"),
            ("kind", "U"),
            ("provenance", "U"),
            ("feature_names", "U"),
        ):
            a, one = data[key], key not in arrays
            if a.dtype.kind != kind and not (kind == "f" and a.dtype.kind == "i") or a.ndim != (0 if one else 1):
                want = {"i": "integer", "f": "number", "U": "string"}[kind]
                want = ("an " if kind == "i" else "a ") + want if one else f"a list of {want}s"
                raise InputError(
                    f"{path}: corrupt leg model ({key} is {a.dtype} of shape {a.shape}; a model's is {want})"
                )
            if kind == "f" and not np.all(np.isfinite(a)):
                raise InputError(f"{path}: corrupt leg model ({key} holds NaN or infinite values)")
        if int(data["format_version"]) != FORMAT_VERSION:
            raise InputError(
                f"{path}: leg model format {int(data['format_version'])}, this datmo reads {FORMAT_VERSION}"
            )
        names = tuple(str(n) for n in data["feature_names"].tolist())
        if names != FEATURE_NAMES:
            raise InputError(
                f"{path}: the leg model was trained on other features ({', '.join(names)}) than "
                f"this datmo computes ({', '.join(FEATURE_NAMES)}); retrain it"
            )
        try:
            provenance = json.loads(str(data["provenance"]))
        except ValueError as exc:
            raise InputError(f"{path}: corrupt leg model (provenance is not JSON: {exc})") from None

        def sane(clusters) -> bool:  # how model_clusters reads provenance["clusters"]
            if not isinstance(clusters, dict) or clusters.get("method") not in ("segments", "gap"):
                return False
            gap, least = clusters.get("gap", GAP_M), clusters.get("min_points", GAP_MIN_POINTS)
            return (
                isinstance(gap, int | float)
                and not isinstance(gap, bool)
                and math.isfinite(gap)
                and gap > 0
                and isinstance(least, int)
                and not isinstance(least, bool)
                and least > 0
            )

        if not isinstance(provenance, dict) or not sane(provenance.get("clusters", {"method": "segments"})):
            what = f"clusters {provenance.get('clusters')!r}" if isinstance(provenance, dict) else "not a JSON object"
            raise InputError(
                f"{path}: corrupt leg model (provenance: {what}; a model's is a JSON object whose "
                'clusters are {"method": "segments"} or {"method": "gap", "gap": metres, '
                '"min_points": n})'
            )
        try:
            return cls(
                data["feature"],
                data["threshold"],
                data["left"],
                data["right"],
                data["value"],
                data["roots"],
                kind=str(data["kind"]),
                base=float(data["base"]),
                scale=float(data["scale"]),
                threshold_p=float(data["threshold_p"]),
                feature_names=names,
                provenance=provenance,
            )
        except (ValueError, TypeError) as exc:
            raise InputError(f"{path}: corrupt leg model ({exc})") from None


def _flatten_trees(trees, leaf_value) -> tuple[list[np.ndarray], np.ndarray]:
    parts = {k: [] for k in ("feature", "threshold", "left", "right", "value")}
    roots = []
    offset = 0
    for tree in trees:
        t = tree.tree_
        inner = t.children_left >= 0
        roots.append(offset)
        parts["feature"].append(np.where(inner, t.feature, -1))
        parts["threshold"].append(np.where(inner, t.threshold, 0.0))
        parts["left"].append(np.where(inner, t.children_left + offset, -1))
        parts["right"].append(np.where(inner, t.children_right + offset, -1))
        parts["value"].append(np.where(inner, 0.0, leaf_value(t.value)))
        offset += t.node_count
    arrays = [np.concatenate(parts[k]) for k in ("feature", "threshold", "left", "right", "value")]
    return arrays, np.array(roots, np.int64)


def from_sklearn(estimator, threshold_p: float, provenance: dict) -> LegModel:
    """A LegModel from a fitted binary scikit-learn RandomForestClassifier, ExtraTreesClassifier or
    GradientBoostingClassifier, trained on FEATURE_NAMES' columns in order (class 1 = leg)."""
    from sklearn.ensemble import ExtraTreesClassifier, GradientBoostingClassifier, RandomForestClassifier

    if getattr(estimator, "n_features_in_", None) != len(FEATURE_NAMES):
        raise ValueError(f"the estimator must be fitted on the {len(FEATURE_NAMES)} columns of FEATURE_NAMES")
    if len(getattr(estimator, "classes_", ())) != 2:
        raise ValueError("the estimator must be a binary classifier")
    if isinstance(estimator, RandomForestClassifier | ExtraTreesClassifier):
        # leaf value: the positive class's (weighted) fraction, whether sklearn stores counts or fractions
        def fraction(v):
            return v[:, 0, 1] / np.maximum(v[:, 0].sum(axis=1), np.finfo(float).tiny)

        arrays, roots = _flatten_trees(estimator.estimators_, fraction)
        return LegModel(*arrays, roots, kind="forest", threshold_p=threshold_p, provenance=dict(provenance))
    if isinstance(estimator, GradientBoostingClassifier):
        trees = estimator.estimators_[:, 0]
        arrays, roots = _flatten_trees(trees, lambda v: v[:, 0, 0])
        # the initial raw score (log-odds of the prior, or 0): the decision function minus the trees' part
        x0 = np.zeros((1, len(FEATURE_NAMES)), np.float32)
        scale = float(estimator.learning_rate)
        base = float(estimator.decision_function(x0)[0]) - scale * sum(float(t.predict(x0)[0]) for t in trees)
        return LegModel(
            *arrays,
            roots,
            kind="boosting",
            base=base,
            scale=scale,
            threshold_p=threshold_p,
            provenance=dict(provenance),
        )
    raise ValueError(
        f"unsupported estimator {type(estimator).__name__}: use RandomForestClassifier, "
        "ExtraTreesClassifier or GradientBoostingClassifier"
    )


_LOADED: dict[tuple, LegModel] = {}  # (resolved path, mtime ns, size) -> the model read from it


def load_leg_model(spec: str) -> LegModel | None:
    """'default': the packaged model; 'paper': None (the paper's circle rule, no learned model); otherwise the
    path of a model file (InputError when absent or bad). A file read before and unchanged since (same
    mtime and size) gives the model read then: streaming stages ask for it once a block, and reading and
    checking the file costs tens of milliseconds. Models are not changed after loading."""
    if spec == "paper":
        return None
    path = Path(DEFAULT_MODEL_PATH if spec == "default" else spec)
    try:
        st = path.stat()
        key = (str(path.resolve()), st.st_mtime_ns, st.st_size)
    except OSError:
        return LegModel.load(path)  # missing or unreadable: load says so in one line
    model = _LOADED.get(key)
    if model is None:
        model = LegModel.load(path)
        if len(_LOADED) >= 8:
            _LOADED.clear()
        _LOADED[key] = model
    return model


def leg_probabilities(
    ranges,
    angles,
    seg_start,
    seg_end,
    seg_offsets,
    range_min: float,
    range_max: float,
    model: LegModel,
    threads: int = 1,
) -> np.ndarray:
    """Leg probability (M,) float64 of every segment (inputs as in cluster_features): features and ensemble in
    one compiled call, on `threads` threads (a perception.threads.resolve()d count; the same result for any).
    Segments outside candidate_mask get 0."""
    from . import _leg_kernels as LK
    from . import threads as T

    ranges, angles, cos_a, sin_a, start, end, offsets = _scan_inputs(ranges, angles, seg_start, seg_end, seg_offsets)
    lo, hi = _limits(range_min, range_max)
    M = len(start)
    out = np.zeros(M, np.float64)
    if M:
        feats = np.empty((M, LK.N_FEATURES), np.float64)
        args = (
            cos_a,
            sin_a,
            angles,
            start,
            end,
            offsets,
            lo,
            hi,
            RADIUS_CLIP,
            OCCLUSION_MARGIN,
            CANDIDATE_MAX_WIDTH,
            CANDIDATE_MIN_POINTS,
            _angle_step(angles),
            *model._kernel_args(),
            feats,
            out,
        )
        N = len(ranges)
        threads = T.for_scans(threads, N)
        if threads > 1:
            with T.numba_threads(threads):
                LK.block_probabilities_parallel(ranges, min(N, 4 * threads), *args)
        else:
            LK.block_probabilities(ranges, *args)
    return out
