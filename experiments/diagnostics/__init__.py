"""Diagnostics: figures and reports that look inside a model or a data set."""
