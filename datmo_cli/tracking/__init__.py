"""Tracking and classification (method.md §6): small parts, composed per scan in one compiled step (_step).

measurements  features of a scan -> model-centre measurements (legs paired into people)
kalman        constant-velocity Kalman filter, batched over tracks (filterpy's model)
association   Mahalanobis gating and global nearest neighbour (the numba solver of _assign)
people        leg pairing and the walking pattern (reference versions of the kernels)
classification  classes and mobility (0 static, 1 dynamic, X undefined)
tracker       Tracker: the state between compiled steps, one call per scan (`step`) or per block of scans
              (`track_block`)
markers       visualization_msgs/MarkerArray CDR for Foxglove
synthetic     ScanFeatures from plain lists (tests, accuracy)
accuracy      figures against ground truth that datmo_cli.evaluate does not give
params        TrackingParams (defaults, TOML)
_kernels      numba kernels behind kalman, measurements and the step
_step         the compiled tracking step: every phase of a scan, and blocks of scans, in one numba call
_assign       numba assignment solver (shortest augmenting paths; scipy's answer) and GNN
state         the track table (one float64 array, named columns), parameter vector, context
"""
