"""Process-level settings that make XLA:CPU training fast.

XLA:CPU allocates its activation buffers (hundreds of MB each at the paper
config) afresh every step. With 4 KiB pages each step then takes ~10^6 page
faults; letting glibc's malloc back large blocks with transparent huge pages
(`GLIBC_TUNABLES=glibc.malloc.hugetlb=1`) measured 1.8x faster steps on the
project's 2-core machine (experiments/benchmarks/training.py, README). glibc reads the
tunable at process start only, so entry points re-execute themselves once
with it set. Set SSD_JAX_NO_REEXEC=1 to opt out.
"""

from __future__ import annotations

import os
import platform
import sys

_TUNABLE = 'glibc.malloc.hugetlb=1'


def _wants_reexec(env) -> bool:
  if platform.system() != 'Linux' or platform.libc_ver()[0] != 'glibc':
    return False
  if env.get('SSD_JAX_NO_REEXEC') or env.get('_SSD_JAX_REEXECED'):
    return False
  return 'glibc.malloc.hugetlb' not in env.get('GLIBC_TUNABLES', '')


def hugepage_env(env=None) -> dict:
  """A copy of `env` (default os.environ) with the huge-page malloc tunable added."""
  env = dict(os.environ if env is None else env)
  tunables = env.get('GLIBC_TUNABLES', '')
  if 'glibc.malloc.hugetlb' not in tunables:
    env['GLIBC_TUNABLES'] = f'{tunables}:{_TUNABLE}' if tunables else _TUNABLE
  return env


def reexec_with_hugepages() -> None:
  """Re-run this exact command line with huge-page malloc, if not yet set.

  Call first thing in an entry point (before JAX allocates anything). Returns
  without doing anything where the setting is already present, not applicable,
  or opted out.
  """
  if not _wants_reexec(os.environ):
    return
  env = hugepage_env()
  env['_SSD_JAX_REEXECED'] = '1'
  sys.stdout.flush()
  sys.stderr.flush()
  os.execve(sys.executable, list(sys.orig_argv), env)
