"""The learned leg detector's model: a tree ensemble (a random forest / extra trees or gradient boosting,
trained offline with scikit-learn) shipped as plain node arrays in one .npz (LegModel) and evaluated by a numba
kernel (leg_forest.py), so run time needs neither scikit-learn nor pickles. The features it scores and the
candidate rule are in leg_rules.py.
"""

from __future__ import annotations

import io
import json
import math
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..base.errors import InputError
from .leg_rules import CANDIDATE_MAX_WIDTH, CANDIDATE_MIN_POINTS, FEATURE_NAMES, GAP_M, GAP_MIN_POINTS

FORMAT_VERSION = 1
KINDS = ("forest", "boosting")
DEFAULT_MODEL_PATH = Path(__file__).resolve().parent / "models" / "legs.npz"


MEMBERS = (  # the arrays of a leg model file (.npz members NAME.npy)
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
MAX_MODEL_MEMBERS = 64  # members of a leg model file read at most (a model has 13): more are refused unopened
MAX_MODEL_BYTES = 256 << 20  # bytes of a leg model file, of its members uncompressed and of the arrays they
# declare (the packaged model: about 0.5 MB)


class EnsembleArrays(NamedTuple):
    """What leg_forest's kernels walk of a LegModel (made once, at its construction; LegModel._kernel_args)."""

    nodes: np.ndarray  # (nodes, 3) int64: each node's (feature, left, right), feature -1 at leaves
    split: np.ndarray  # (nodes,) float: an inner node's threshold, a leaf's value
    roots: np.ndarray  # (trees,) int64: each tree's root node
    kind: int  # leg_forest.KIND_FOREST or KIND_BOOSTING
    base: float  # boosting: the sum's offset
    scale: float  # boosting: the sum's scale
    perfect_feature: np.ndarray  # int32: the perfect trees' inner nodes' features (perfect_trees)
    perfect_threshold: np.ndarray  # float32: their thresholds
    perfect_value: np.ndarray  # float: their leaves' values
    depth: int  # the perfect trees' depth, -1 when there are none (walk the node arrays)


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
        kind = 0 if self.kind == "forest" else 1  # leg_forest.KIND_FOREST / KIND_BOOSTING
        pf, pt, pv, depth = perfect_trees(self)
        self._args = EnsembleArrays(
            nodes=self._nodes,
            split=self._split,
            roots=self.roots,
            kind=kind,
            base=self.base,
            scale=self.scale,
            perfect_feature=pf,
            perfect_threshold=pt,
            perfect_value=pv,
            depth=depth,
        )

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

    def _kernel_args(self) -> EnsembleArrays:
        """What the ensemble kernel takes after the features, in its order (nodes, split, roots, kind, base,
        scale, then the perfect trees: feature, threshold, leaf value, depth), by name."""
        return self._args

    def probabilities(self, features: np.ndarray) -> np.ndarray:
        """Leg probability (M,) float64 of each row of features (M, len(feature_names)); rows outside
        candidate_mask get 0."""
        from . import leg_forest

        f = np.ascontiguousarray(features, np.float64)
        if f.ndim != 2 or f.shape[1] != len(self.feature_names):
            raise ValueError(f"features must be (M, {len(self.feature_names)}), got shape {f.shape}")
        out = np.empty(len(f), np.float64)
        leg_forest.ensemble(f, CANDIDATE_MAX_WIDTH, CANDIDATE_MIN_POINTS, *self._kernel_args(), out)
        return out

    def save(self, path: str | Path, *, force: bool = True) -> None:
        """Write the model to one .npz at `path` (exactly that name; via a temporary file renamed, see
        outputs.atomic_output: an existing regular file is replaced only with `force`)."""
        from ..base.outputs import atomic_output

        with atomic_output(path, force=force, what="model") as f:
            self._write(f)

    def _write(self, f) -> None:
        arrays = {
            "format_version": np.int64(FORMAT_VERSION),
            "feature": self.feature,
            "threshold": self.threshold,
            "left": self.left,
            "right": self.right,
            "value": self.value,
            "roots": self.roots,
            "kind": np.str_(self.kind),
            "base": np.float64(self.base),
            "scale": np.float64(self.scale),
            "threshold_p": np.float64(self.threshold_p),
            "feature_names": np.array(self.feature_names, np.str_),
            "provenance": np.str_(json.dumps(self.provenance, sort_keys=True)),
        }
        np.savez_compressed(f, **arrays)

    @classmethod
    def load(cls, path: str | Path) -> LegModel:
        """Read a model written by save. InputError naming the file when it is missing, corrupt or made for
        other features than FEATURE_NAMES. Nothing is loaded before the arrays' declared shapes are read from
        the file and found within a model's size (at most 256 MiB of arrays: a file declaring more, whatever its
        own size, is refused before any memory is spent); then every array must have a model's type and shape
        (integer node indices, finite thresholds and leaf values, a JSON object of provenance)."""

        from ..base.input_files import check

        most = MAX_MODEL_BYTES
        path = Path(path)
        if not path.exists():
            raise InputError(f"{path}: no such leg model file")
        size = check(path).st_size  # a folder, FIFO or device: one line saying what it is
        if size > most:
            raise InputError(f"{path}: not a leg model file ({size:,} bytes; a leg model takes at most {most:,})")
        try:
            declared = 0
            with zipfile.ZipFile(path) as zf:
                infos = zf.infolist()
                if len(infos) > MAX_MODEL_MEMBERS:
                    raise InputError(
                        f"{path}: not a leg model file ({len(infos):,} members; a leg model has "
                        f"{len(MEMBERS)}, at most {MAX_MODEL_MEMBERS} are read)"
                    )
                stored = sum(i.file_size for i in infos)
                if stored > most:
                    raise InputError(
                        f"{path}: not a leg model file (its members hold {stored:,} bytes uncompressed, more "
                        f"than a leg model takes ({most:,}))"
                    )
                for info in infos:
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
        missing = [k for k in MEMBERS if k not in data]
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


PERFECT_MAX_DEPTH = 8  # deepest model stored as perfect trees (2**depth leaves each); deeper: the node walk


def _floor32(threshold: np.ndarray) -> np.ndarray:
    """The largest float32 <= each threshold: for a float32 x, x <= t exactly when x <= _floor32(t)."""
    t32 = threshold.astype(np.float32)
    over = t32.astype(np.float64) > threshold
    t32[over] = np.nextafter(t32[over], np.float32(-np.inf))
    return t32


def perfect_trees(model: LegModel) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The trees as perfect binary trees of one depth D (the model's deepest leaf), for a walk of exactly D
    steps with no branch on the node kind: (feature int32, threshold float32, leaf value float64, D), tree t's
    2**D - 1 inner nodes at feature/threshold[t * (2**D - 1):] and its 2**D leaves at value[t * 2**D:]. Within
    a tree, node i's children are 2i + 1 (x[feature] <= threshold) and 2i + 2, and node 2**D - 1 + k is leaf k.
    A leaf above depth D becomes a subtree whose every leaf holds its value (its inner nodes split on feature 0
    at +inf: either way the same value). Thresholds are rounded down to float32 (_floor32): the same
    comparisons as float32(x) <= threshold. D = -1 (empty arrays) when a tree is deeper than PERFECT_MAX_DEPTH."""
    feature, left, right = model.feature, model.left, model.right
    cur = model.roots[:, None]  # (T, 2**level): the node of the original tree at each perfect position
    feats, thresholds = [], []
    depth = 0
    while np.any(feature[cur] >= 0):
        if depth == PERFECT_MAX_DEPTH:
            return np.zeros(0, np.int32), np.zeros(0, np.float32), np.zeros(0, np.float64), -1
        inner = feature[cur] >= 0
        feats.append(np.where(inner, feature[cur], 0))
        thresholds.append(np.where(inner, _floor32(model.threshold[cur]), np.float32(np.inf)))
        nxt = np.empty((cur.shape[0], 2 * cur.shape[1]), np.int64)
        nxt[:, 0::2] = np.where(inner, left[cur], cur)
        nxt[:, 1::2] = np.where(inner, right[cur], cur)
        cur = nxt
        depth += 1
    T = len(model.roots)
    f = np.concatenate(feats, axis=1) if feats else np.zeros((T, 0))
    t = np.concatenate(thresholds, axis=1) if thresholds else np.zeros((T, 0))
    flat = (np.ascontiguousarray(f, np.int32).ravel(), np.ascontiguousarray(t, np.float32).ravel())
    return (*flat, np.ascontiguousarray(model.value[cur], np.float64).ravel(), depth)


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
