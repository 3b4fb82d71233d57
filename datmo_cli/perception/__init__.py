"""Segmentation, Hough line and circle extraction, feature decision and landmarks."""
