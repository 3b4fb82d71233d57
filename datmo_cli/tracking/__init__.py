"""Kalman tracking, association, track life cycle and classification."""
