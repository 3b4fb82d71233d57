"""The message vocabulary: the codes datmo_msgs' .msg files define, and the names derived from them.

Every module takes its class, mobility, status, landmark-type and blob-kind codes from here; the values are
read from the .msg files (through `types.constants`, what rosbags' type store gives), so the files stay
their one source. The codes are plain ints, usable as compile-time constants in numba kernels.

- Track.msg: CLASS_UNKNOWN, CLASS_PERSON, CLASS_CIRCLE_OBJECT, CLASS_RECTANGULAR_OBJECT; MOBILITY_*; STATUS_*.
- GroundTruthObject.msg: the movers' classes above (same codes) and CLASS_COLUMN, CLASS_BENCH,
  CLASS_WALL_CORNER, CLASS_WALL for the static objects of a simulated scene.
- Landmark.msg: LANDMARK_* (the .msg names CORNER, ... with a LANDMARK_ prefix).
- Blob.msg: BLOB_KIND_BLOB, BLOB_KIND_POINT (its KIND_* with a BLOB_ prefix).

The name tables (code -> lower-case words, e.g. 2 -> "circle object") are what report, plot, export and
evaluate print and parse.
"""

from __future__ import annotations

from . import types

_TRACK = types.constants(types.TRACK)
_GROUND_TRUTH = types.constants(types.GROUND_TRUTH_OBJECT)
_LANDMARK = types.constants(types.LANDMARK)
_BLOB = types.constants(types.BLOB)

CLASS_UNKNOWN = _TRACK["CLASS_UNKNOWN"]
CLASS_PERSON = _TRACK["CLASS_PERSON"]
CLASS_CIRCLE_OBJECT = _TRACK["CLASS_CIRCLE_OBJECT"]
CLASS_RECTANGULAR_OBJECT = _TRACK["CLASS_RECTANGULAR_OBJECT"]
CLASS_COLUMN = _GROUND_TRUTH["CLASS_COLUMN"]
CLASS_BENCH = _GROUND_TRUTH["CLASS_BENCH"]
CLASS_WALL_CORNER = _GROUND_TRUTH["CLASS_WALL_CORNER"]
CLASS_WALL = _GROUND_TRUTH["CLASS_WALL"]

MOBILITY_STATIC = _TRACK["MOBILITY_STATIC"]
MOBILITY_DYNAMIC = _TRACK["MOBILITY_DYNAMIC"]
MOBILITY_UNDEFINED = _TRACK["MOBILITY_UNDEFINED"]

STATUS_TENTATIVE = _TRACK["STATUS_TENTATIVE"]
STATUS_CONFIRMED = _TRACK["STATUS_CONFIRMED"]
STATUS_COASTING = _TRACK["STATUS_COASTING"]

LANDMARK_CORNER = _LANDMARK["CORNER"]
LANDMARK_CONVEX_DEFLECTION = _LANDMARK["CONVEX_DEFLECTION"]
LANDMARK_CONCAVE_DEFLECTION = _LANDMARK["CONCAVE_DEFLECTION"]
LANDMARK_LINE_END = _LANDMARK["LINE_END"]
LANDMARK_COLUMN = _LANDMARK["COLUMN"]
LANDMARK_BENCH = _LANDMARK["BENCH"]

BLOB_KIND_BLOB = _BLOB["KIND_BLOB"]
BLOB_KIND_POINT = _BLOB["KIND_POINT"]


def _names(table: dict[str, int], prefix: str) -> dict[int, str]:
    """{code: name} of the constants of `table` starting with `prefix`, named by the rest in lower-case
    words: CLASS_CIRCLE_OBJECT -> "circle object"."""
    return {v: k.removeprefix(prefix).lower().replace("_", " ") for k, v in table.items() if k.startswith(prefix)}


CLASS_NAMES = _names(_TRACK, "CLASS_")  # a track's classes
MOBILITY_NAMES = _names(_TRACK, "MOBILITY_")
STATUS_NAMES = _names(_TRACK, "STATUS_")
LANDMARK_NAMES = _names(_LANDMARK, "")
BLOB_KIND_NAMES = _names(_BLOB, "KIND_")
