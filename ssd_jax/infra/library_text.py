"""Every place the project reads another library's wording, in one module.

JAX, orbax and tensorstore report some failures only as text: a C++ fatal line, an
exception message, a traceback Python prints for a coroutine nobody awaited. To turn
them into one line naming the cause, the project matches that text, and an upgrade that
rewords it would silently bring back the stack traces. So each pattern lives here, and a
test makes the library produce the real text and checks the pattern still matches it:

| pattern | library | test that pins it |
|---|---|---|
| `jax_fatal_status`, `jax_stop_reason` | JAX's coordination service | `test_distributed.py::test_a_process_that_never_joins_ends_the_run_in_one_line` |
| `PEER_FAILURE` | gloo, NCCL, JAX's coordination service | `test_distributed.py::test_a_killed_process_stops_the_run_and_the_rerun_resumes` |
| `is_failed_array_read` | orbax, tensorstore | `test_checkpoint.py::test_damaged_newest_checkpoint_falls_back_or_is_named` |
| `first_line` | orbax, tensorstore | the same |
| `config_load_error` | ml_collections | `test_cli.py::test_cli_mistakes_end_in_one_line` |
"""

from __future__ import annotations

import re

# JAX's fatal line when its coordination service gives up on this process, e.g.
# "F1203 ... Terminating process because the JAX distributed service detected fatal
# errors. ... absl::Status: DEADLINE_EXCEEDED: ...".
_JAX_FATAL = re.compile(r'^F\d{4} .*(Terminating process because the JAX distributed service'
                        r'.*?)(absl::Status: (.*))?$')

# ml_collections' prefixes of a --config file that does not load, before the file's own
# error, in any order: "Configuration is not available because of an earlier failure to
# load: ", "Failed loading config file config_config ", "Attempted [Relative path]: ".
_CONFIG_LOAD_PREFIX = re.compile(r'^(?:Failed loading config file \S+ |Configuration is not '
                                 r'available because of an earlier failure to load: |'
                                 r'Attempted \[[^\]]*\]: )+')


def config_load_error(message: str) -> str:
  """ml_collections' one-line message for a --config file that does not load -> the
  file's own error (e.g. "configs/x.py [Errno 2] No such file or directory: ...")."""
  return _CONFIG_LOAD_PREFIX.sub('', message)


# What a collective or a coordination call says when its peer process is gone.
PEER_FAILURE = ('Gloo', 'NCCL', 'Connection reset', 'Connection closed', 'DEADLINE_EXCEEDED',
                'UNAVAILABLE', 'heartbeat')


def jax_fatal_status(line: str) -> str | None:
  """The status of JAX's fatal coordination line (its absl::Status, else the sentence),
  or None for any other line."""
  fatal = _JAX_FATAL.match(line.rstrip('\r\n'))
  return (fatal.group(3) or fatal.group(1)) if fatal else None


def jax_stop_reason(status: str) -> str:
  """'never_joined', 'peer_stopped' or 'other' for a status of `jax_fatal_status`."""
  if 'DEADLINE_EXCEEDED' in status:
    return 'never_joined'
  if any(k in status for k in ('unhealthy', 'heartbeat', 'Shutdown barrier', 'UNAVAILABLE')):
    return 'peer_stopped'
  return 'other'


def names_a_peer_failure(text: str) -> bool:
  """True when an error's text is what a collective says once its peer process is gone."""
  return any(marker in text for marker in PEER_FAILURE)


def is_failed_array_read(unraisable) -> bool:
  """An orbax array read of a damaged checkpoint failing after the first one was
  reported: the coroutine, or the tensorstore error it left in a future (an object of
  `sys.unraisablehook`)."""
  name = getattr(unraisable.object, '__qualname__', '') or repr(unraisable.object)
  return '_read_array' in name or names_a_failed_array_read(str(unraisable.exc_value))


def names_a_failed_array_read(text: str) -> bool:
  """True when an error's text (or a log line quoting it, such as asyncio's "Future
  exception was never retrieved") is an orbax array read of a damaged checkpoint."""
  return ('Encountered error while reading array' in text
          or ('OUT_OF_RANGE' in text and 'OCDBT' in text) or 'Event loop is closed' in text)


def first_line(error: Exception) -> str:
  """One line of an orbax / tensorstore / JSON error, which may span a hundred."""
  line = (str(error).strip().splitlines() or [''])[0].split('. See full TensorStore')[0]
  return f'{type(error).__name__}: {line[:160]}' if line else type(error).__name__
