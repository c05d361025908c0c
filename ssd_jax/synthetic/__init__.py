"""Synthetic LiDAR street scenes with exact poses: the project's embedded default data."""
