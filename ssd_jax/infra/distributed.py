"""One run over many processes, on JAX's own multi-process runtime (`jax.distributed`).

Every process runs the same command. `initialize` joins them when the flags or the
environment say there are several (explicit flags, `JAX_COORDINATOR_ADDRESS`, a Slurm
step or an Open MPI job of more than one task, a multi-host Cloud TPU); after it,
`jax.devices()` lists the devices of all processes and a `jax.sharding.Mesh` over them
spans the run. The helpers below split work over the processes (`local_rows` for a
global training batch, `map_items` for evaluation pairs) and gather it back (`gather`);
with one process they are plain loops.

JAX ends every process of a run when one of them dies, never joins, or cannot reach the
coordinator, but it does so with a C++ abort and a stack trace. So a multi-process
command runs its work in a child process and the command itself only watches: it passes
the child's output through, and turns such an abort into one line naming the cause and
exit status 1 (`_supervise`).
"""

from __future__ import annotations

import ctypes
import os
import pickle
import re
import signal
import subprocess
import sys
from typing import Callable, Mapping, Sequence, TypeVar

import jax
from jax.experimental import multihost_utils
import numpy as np

from ssd_jax.infra import library_text

T = TypeVar('T')
R = TypeVar('R')

_CHILD = '_SSD_JAX_DISTRIBUTED_CHILD'


class DistributedError(RuntimeError):
  """The processes of a run could not be joined (wrong settings)."""


def environment_has_many(environ: Mapping[str, str] | None = None) -> bool:
  """True when the launcher describes more than one process: `JAX_COORDINATOR_ADDRESS`,
  a Slurm step or Open MPI job of several tasks, or a Cloud TPU slice of several hosts."""
  env = os.environ if environ is None else environ
  if env.get('JAX_COORDINATOR_ADDRESS'):
    return True
  counts = (env.get('SLURM_NTASKS') if 'SLURM_STEP_ID' in env else None,
            env.get('OMPI_COMM_WORLD_SIZE'))
  if any(c and c.isdigit() and int(c) > 1 for c in counts):
    return True
  return len([h for h in env.get('TPU_WORKER_HOSTNAMES', '').split(',') if h]) > 1


def initialize(coordinator_address: str | None = None, num_processes: int | None = None,
               process_id: int | None = None, timeout_s: int = 300,
               heartbeat_s: int = 100) -> None:
  """Join this process to its run, if the run has several (see `environment_has_many`);
  otherwise do nothing. Call before any JAX computation.

  Arguments left None are found by `jax.distributed.initialize` from the environment
  (Slurm, Open MPI, Cloud TPU, `JAX_COORDINATOR_ADDRESS`). Processes that are not all
  joined within `timeout_s` seconds, or a process whose heartbeats stop for
  `heartbeat_s` seconds, end every process of the run with a one-line error.
  """
  explicit = (coordinator_address, num_processes, process_id)
  if all(v is None for v in explicit) and not environment_has_many():
    return
  if num_processes is not None and num_processes < 1:
    raise DistributedError(f'--num_processes={num_processes}: must be at least 1')
  if process_id is not None and num_processes is not None and not 0 <= process_id < num_processes:
    raise DistributedError(f'--process_id={process_id}: must be in [0, {num_processes})')
  if timeout_s < 1 or heartbeat_s < 1:
    raise DistributedError('the distributed timeouts must be at least 1 second')
  if not os.environ.get(_CHILD):
    _supervise(coordinator_address or os.environ.get('JAX_COORDINATOR_ADDRESS', 'auto'),
               num_processes, process_id, timeout_s, heartbeat_s)
  try:
    jax.distributed.initialize(coordinator_address, num_processes, process_id,
                               initialization_timeout=timeout_s,
                               heartbeat_timeout_seconds=heartbeat_s)
  except (RuntimeError, ValueError, TypeError) as e:
    raise DistributedError(f'jax.distributed.initialize: {str(e).splitlines()[0]}') from None


def _die_with_parent() -> None:
  """In the child, before exec: get SIGTERM when the watching process dies."""
  try:
    ctypes.CDLL('libc.so.6', use_errno=True).prctl(1, signal.SIGTERM)   # PR_SET_PDEATHSIG
  except OSError:
    pass


def _supervise(address: str, num_processes: int | None, process_id: int | None,
               timeout_s: int, heartbeat_s: int) -> None:
  """Run this command again as a child that does the work; pass its output through, end
  with its exit status, and turn JAX's abort into one line. Never returns."""
  env = dict(os.environ, **{_CHILD: '1'})
  sys.stdout.flush()
  sys.stderr.flush()
  child = subprocess.Popen(list(sys.orig_argv), env=env, stderr=subprocess.PIPE,
                           preexec_fn=_die_with_parent)
  for sig in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
    signal.signal(sig, lambda s, _: child.send_signal(s))
  status, reported, pending = None, False, b''
  while chunk := os.read(child.stderr.fileno(), 1 << 16):
    pending += chunk
    # tqdm redraws with '\r': pass those through as they come, not at the next '\n'.
    *lines, pending = re.split(rb'(?<=[\r\n])', pending)
    for raw in lines:
      fatal = library_text.jax_fatal_status(raw.decode(errors='replace'))
      if fatal is not None and status is None:
        status = fatal
      # After JAX's fatal line comes only the abort: the C++ and Python stack traces.
      if status is None:
        sys.stderr.buffer.write(raw)
        reported = reported or raw.startswith(b'error: ')
    sys.stderr.flush()
  if status is None:
    sys.stderr.buffer.write(pending)
  code = child.wait()
  if status is None or reported:   # the child said why, in its own one line
    sys.exit(code if code >= 0 else 128 - code)
  who = (f'process {process_id} of {num_processes}' if process_id is not None
         and num_processes is not None else 'this process')
  kind = library_text.jax_stop_reason(status)
  if kind == 'never_joined':
    reason = (f'not all {num_processes or "the"} processes joined the coordinator at {address} '
              f'within {timeout_s} s (is the coordinator address right, and did every '
              f'process start with the same --num_processes?)')
  elif kind == 'peer_stopped':
    reason = (f'another process of the run stopped (no heartbeat for {heartbeat_s} s); '
              f'{STOPPED_HINT}')
  else:
    reason = f'the JAX distributed runtime stopped the run: {status.strip()[:300]}'
  print(f'error: {who}: {reason}', file=sys.stderr)
  sys.exit(1)


STOPPED_HINT = ('every process stops. Rerun all of them with the same --workdir: training '
                'resumes from its last checkpoint')


def is_peer_failure(error: BaseException) -> bool:
  """True for an error that another process of a multi-process run stopping causes: a
  runtime error of a collective (gloo, NCCL), also when orbax or multihost_utils
  re-raise it as another type."""
  if jax.process_count() == 1:
    return False
  return (isinstance(error, jax.errors.JaxRuntimeError)
          or library_text.names_a_peer_failure(str(error)))


def fail(reason: str) -> None:
  """End this process of a run at once with `error: process P of N: reason`: a normal
  exit would wait in JAX's shutdown barrier for processes that are gone."""
  print(f'error: process {jax.process_index()} of {jax.process_count()}: {reason}',
        file=sys.stderr, flush=True)
  sys.stdout.flush()
  os._exit(1)


def is_main() -> bool:
  """True in the process that writes logs, reports and metrics (process 0)."""
  return jax.process_index() == 0


def local_rows(global_batch: int) -> range:
  """The rows of a global batch this process builds: a contiguous block, in process
  order, which is the order of a mesh over `jax.devices()` on its first axis."""
  n, p = jax.process_count(), jax.process_index()
  if global_batch % n:
    raise DistributedError(f'a global batch of {global_batch} does not split over {n} '
                           'processes; make train.batch_size a multiple of it')
  size = global_batch // n
  return range(p * size, (p + 1) * size)


def gather(obj: T) -> list[T]:
  """Every process's `obj` (any picklable value), in process order, on every process."""
  if jax.process_count() == 1:
    return [obj]
  data = np.frombuffer(pickle.dumps(obj), np.uint8)
  sizes = np.asarray(multihost_utils.process_allgather(np.array([data.size], np.int32)))
  padded = np.zeros(int(sizes.max()), np.uint8)
  padded[:data.size] = data
  parts = np.asarray(multihost_utils.process_allgather(padded))
  return [pickle.loads(parts[p, :int(sizes[p, 0])].tobytes()) for p in range(len(parts))]


def map_items(fn: Callable[[int, T], R], items: Sequence[T],
              wrap: Callable[[Sequence[int]], Sequence[int]] = lambda ns: ns) -> list[R]:
  """[fn(n, items[n]) for every n], each computed by one process (n modulo the process
  count) and gathered, in order, on every process. `wrap` may wrap this process's
  indices (a progress bar)."""
  mine = range(jax.process_index(), len(items), jax.process_count())
  done = {n: fn(n, items[n]) for n in wrap(mine)}
  if jax.process_count() > 1:
    for part in gather(done):
      done.update(part)
  return [done[n] for n in range(len(items))]


def barrier(name: str) -> None:
  """Wait until every process reaches the barrier called `name`."""
  if jax.process_count() > 1:
    multihost_utils.sync_global_devices(name)
