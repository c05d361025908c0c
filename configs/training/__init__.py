"""Training recipes: the shipped models' configs (docstrings carry the command and the
expected result), the paper's, and experiments.adapt's."""
