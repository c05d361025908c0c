"""Benchmarks: scripts that time the training step, inference, RANSAC and registration
and print a table (docs/benchmarks.md)."""
