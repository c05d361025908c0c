"""ssd_jax.infra.runtime: the huge-page malloc setting and the one-time re-execution."""

import os
import platform
import subprocess
import sys

import pytest

from ssd_jax.infra import runtime

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_hugepage_env_adds_the_tunable_once_and_keeps_others():
  env = runtime.hugepage_env({'GLIBC_TUNABLES': 'glibc.malloc.arena_max=2', 'A': '1'})
  assert env == {'GLIBC_TUNABLES': 'glibc.malloc.arena_max=2:glibc.malloc.hugetlb=1', 'A': '1'}
  assert runtime.hugepage_env(env) == env
  assert runtime.hugepage_env({})['GLIBC_TUNABLES'] == 'glibc.malloc.hugetlb=1'


@pytest.mark.multiprocess
@pytest.mark.skipif(platform.libc_ver()[0] != 'glibc', reason='glibc only')
def test_entry_points_reexecute_once_unless_opted_out():
  script = ('from ssd_jax.infra import runtime\n'
            'print("start", flush=True)\n'
            'runtime.reexec_with_hugepages()\n'
            'import os; print(os.environ.get("GLIBC_TUNABLES", ""))\n')
  env = {k: v for k, v in os.environ.items()
         if k not in ('GLIBC_TUNABLES', 'SSD_JAX_NO_REEXEC', '_SSD_JAX_REEXECED')}
  run = lambda extra: subprocess.run([sys.executable, '-c', script], cwd=ROOT, text=True,
                                     env={**env, **extra}, capture_output=True, timeout=60)
  out = run({}).stdout.split()
  assert out == ['start', 'start', 'glibc.malloc.hugetlb=1']    # ran twice, then with it set
  assert run({'SSD_JAX_NO_REEXEC': '1'}).stdout.split() == ['start']
  preset = run({'GLIBC_TUNABLES': 'glibc.malloc.hugetlb=1'}).stdout.split()
  assert preset == ['start', 'glibc.malloc.hugetlb=1']
