"""Keep the console readable: library INFO chatter (orbax) goes to WARNING and up."""

from __future__ import annotations

import logging as py_logging

from absl import logging

_NOISY = ('/orbax/', '/tensorstore/', '/etils/', 'xla_bridge.py')


class _LibraryFilter(py_logging.Filter):

  def filter(self, record: py_logging.LogRecord) -> bool:
    path = record.pathname.replace('\\', '/')
    return record.levelno >= py_logging.WARNING or not any(n in path for n in _NOISY)


def quiet_libraries() -> None:
  """Drop INFO records of noisy libraries from the absl handler (idempotent)."""
  handler = logging.get_absl_handler()
  if not any(isinstance(f, _LibraryFilter) for f in handler.filters):
    handler.addFilter(_LibraryFilter())
