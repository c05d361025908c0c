"""Benchmarks: scripts that time the training step, inference and registration and
print a table (docs/benchmarks.md)."""
