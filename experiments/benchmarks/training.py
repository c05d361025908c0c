r"""Training-step benchmark: speed, achieved FLOP rate, compile time and peak memory.

    python -m experiments.benchmarks.training                       # paper + paper_small configs
    python -m experiments.benchmarks.training --configs=paper_small --steps=10

Prints one table row per config plus this machine's JAX fp32 matmul rate
(2048 x 2048, jit, median) as the ceiling. FLOPs are counted analytically
over the dense layers (training = 3 x forward: forward, input and weight
gradients), as in docs/notes/speed.md; XLA's own count of the compiled step is
shown beside it. Each config runs in a fresh subprocess so its peak RSS is
its own. A breakdown of the paper config's step (FPS, ball query, network)
shows where the time goes.
"""

import importlib
import json
import os
import resource
import subprocess
import sys
import time

from ssd_jax.infra import cli, runtime

runtime.reexec_with_hugepages()

from absl import app  # pylint: disable=g-import-not-at-top,wrong-import-position
from absl import flags
import jax
import jax.numpy as jnp
import numpy as np

from ssd_jax import grouping, train  # pylint: disable=g-import-not-at-top,wrong-import-position

FLAGS = flags.FLAGS
flags.DEFINE_list('configs', ['paper', 'paper_small'], 'Config modules under configs/training/.')
flags.DEFINE_integer('steps', 5, 'Timed steps per config (after compilation).')
flags.DEFINE_bool('breakdown', True, 'Also time the parts of the paper-config step.')
flags.DEFINE_string('child', None, 'Internal: benchmark this one config and print JSON.')


def _median_seconds(fn, *args, repeats: int = 5) -> float:
  jax.block_until_ready(fn(*args))
  times = []
  for _ in range(repeats):
    t = time.perf_counter()
    jax.block_until_ready(fn(*args))
    times.append(time.perf_counter() - t)
  return float(np.median(times))


def matmul_ceiling_gflops(n: int = 2048) -> float:
  a = jax.random.normal(jax.random.key(0), (n, n), jnp.float32)
  b = jax.random.normal(jax.random.key(1), (n, n), jnp.float32)
  return 2 * n ** 3 / _median_seconds(jax.jit(jnp.matmul), a, b, repeats=10) / 1e9


def forward_flops(config) -> float:
  """Dense-layer FLOPs of one forward pass of both branches (2B clouds)."""
  m = config.model
  clouds = 2 * config.train.batch_size
  points = clouds * m.num_clusters * m.num_samples
  clusters = clouds * m.num_clusters
  hidden = 256 if m.descriptor_dim > 64 else 128
  per_point = (3 * 64 + 64 * 128 + 128 * 256          # detector point MLP
               + 3 * 32 + 32 * 64 + 128 * hidden)      # descriptor point MLPs
  per_cluster = 256 * 128 + 128 * 64 + 64 * 3 + hidden * m.descriptor_dim
  return 2.0 * (points * per_point + clusters * per_cluster)


def synthetic_batch(config, seed: int = 0) -> np.ndarray:
  """Street-like random clouds: 40 m x 40 m, 4 m tall (ball sizes as in real scans)."""
  rng = np.random.default_rng(seed)
  shape = (config.train.batch_size, config.data.num_points, 3)
  return (rng.uniform(-1, 1, shape) * np.array([20.0, 20.0, 2.0])).astype(np.float32)


def bench_config(name: str, steps: int, breakdown: bool) -> dict:
  config = importlib.import_module(f'ssd_jax.configs.training.{name}').get_config()
  mesh = train.make_mesh()
  step = train.jit_train_step(config, mesh)
  state = train.replicate(train.create_train_state(config, jax.random.key(0)), mesh)
  batch = synthetic_batch(config)
  points = train.shard_batch(batch, mesh, len(batch))   # one process: all rows are local
  t = time.perf_counter()
  compiled = step.lower(state, points).compile()
  compile_s = time.perf_counter() - t
  cost = compiled.cost_analysis()
  cost = cost[0] if isinstance(cost, (list, tuple)) else cost
  state, metrics = compiled(state, points)
  jax.block_until_ready(metrics)
  times = []
  for _ in range(steps):
    t = time.perf_counter()
    state, metrics = compiled(state, points)
    jax.block_until_ready(metrics)
    times.append(time.perf_counter() - t)
  step_s = float(np.median(times))
  flops = 3 * forward_flops(config)
  row = {'config': name, 'batch': config.train.batch_size, 'points': config.data.num_points,
         'clusters': config.model.num_clusters, 'samples': config.model.num_samples,
         'step_s': step_s, 'steps_per_s': 1 / step_s, 'compile_s': compile_s,
         'train_gflop': flops / 1e9, 'xla_gflop': float(cost.get('flops', 0.0)) / 1e9,
         'gflops': flops / step_s / 1e9,
         'peak_rss_gb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20}
  stats = jax.devices()[0].memory_stats() or {}
  if 'peak_bytes_in_use' in stats:
    row['peak_device_gb'] = stats['peak_bytes_in_use'] / 2 ** 30
  if breakdown:
    row['breakdown'] = time_parts(config)
  return row


def time_parts(config) -> dict:
  """Seconds of FPS, ball query + grouping and network forward+backward, alone."""
  m = config.model
  both = jnp.asarray(np.concatenate([synthetic_batch(config)] * 2))
  valid = jnp.ones(both.shape[:2], bool)
  fps = jax.jit(lambda p: grouping.sample_centers(jax.random.key(0), p, valid, m.num_clusters,
                                                  'fps')[0])
  idx = fps(both)
  centers = jnp.take_along_axis(both, idx[..., None], 1)
  group = jax.jit(lambda p, c: grouping.extract_clusters(p, valid, c, m.radius, m.num_samples)[0])
  clusters = group(both, centers)
  model = train.create_model(config)
  state = train.create_train_state(config, jax.random.key(0))

  def net(params):
    (desc, _, angle), _ = model.apply({'params': params, 'batch_stats': state.batch_stats},
                                      clusters, train=True, mutable=['batch_stats'])
    return jnp.sum(desc) + jnp.sum(angle)

  return {'fps_s': _median_seconds(fps, both, repeats=3),
          'ball_query_group_s': _median_seconds(group, both, centers, repeats=3),
          'network_fwd_s': _median_seconds(jax.jit(net), state.params, repeats=3),
          'network_fwd_bwd_s': _median_seconds(jax.jit(jax.grad(net)), state.params, repeats=3)}


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  if FLAGS.child:
    print('RESULT ' + json.dumps(bench_config(FLAGS.child, FLAGS.steps,
                                               FLAGS.breakdown and FLAGS.child == 'paper')))
    return
  ceiling = matmul_ceiling_gflops()
  rows = []
  for name in FLAGS.configs:
    out = subprocess.run([sys.executable, '-m', 'experiments.benchmarks.training',
                          f'--child={name}', f'--steps={FLAGS.steps}',
                          f'--breakdown={FLAGS.breakdown}'],
                         capture_output=True, text=True, check=False)
    lines = [l for l in out.stdout.splitlines() if l.startswith('RESULT ')]
    if out.returncode or not lines:
      raise SystemExit(f'benchmark of {name} failed:\n{out.stderr[-3000:]}')
    rows.append(json.loads(lines[-1][len('RESULT '):]))
  device = jax.devices()[0]
  print(f'\nDevice: {device.device_kind} ({device.platform}), {jax.device_count()} device(s); '
        f'JAX {jax.__version__}')
  hugepages = 'glibc.malloc.hugetlb=1' in os.environ.get('GLIBC_TUNABLES', '')
  print(f'Matmul ceiling (fp32 2048^2, jit): {ceiling:.1f} GFLOP/s; '
        f'malloc huge pages: {"on" if hugepages else "off (SSD_JAX_NO_REEXEC)"}\n')
  print('| config | B x N, k x c | step (s) | steps/s | compile (s) | train GFLOP/step '
        '(XLA count) | GFLOP/s | % of matmul | peak RSS (GB) |')
  print('|---|---|---|---|---|---|---|---|---|')
  for r in rows:
    print(f"| {r['config']} | {r['batch']} x {r['points']}, {r['clusters']} x {r['samples']} | "
          f"{r['step_s']:.3f} | {r['steps_per_s']:.2f} | {r['compile_s']:.1f} | "
          f"{r['train_gflop']:.1f} ({r['xla_gflop']:.1f}) | {r['gflops']:.1f} | "
          f"{100 * r['gflops'] / ceiling:.0f} % | {r['peak_rss_gb']:.2f} |")
  for r in rows:
    if 'breakdown' in r:
      parts = ', '.join(f'{k[:-2]} {v:.2f} s' for k, v in r['breakdown'].items())
      print(f"\n{r['config']} step parts, each alone: {parts}")


if __name__ == '__main__':
  cli.run(main)
