"""Host-side point-cloud I/O and the training data pipeline."""
