r"""Process KITTI odometry into 3DFeat-Net's registration layout (docs/method.md §6).

    python -m experiments.data.process_kitti --kitti_root=/data/kitti/dataset \
        --sequences=08,09,10 --out=/data/kitti_processed [--icp]

Writes OUT/<seq>/%06d.bin (N x 6, 0.2 m voxels + normals, named by frame index),
OUT/<seq>/groundtruths.txt (pairs < 10 m apart) and OUT/<seq>/poses.txt (the
velodyne-frame poses of the kept frames). With --icp each pair's pose is refined
by point-to-plane ICP started at KITTI's pose; groundtruths.txt then holds the
refined pose, groundtruths_kitti.txt KITTI's own, and the differences (how far
KITTI's GPS/INS pose was off) are printed and written to icp_corrections.txt.
"""

from absl import app
from absl import flags
import numpy as np

from ssd_jax.infra import cli
from ssd_jax.data import kitti
from ssd_jax.registration import pair_stages

FLAGS = flags.FLAGS
flags.DEFINE_string('kitti_root', None, 'Folder holding sequences/ and poses/.')
flags.DEFINE_list('sequences', ['08', '09', '10'], 'Sequences to process.')
flags.DEFINE_string('out', None, 'Output folder.')
flags.DEFINE_float('spacing', 10.0, 'Keep a cloud every this many metres of travel.')
flags.DEFINE_float('pair_distance', 10.0, 'Pair kept clouds closer than this (metres).')
flags.DEFINE_float('voxel_size', 0.2, 'Voxel grid (metres).')
flags.DEFINE_float('normal_radius', 1.0, 'Normal estimation radius (metres).')
flags.DEFINE_bool('icp', False, 'Refine each pair pose by ICP and report the corrections.')
flags.mark_flags_as_required(['kitti_root', 'out'])


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  for seq in FLAGS.sequences:
    n, m, corr = kitti.process_sequence(
        FLAGS.kitti_root, seq, FLAGS.out, FLAGS.spacing, FLAGS.pair_distance,
        FLAGS.voxel_size, FLAGS.normal_radius, pair_stages.refine_icp if FLAGS.icp else None)
    line = f'sequence {seq}: {n} clouds, {m} pairs'
    if corr:
      dt = np.array([c['rte'] for c in corr])
      dr = np.array([c['rre_geodesic'] for c in corr])
      line += (f'; ICP moved KITTI poses by median {np.median(dt):.3f} m / {np.median(dr):.3f} deg,'
               f' max {dt.max():.3f} m / {dr.max():.3f} deg')
    print(line)


if __name__ == '__main__':
  cli.run(main)
