"""Tracking and classification (docs/method.md §6): small parts, composed per scan in one compiled step (_step).

measurements  the measurement kinds, and the containers of a scan's features and measurements
tracker       Tracker: the state between compiled steps, one call per scan (`step`) or per block of scans
              (`track_block`)
hindsight     the fixed-lag smoother and the person labels over a lag of the batch outputs (run, track)
markers       visualization_msgs/MarkerArray CDR for Foxglove
params        TrackingParams (defaults, TOML)
_step         the compiled tracking step: every phase of a scan, and blocks of scans, in one numba call
_scan_measurements  features to measurements (the paper's rule, or with the leg detector's legs); frames
_association  prediction, gating and GNN association, Kalman update, reacquisition of lost tracks
_people       legs given to the tracks of people, and the leg evidence that makes a person
_background   the background grid and the carried beams: leg candidates that are no legs
_life_cycle   occlusion, confirmation and deletion, duplicates, new tracks, tails
_classify     class and mobility of every track (with a leg detector, the person life cycle)
_kernels      numba kernels the phases call: measurements, legs, background, occlusion, duplicates
              (their plain statements, and the pre-step tracker, are tests/reference_tracking.py)
_marker_kernels  the markers' points, colours, arrows and tails (markers.py)
_rts          numba kernel of hindsight's fixed-lag RTS smoother (hindsight.py; its numpy statements are
              tests/reference_tracking.reference_smooth)
_assign       numba assignment solver (shortest augmenting paths; scipy's answer) and GNN
state         the track table (one float64 array, named columns), parameter vector, context
bundles       the named tuples the compiled step takes and returns (features, measurements, scratch)
"""
