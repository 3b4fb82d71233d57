"""Tracking and classification (docs/method.md §6): small parts, composed per scan in one compiled step (_step).

measurements  the measurement kinds, and the containers of a scan's features and measurements
tracker       Tracker: the state between compiled steps, one call per scan (`step`) or per block of scans
              (`track_block`)
markers       visualization_msgs/MarkerArray CDR for Foxglove
synthetic     ScanFeatures from plain lists (tests, accuracy)
accuracy      figures against ground truth that datmo_cli.evaluate does not give
params        TrackingParams (defaults, TOML)
_kernels      numba kernels the step calls: measurements, legs, background, occlusion, duplicates; markers
              (their plain statements, and the pre-step tracker, are tests/reference_tracking.py)
_step         the compiled tracking step: every phase of a scan, and blocks of scans, in one numba call
_assign       numba assignment solver (shortest augmenting paths; scipy's answer) and GNN
state         the track table (one float64 array, named columns), parameter vector, context
"""
