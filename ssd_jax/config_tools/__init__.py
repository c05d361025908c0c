"""Config checking (`checks`: every value named in one line before any work) and
upgrading (`upgrade`: a stored config of an older layout read into today's)."""
