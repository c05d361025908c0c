r"""Inference speed on a 16,384-point cloud: learned descriptors (host KD-tree
neighbourhoods, and `describe_fn`, the pure JAX function) and attention beside Open3D
FPFH on the same keypoints.

    python -m experiments.benchmarks.inference [--cloud=../shared/data/example/oxford_270.bin]

Without --cloud a synthetic Oxford-style test model is made on the fly. The
network has the paper's shape (D 32, 64 points per 2 m cluster, random weights:
speed does not depend on the values).
"""

import time

from absl import app
from absl import flags
import jax
import numpy as np

from ssd_jax.configs.training import paper
from ssd_jax.configs.data import synthetic
from ssd_jax import inference, train
from ssd_jax.infra import cli
from ssd_jax.data import io, preprocess
from ssd_jax.synthetic import dataset
from ssd_jax.registration import features

FLAGS = flags.FLAGS
flags.DEFINE_string('cloud', None, 'A cloud file; default: a synthetic 16,384-point model.')
flags.DEFINE_integer('keypoints', 1024, 'Keypoints to describe.')
flags.DEFINE_integer('repeats', 3, 'Timed repeats (median).')


def _cloud():
  if FLAGS.cloud:
    return io.read_cloud(FLAGS.cloud)
  drive = dataset.make_drive(synthetic.get_config(), 'test_oxford', 0)
  pts = preprocess.voxel_downsample(drive.scan(3), 0.2)
  pts = pts[np.linalg.norm(pts[:, :2], axis=1) < 30]
  return pts[np.random.default_rng(0).choice(len(pts), 16384, replace=len(pts) < 16384)]


def _time(fn):
  fn()
  times = []
  for _ in range(FLAGS.repeats):
    start = time.perf_counter()
    fn()
    times.append(time.perf_counter() - start)
  return float(np.median(times))


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  config = paper.get_config()
  state = train.create_train_state(config, jax.random.key(0))
  model = inference.Model.from_config(config, {'params': state.params,
                                               'batch_stats': state.batch_stats})
  pts = _cloud()
  kp_idx = np.random.default_rng(1).choice(len(pts), FLAGS.keypoints, replace=False)
  kp = pts[kp_idx]
  pure_jax = jax.jit(inference.describe_fn(model))
  rows = [
      (f'learned descriptors, {FLAGS.keypoints} keypoints, KD-tree neighbourhoods',
       _time(lambda: inference.describe(model, pts, kp))),
      (f'learned descriptors, {FLAGS.keypoints} keypoints, `describe_fn` jitted (dense ball query)',
       _time(lambda: pure_jax(pts, kp).block_until_ready())),
      (f'attention for all {len(pts):,} points, KD-tree',
       _time(lambda: inference.attention(model, pts))),
      (f'Open3D FPFH, same {FLAGS.keypoints} keypoints, 4 m, every neighbour (the default)',
       _time(lambda: features.fpfh(pts, kp_idx))),
      (f'Open3D FPFH, same {FLAGS.keypoints} keypoints, 4 m, neighbour cap 1000',
       _time(lambda: features.fpfh(pts, kp_idx, max_nn=1000))),
      (f'Open3D FPFH, same {FLAGS.keypoints} keypoints, 4 m, neighbour cap 200',
       _time(lambda: features.fpfh(pts, kp_idx, max_nn=200))),
  ]
  print(f'\n{len(pts):,}-point cloud, {jax.devices()[0].platform.upper()}, median of '
        f'{FLAGS.repeats}\n')
  print('| step | seconds |\n|---|---|')
  for name, t in rows:
    print(f'| {name} | {t:.2f} |')


if __name__ == '__main__':
  cli.run(main)
