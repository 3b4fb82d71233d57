"""Which test checks each numba kernel of the package directly against its reference in tests/reference_*.py.

Keys: 'package.module.kernel' under datmo_cli; values: 'test file::test function'. The tests named here get
the `kernels` marker (conftest.py), so `make test-nojit` runs them all with NUMBA_DISABLE_JIT=1, the kernels as
plain Python; tests/test_kernels_reference.py checks that the table covers every kernel the package defines,
so a new kernel needs its direct check. Plain data: conftest.py reads it at collection.
"""

from __future__ import annotations

HERE = "test_kernels_reference.py"
DRIVERS = "test_kernels_drivers.py"
HOLD = "test_tracking_people_hold.py"
STEP_PHASES = "test_tracking_step.py::test_every_phase_equals_the_reference_on_small_scenes"

CHECKS: dict[str, str] = {
    # tracking: the kernels the compiled step calls
    "tracking._kernels.pair_legs": "test_tracking_people.py::test_pairing_kernel_matches_the_reference",
    "tracking._kernels.legs_to_measurements": f"{HERE}::test_legs_to_measurements",
    "tracking._kernels._people_first": f"{HERE}::test_people_first",
    "tracking._kernels.measurements": f"{HERE}::test_paper_measurements",
    "tracking._kernels._beam_marks": f"{HERE}::test_beam_marks_and_span_max",
    "tracking._kernels._span_max": f"{HERE}::test_beam_marks_and_span_max",
    "tracking._kernels.learned_measurements": "test_tracking_learned.py::test_learned_measurements_match_the_reference",
    "tracking._kernels.leg_stage": f"{HERE}::test_leg_stage",
    "tracking._kernels.leg_stage_measurements": f"{HERE}::test_leg_stage_measurements",
    "tracking._kernels._cover": f"{HERE}::test_cover",
    "tracking._kernels.duplicates": f"{HERE}::test_duplicates",
    "tracking._kernels.occlusion": f"{HERE}::test_occlusion",
    "tracking._kernels.on_background": f"{HERE}::test_on_background",
    "tracking._kernels.tracks_on_background": f"{HERE}::test_tracks_on_background",
    "tracking._marker_kernels.marker_points": "test_tracking_markers.py::test_kernel_tails_equal_tail_segments",
    # tracking: the compiled step's phases, each run on the reference tracker's state (lockstep)
    "tracking._scan_measurements.paper_measurements": STEP_PHASES,
    "tracking._scan_measurements.learned_measurements": STEP_PHASES,
    "tracking._scan_measurements.moved": STEP_PHASES,
    "tracking._association.kind_group": f"{HERE}::test_step_kind_group",
    "tracking._association.predict": STEP_PHASES,
    "tracking._background.off_background": STEP_PHASES,
    "tracking._people.legs_stage": STEP_PHASES,
    "tracking._association.associate": STEP_PHASES,
    "tracking._background.hit_background": STEP_PHASES,
    "tracking._association.update": STEP_PHASES,
    "tracking._association.reacquire": STEP_PHASES,
    "tracking._association.merge_reacquired": STEP_PHASES,
    "tracking._people.leg_evidence": STEP_PHASES,
    "tracking._life_cycle.occlusion": STEP_PHASES,
    "tracking._life_cycle.life_cycle": STEP_PHASES,
    "tracking._life_cycle.spawn": STEP_PHASES,
    "tracking._classify.classify": STEP_PHASES,
    "tracking._life_cycle.push_tail": STEP_PHASES,
    "tracking._background.background": STEP_PHASES,
    "tracking._step.write_tracks": STEP_PHASES,
    "tracking._step.track_block": f"{DRIVERS}::test_track_block_step_measurements_and_track_scan",
    "tracking._step.step_measurements": f"{DRIVERS}::test_track_block_step_measurements_and_track_scan",
    "tracking._step.track_scan": f"{DRIVERS}::test_track_block_step_measurements_and_track_scan",
    "tracking._association.kalman_update": f"{HERE}::test_step_kalman_update_and_restart",
    "tracking._association.restart": f"{HERE}::test_step_kalman_update_and_restart",
    "tracking._scan_measurements.to_sensor": f"{HERE}::test_step_to_sensor",
    "tracking._association.gated_costs": f"{HERE}::test_step_gated_costs",
    "tracking._background.background_update": f"{HERE}::test_step_background_update",
    "tracking._people.leg_probability": f"{HERE}::test_step_leg_probability",
    "tracking._people.leggy_tracks": f"{HERE}::test_step_leggy_tracks_and_duplicates",
    "tracking._life_cycle.duplicates": f"{HERE}::test_step_leggy_tracks_and_duplicates",
    "tracking._background.carried_update": f"{HERE}::test_step_carried_update_and_beams",
    "tracking._background.carried_beams": f"{HERE}::test_step_carried_update_and_beams",
    "tracking._people.fold_evidence": f"{HERE}::test_step_fold_evidence",
    "tracking._people.sure_person": f"{HERE}::test_step_leggy_tracks_and_duplicates",
    "tracking._people.owns_returns": f"{HOLD}::test_owns_returns_people_and_tracks_of_background_shield_evidence",
    "tracking._people.in_free_space": f"{HOLD}::test_in_free_space_equals_the_reference",
    "tracking._people.free_legs": STEP_PHASES,
    "tracking._people.keep_scan": STEP_PHASES,
    "tracking._association.hold_people": f"{HOLD}::test_a_person_whose_legs_are_there_takes_no_segment_beside_them",
    # tracking: the assignment solver
    "tracking._assign.lsap": "test_tracking_assign.py::test_lsap_is_scipys_assignment",
    "tracking._assign.gnn": "test_tracking_assign.py::test_gnn_is_the_reference_gnn_on_gated_matrices",
    "tracking._assign._components": f"{HERE}::test_components",
    # sim
    "sim._kernels._ray_segment": f"{HERE}::test_ray_segment_and_circle",
    "sim._kernels._ray_circle": f"{HERE}::test_ray_segment_and_circle",
    "sim._kernels.cast_batch": f"{HERE}::test_cast_batch",
    "sim._kernels.tow": "test_sim_walking.py::test_towed_load_keeps_the_wire_length",
    # perception: features
    "perception.segmentation.valid_return": f"{HERE}::test_valid_return",
    "perception.hough_lines._atan2": f"{HERE}::test_atan2",
    "perception.hough_lines._wrap_pi": "test_perception_speedups.py::test_wrap_pi_is_the_float_modulo",
    "perception.segmentation.segment_scan": "test_perception_reference.py::test_segmentation_equals_the_reference",
    "perception.hough_lines.fit_line": "test_perception_reference.py::test_line_fit_equals_the_reference",
    "perception.hough_circles.fit_circle": "test_perception_reference.py::test_circle_fit_equals_the_reference",
    "perception.hough_circles.circle_posed": "test_perception_circles.py::test_circle_posed_equals_the_reference",
    "perception.scan_extractor.gather_rows": (
        "test_perception_speedups.py::test_gather_rows_keeps_each_scans_rows_in_order"
    ),
    "perception.hough_lines.normal_cells": (
        "test_perception_reference.py::test_full_accumulator_peak_equals_the_reference"
    ),
    "perception.hough_lines.line_subsegments": (
        "test_perception_reference.py::test_full_accumulator_peak_equals_the_reference"
    ),
    "perception.hough_lines.line_of_run": "test_perception_kernels.py::test_noisy_wall_is_one_line_near_the_truth",
    "perception.hough_circles.circle_of_run": (
        "test_perception_kernels.py::test_circle_votes_equal_the_reference_window"
    ),
    "perception.hough_circles.ring_count": "test_perception_speedups.py::test_ring_count_equals_hypot_on_every_point",
    "perception.scan_extractor._lines_rss": "test_perception_speedups.py::test_lines_rss_equals_the_per_point_sum",
    "perception.segmentation.segment_block": f"{HERE}::test_segment_block",
    "perception.hough_lines.scatter": f"{HERE}::test_scatter",
    "perception.hough_lines._one_line": f"{HERE}::test_one_line",
    "perception.hough_lines._row_offset": f"{HERE}::test_bounding_box_and_row_offset",
    "perception.hough_lines._bounding_box": f"{HERE}::test_bounding_box_and_row_offset",
    "perception.scan_extractor._perpendicular": f"{HERE}::test_perpendicular_and_convex",
    "perception.scan_extractor._convex": f"{HERE}::test_perpendicular_and_convex",
    "perception.hough_lines._vote": f"{HERE}::test_vote_and_clear",
    "perception.hough_lines._clear": f"{HERE}::test_vote_and_clear",
    "perception.scan_extractor.extract_scan": f"{DRIVERS}::test_extract_scan_decision_equals_the_reference",
    "perception.scan_extractor.extract_scans": f"{DRIVERS}::test_extract_scan_scans_and_parallel",
    "perception.scan_extractor.extract_parallel": f"{DRIVERS}::test_extract_scan_scans_and_parallel",
    "perception.scan_extractor.scan_work": f"{DRIVERS}::test_extract_scan_decision_equals_the_reference",
    "perception.scan_extractor._merge_lines": f"{DRIVERS}::test_extract_scan_decision_equals_the_reference",
    "perception.scan_extractor._circle_case": f"{DRIVERS}::test_extract_scan_decision_equals_the_reference",
    "perception.scan_extractor._circle_wins": f"{DRIVERS}::test_extract_scan_decision_equals_the_reference",
    "perception.scan_extractor._circle_row": f"{DRIVERS}::test_extract_scan_decision_equals_the_reference",
    "perception.scan_extractor._line_row": f"{DRIVERS}::test_extract_scan_decision_equals_the_reference",
    "perception.scan_extractor._blob_row": f"{DRIVERS}::test_extract_scan_decision_equals_the_reference",
    # perception: ego-motion
    "perception.scan_odometry.scan_points": "test_egomotion.py::test_scan_points_match_reference",
    "perception.scan_odometry.beam_normal": "test_egomotion.py::test_normals_match_reference",
    "perception.scan_odometry.scan_normals": "test_egomotion.py::test_normals_match_reference",
    "perception.icp.grid_insert": "test_egomotion.py::test_grid_nearest_matches_brute_force",
    "perception.icp.grid_nearest": "test_egomotion.py::test_grid_nearest_matches_brute_force",
    "perception.icp.icp_step": "test_egomotion.py::test_icp_step_matches_reference",
    "perception.icp.icp_align": "test_egomotion.py::test_icp_align_matches_reference",
    "perception.icp.robust_weight": f"{HERE}::test_robust_weight",
    "perception.icp.solve3": f"{HERE}::test_solve3",
    "perception.icp.compose": f"{HERE}::test_compose_and_between",
    "perception.icp.between": f"{HERE}::test_compose_and_between",
    "perception.icp.add_to_map": f"{HERE}::test_add_to_map",
    "perception.icp.cell_of": f"{HERE}::test_cell_of_and_hash",
    "perception.icp.cell_hash": f"{HERE}::test_cell_of_and_hash",
    "perception.scan_odometry._gather": f"{DRIVERS}::test_gather",
    "perception.scan_odometry.rebuild_map": f"{DRIVERS}::test_rebuild_map",
    "perception.scan_odometry.odometry_run": f"{DRIVERS}::test_odometry_run",
    "perception.scan_odometry._predict": f"{DRIVERS}::test_predict_and_match",
    "perception.scan_odometry._match": f"{DRIVERS}::test_predict_and_match",
    # perception: the leg detector
    "perception.leg_features._gap_pass": f"{HERE}::test_gap_pass_and_block_features",
    "perception.leg_features.block_features": f"{HERE}::test_gap_pass_and_block_features",
    "perception.leg_features.check_segments": f"{HERE}::test_check_segments",
    "perception.leg_features._median": f"{HERE}::test_median_and_jump",
    "perception.leg_features._jump": f"{HERE}::test_median_and_jump",
    "perception.leg_forest.ensemble": f"{HERE}::test_ensemble_leaf_and_candidates",
    "perception.leg_forest.is_candidate": f"{HERE}::test_ensemble_leaf_and_candidates",
    "perception.leg_forest._leaf": f"{HERE}::test_ensemble_leaf_and_candidates",
    "perception.leg_forest._leaves4": f"{HERE}::test_ensemble_leaf_and_candidates",
    "perception.leg_forest.block_probabilities": f"{HERE}::test_block_probabilities",
    "perception.leg_forest.block_probabilities_parallel": f"{HERE}::test_block_probabilities",
    "perception.leg_features.segment_features": f"{DRIVERS}::test_segment_features",
    # perception: landmarks
    "perception.landmarks._beyond": f"{DRIVERS}::test_beyond",
    "perception.landmarks._benches": f"{DRIVERS}::test_benches",
    "perception.landmark_database.accumulate": f"{DRIVERS}::test_accumulate_and_hide_bench_supports",
    "perception.landmark_database._fold": f"{DRIVERS}::test_accumulate_and_hide_bench_supports",
    "perception.landmark_database._hide_bench_supports": f"{DRIVERS}::test_accumulate_and_hide_bench_supports",
}
