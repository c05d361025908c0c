"""Command-line plumbing shared by the scripts in experiments/: a flag or config
override that cannot be parsed ends in one line and exit status 2, not a traceback, and
`--config=configs/x.py` finds the project's own config from any working directory."""

from __future__ import annotations

import atexit
import ctypes
import importlib.util
import os
import sys
import threading
from typing import Callable, Sequence

from absl import app
from absl import flags
import jax
from ml_collections import config_flags
from tqdm import auto as tqdm

from ssd_jax.infra import distributed, errors, library_text


_CONFIG_FLAGS: set[str] = set()   # names of the flags defined by define_config_file


def configs_dir() -> str:
  """The folder of the project's configs (the repository's configs/, installed as
  ssd_jax.configs)."""
  return list(importlib.util.find_spec('ssd_jax.configs').submodule_search_locations)[0]


def resolve_config_path(value: str) -> str:
  """'configs/x.py[:arg]' -> the project's configs/x.py when no such file exists here,
  so the commands of the docs work from any directory; any other value unchanged."""
  path, sep, arg = value.partition(':')
  if os.path.exists(path) or not path.startswith('configs/'):
    return value
  packaged = os.path.join(configs_dir(), path[len('configs/'):])
  return packaged + sep + arg if os.path.exists(packaged) else value


def _resolve_config_args(argv: Sequence[str]) -> list[str]:
  out, follows = [], False
  for arg in argv:
    if follows:   # the value of a `--config PATH` pair
      arg, follows = resolve_config_path(arg), False
    else:
      for name in _CONFIG_FLAGS:
        if arg.startswith(f'--{name}='):
          arg = f'--{name}=' + resolve_config_path(arg[len(name) + 3:])
        follows = follows or arg == f'--{name}'
    out.append(arg)
  return out


def _one_line(text: str) -> str:
  return ' '.join(part.strip() for part in text.splitlines() if part.strip())


def parse_flags(argv: Sequence[str]) -> list[str]:
  """absl's flag parsing, with ml_collections' config errors made one line: an
  unknown `--config.a.b` key, a value of the wrong type, a missing config file."""
  try:
    rest = flags.FLAGS(_resolve_config_args(argv))
    for name in flags.FLAGS:
      # ml_collections keeps a config file's load error until the config is first used.
      getattr(getattr(flags.FLAGS, name), 'keys', None)
    return rest
  except OSError as e:   # a --config file that is missing or does not load
    message = _one_line(str(e))
  except flags.Error as e:
    lines = [l for l in str(e).splitlines() if l.strip()]
    # A config file that raises: the flag and the exception, not the traceback between.
    message = _one_line(lines[0] + ' ' + lines[-1] if len(lines) > 2 else str(e))
  except (AttributeError, KeyError, TypeError, ValueError) as e:
    message = _override_message(e, argv)
  _exit(library_text.config_load_error(message))


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
  at definition: a bad `--NAME.key=value` there ends in one line too. A default
  'configs/x.py' is the project's own file wherever the command runs."""
  _CONFIG_FLAGS.add(name)
  if default is not None:
    default = resolve_config_path(default)
  try:
    return config_flags.DEFINE_config_file(name, default, help_string, **kwargs)
  except (AttributeError, KeyError, TypeError, ValueError) as e:
    _exit(_override_message(e, sys.argv))


def default_compilation_cache() -> str:
  """$SSD_JAX_COMPILATION_CACHE, else $XDG_CACHE_HOME/ssd_jax/jax (~/.cache/ssd_jax/jax)."""
  if 'SSD_JAX_COMPILATION_CACHE' in os.environ:
    return os.environ['SSD_JAX_COMPILATION_CACHE']
  base = os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache')
  return os.path.join(base, 'ssd_jax', 'jax')


flags.DEFINE_string('compilation_cache', default_compilation_cache(),
                    "Folder of JAX's persistent compilation cache, so that a new process "
                    "loads the kernels an earlier one compiled ('' disables it).")


def enable_compilation_cache(directory: str) -> None:
  """Keep every compiled XLA program in `directory` ('' does nothing): a new process
  then loads the RANSAC, inference and training kernels instead of compiling them."""
  if not directory:
    return
  jax.config.update('jax_compilation_cache_dir', directory)
  # JAX caches only programs that took over a second to compile by default; the
  # kernels of one registration take less each but add up in a fresh process.
  jax.config.update('jax_persistent_cache_min_compile_time_secs', 0.0)
  jax.config.update('jax_persistent_cache_min_entry_size_bytes', 0)


def one_line_errors(main: Callable[[list[str]], None]) -> Callable[[list[str]], None]:
  """main, with the `errors.REPORTED` errors it raises (bad input: `errors.UserError`, and
  a library's ValueError or FileNotFoundError) ended as 'error: <message>' and exit
  status 1 (SystemExit), every other exception left as it is."""
  def wrapped(argv):
    try:
      return main(argv)
    except errors.REPORTED as e:
      raise SystemExit(f'error: {library_text.config_load_error(str(e))}') from None
  return wrapped


def run(main: Callable[[list[str]], None], fast_exit: bool = False) -> None:
  """`absl.app.run(main)` with `parse_flags`, and the compilation cache on; the
  `errors.REPORTED` errors of main end in one line, 'error: ...', and exit status 1.

  fast_exit: once main has succeeded, run the atexit hooks, flush, and end the process
  without the interpreter's teardown. Freeing the modules and objects of JAX, XLA and
  Open3D takes ~0.6 s on the 2-core VM, a sixth of a one-pair `register`
  (docs/notes/speed.md). Only for commands whose results are in closed files and
  flushed streams when main returns; a failure, or a non-daemon thread still running,
  exits the usual way.
  """
  def with_cache(argv):
    enable_compilation_cache(flags.FLAGS.compilation_cache)
    return one_line_errors(main)(argv)
  try:
    app.run(with_cache, flags_parser=parse_flags)
  except SystemExit as e:
    if fast_exit and e.code in (None, 0) and not _threads_a_normal_exit_joins():
      _exit_without_teardown()
    raise


def _threads_a_normal_exit_joins() -> list[threading.Thread]:
  return [t for t in threading.enumerate() if not t.daemon and t is not threading.main_thread()]


def _exit_without_teardown() -> None:
  """Exit status 0 right after what a normal exit does that matters: atexit hooks
  (absl's, JAX's, logging's) and flushing Python's and C's output buffers."""
  atexit._run_exitfuncs()  # pylint: disable=protected-access  (CPython's own exit step)
  sys.stdout.flush()
  sys.stderr.flush()
  if os.name == 'posix':   # the C library of the process itself, as dlopen(NULL) gives it
    ctypes.CDLL(None).fflush(None)   # C/C++ libraries' buffered stdout (Open3D's messages)
  os._exit(0)


def check_writable(path: str | None) -> None:
  """Create an output file's folder now, so that a bad path fails before the work."""
  if not path:
    return
  folder = os.path.dirname(os.path.abspath(path))
  try:
    os.makedirs(folder, exist_ok=True)
  except OSError as e:
    raise errors.UserError(f'cannot create the folder of {path}: {e.strerror}') from None
  if os.path.isdir(path) or not os.access(folder, os.W_OK):
    raise errors.UserError(f'{path}: cannot write a file there')


class StageBar:
  """A one-line progress bar of a command's stages on stderr (`enabled`: e.g. when stderr
  is a terminal): `stage(name)` as each starts, `say(line)` prints above the bar."""

  def __init__(self, total: int, enabled: bool, name: str):
    self._bar = tqdm.tqdm(total=total, unit='stage', leave=False, disable=not enabled,
                          bar_format=name + ' {n}/{total} [{elapsed}] {desc}')

  def stage(self, name: str) -> None:
    self._bar.set_description_str(name, refresh=False)
    self._bar.update(1)
    self._bar.refresh()   # update() redraws at most every 0.1 s: show a long stage's name

  def say(self, line: str) -> None:
    (print if self._bar.disable else self._bar.write)(line)

  def clear(self) -> None:
    """Off the screen until the next stage (which redraws it below what was printed)."""
    self._bar.clear()

  def close(self) -> None:
    self._bar.close()


def define_distributed_flags() -> None:
  """The flags that join the processes of one run (`distributed.initialize`)."""
  flags.DEFINE_string('coordinator_address', None,
                      'host:port of process 0, for a run over several processes (unset: '
                      'from JAX_COORDINATOR_ADDRESS, Slurm, Open MPI or Cloud TPU, or one '
                      'process).')
  flags.DEFINE_integer('num_processes', None, 'Processes in the run (unset: from the launcher).')
  flags.DEFINE_integer('process_id', None, "This process's index in [0, num_processes).")
  flags.DEFINE_integer('distributed_timeout', 300,
                       'Seconds to wait for every process to join; a process that stops '
                       'sending heartbeats for a third of this ends the run.')


def initialize_distributed() -> None:
  """`distributed.initialize` from the flags of `define_distributed_flags`; wrong
  settings end in one line and exit status 2."""
  f = flags.FLAGS
  try:
    distributed.initialize(f.coordinator_address, f.num_processes, f.process_id,
                           timeout_s=f.distributed_timeout,
                           heartbeat_s=max(1, f.distributed_timeout // 3))
  except distributed.DistributedError as e:
    _exit(str(e))
