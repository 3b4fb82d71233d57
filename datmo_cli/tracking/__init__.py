"""Tracking and classification (method.md §6): small parts composed by `tracker.Tracker.step`.

measurements  features of a scan -> model-centre measurements (legs paired into people)
kalman        constant-velocity Kalman filter, batched over tracks (filterpy's model)
association   Mahalanobis gating and global nearest neighbour (scipy's linear_sum_assignment)
people        leg pairing and the walking pattern (reference versions of the kernels)
classification  classes and mobility (0 static, 1 dynamic, X undefined)
tracker       the per-scan step: legs, association, update, reacquisition, occlusion, life cycle
markers       visualization_msgs/MarkerArray CDR for Foxglove
pipeline      a whole run: features in, Tracks and markers payloads out
accuracy      figures against ground truth that datmo_cli.evaluate does not give
params        TrackingParams (defaults, TOML)
_kernels      numba kernels behind kalman, measurements and tracker
"""
