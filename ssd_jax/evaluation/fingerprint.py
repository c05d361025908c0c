"""Stage fingerprints: a short hash of what each stage of an evaluation produced (the
test files, keypoints, descriptors, model weights, per-pair registration results) and
the software and CPU that produced it. Two reports that differ in a table can be
compared stage by stage: the first stage whose hash differs is where they parted.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
from importlib import metadata
from typing import Iterable, Mapping

import jax
import numpy as np

PACKAGES = ('numpy', 'scipy', 'jax', 'jaxlib', 'flax', 'optax', 'orbax-checkpoint', 'open3d')


def digest(arrays: Iterable[np.ndarray]) -> str:
  """12 hex digits of SHA-256 over each array's dtype, shape and bytes, in order."""
  h = hashlib.sha256()
  for a in arrays:
    a = np.ascontiguousarray(a)
    h.update(f'{a.dtype.str}{a.shape}'.encode())
    h.update(a.tobytes())
  return h.hexdigest()[:12]


def params_digest(variables) -> str:
  """digest of a model's parameters and statistics (pytree leaves in tree order)."""
  return digest(np.asarray(leaf) for leaf in jax.tree.leaves(jax.device_get(variables)))


def registration_digests(jsonl_path: str | os.PathLike) -> dict[str, str]:
  """Per row of a `*_pairs.jsonl` registration log: digest of every pair's trials,
  inliers, RTE and RRE (exact floats, as logged)."""
  values: dict[str, list] = {}
  with open(jsonl_path) as f:
    for line in f:
      r = json.loads(line)
      values.setdefault(r['row'], []).append([r['trials'], r['inliers'], r['rte'], r['rre']])
  return {row: digest([np.asarray(v, np.float64)]) for row, v in values.items()}


def _cpu() -> str:
  try:
    with open('/proc/cpuinfo') as f:
      info = f.read()
  except OSError:
    return platform.processor() or platform.machine()
  model = next((l.split(':', 1)[1].strip() for l in info.splitlines()
                if l.startswith('model name')), platform.machine())
  flags = next((l.split(':', 1)[1].split() for l in info.splitlines()
                if l.startswith('flags')), [])
  isa = [f for f in ('avx2', 'fma', 'avx512f') if f in flags]
  return f'{model} ({os.cpu_count()} cores; {", ".join(isa) or "no AVX2"})'


def environment() -> dict[str, str]:
  """The software and CPU of this process: what a fingerprint depends on."""
  env = {'python': platform.python_version(), 'cpu': _cpu(),
         'jax backend': jax.default_backend()}
  for name in PACKAGES:
    try:
      env[name] = metadata.version(name)
    except metadata.PackageNotFoundError:
      env[name] = 'not installed'
  return env


def markdown(stages: Mapping[str, str], env: Mapping[str, str]) -> str:
  """The report's fingerprint section: the environment, then one row per stage."""
  lines = ['| environment | |', '|---|---|']
  lines += [f'| {k} | {v} |' for k, v in env.items()]
  lines += ['', '| stage | fingerprint |', '|---|---|']
  lines += [f'| {k} | `{v}` |' for k, v in stages.items()]
  return '\n'.join(lines)
