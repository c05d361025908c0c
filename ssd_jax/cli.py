"""Command-line plumbing shared by the scripts in experiments/: a flag or config
override that cannot be parsed ends in one line and exit status 2, not a traceback."""

from __future__ import annotations

import sys
from typing import Callable, Sequence

from absl import app
from absl import flags
from ml_collections import config_flags


def _one_line(text: str) -> str:
  return ' '.join(part.strip() for part in text.splitlines() if part.strip())


def parse_flags(argv: Sequence[str]) -> list[str]:
  """absl's flag parsing, with ml_collections' config errors made one line: an
  unknown `--config.a.b` key, a value of the wrong type, a missing config file."""
  try:
    rest = flags.FLAGS(argv)
    for name in flags.FLAGS:
      # ml_collections keeps a config file's load error until the config is first used.
      getattr(getattr(flags.FLAGS, name), 'keys', None)
    return rest
  except OSError as e:   # a --config file that is missing or does not load
    message = _one_line(str(e)).replace('Failed loading config file config_config ', '')
  except flags.Error as e:
    lines = [l for l in str(e).splitlines() if l.strip()]
    # A config file that raises: the flag and the exception, not the traceback between.
    message = _one_line(lines[0] + ' ' + lines[-1] if len(lines) > 2 else str(e))
  except (AttributeError, KeyError, TypeError, ValueError) as e:
    message = _override_message(e, argv)
  _exit(message)


def _override_message(error: Exception, argv: Sequence[str]) -> str:
  if isinstance(error, (AttributeError, KeyError)):
    # ml_collections raises these for a --config.* field the config does not have.
    overrides = [a.split('=')[0] for a in argv[1:] if a.startswith('--config')]
    return (f'the config has no field {_one_line(str(error))}; check the overrides '
            f'{overrides} against the config file')
  return f'bad --config override: {_one_line(str(error))}'


def _exit(message: str) -> None:
  sys.stderr.write(f'error: {message}\n')
  sys.exit(2)


def define_config_file(name: str, default: str | None = None, help_string: str = '',
                       **kwargs):
  """`config_flags.DEFINE_config_file`, whose overrides of a default file are parsed
  at definition: a bad `--NAME.key=value` there ends in one line too."""
  try:
    return config_flags.DEFINE_config_file(name, default, help_string, **kwargs)
  except (AttributeError, KeyError, TypeError, ValueError) as e:
    _exit(_override_message(e, sys.argv))


def run(main: Callable[[list[str]], None]) -> None:
  """`absl.app.run(main)` with `parse_flags`."""
  app.run(main, flags_parser=parse_flags)
