r"""Process KITTI odometry into 3DFeat-Net's registration layout (docs/method.md §6).

    python -m experiments.process_kitti --kitti_root=/data/kitti/dataset \
        --sequences=08,09,10 --out=/data/kitti_processed [--icp]

Writes OUT/<seq>/%06d.bin (N x 6, 0.2 m voxels + normals, named by frame index),
OUT/<seq>/groundtruths.txt (pairs < 10 m apart) and OUT/<seq>/poses.txt (the
velodyne-frame poses of the kept frames). With --icp each pair's pose is refined
by point-to-point ICP started at KITTI's pose; groundtruths.txt then holds the
refined pose, groundtruths_kitti.txt KITTI's own, and the differences (how far
KITTI's GPS/INS pose was off) are printed and written to icp_corrections.txt.
"""

import os

from absl import app
from absl import flags
import numpy as np
from tqdm import auto as tqdm

from ssd_jax import cli
from ssd_jax.data import groundtruth, io, kitti, preprocess
from ssd_jax.registration import metrics, pipeline

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


def process_sequence(root, seq, out, spacing, pair_distance, voxel, normal_radius, icp):
  tr = kitti.read_velodyne_to_camera(os.path.join(root, 'sequences', seq, 'calib.txt'))
  poses = kitti.velodyne_poses(kitti.read_poses(os.path.join(root, 'poses', f'{seq}.txt')), tr)
  kept = kitti.keyframes(poses[:, :3, 3], spacing)
  folder = os.path.join(out, seq)
  os.makedirs(folder, exist_ok=True)
  clouds = {}
  for i in tqdm.tqdm(kept, desc=f'sequence {seq}', unit='cloud'):
    raw = io.read_cloud(os.path.join(root, 'sequences', seq, 'velodyne', f'{i:06d}.bin'), 'xyzi')
    pts, normals = preprocess.process_scan(raw[np.all(np.isfinite(raw), 1)], voxel,
                                           normal_radius)
    io.write_bin(os.path.join(folder, f'{i:06d}.bin'), pts, normals)
    clouds[int(i)] = pts
  kitti.write_poses(os.path.join(folder, 'poses.txt'), poses[kept])
  pairs = [groundtruth.GroundTruthPair(int(kept[a]), int(kept[b]),
                                       groundtruth.relative_pose(poses, kept[a], kept[b]))
           for a, b in groundtruth.close_pairs(poses[kept, :3, 3], pair_distance)]
  corrections = []
  if icp:
    groundtruth.write_groundtruths(os.path.join(folder, 'groundtruths_kitti.txt'), pairs)
    refined = []
    for p in pairs:
      t, fitness = pipeline.refine_icp(clouds[p.idx1], clouds[p.idx2], p.transform)
      refined.append(groundtruth.GroundTruthPair(p.idx1, p.idx2, t))
      corrections.append({'idx1': p.idx1, 'idx2': p.idx2, 'fitness': fitness,
                          **metrics.registration_errors(p.transform, t)})
    pairs = refined
    with open(os.path.join(folder, 'icp_corrections.txt'), 'w') as f:
      f.write('idx1\tidx2\tfitness\tdelta_t_m\tdelta_r_deg\n')
      for c in corrections:
        f.write(f'{c["idx1"]}\t{c["idx2"]}\t{c["fitness"]:.3f}\t{c["rte"]:.3f}\t'
                f'{c["rre_geodesic"]:.3f}\n')
  groundtruth.write_groundtruths(os.path.join(folder, 'groundtruths.txt'), pairs)
  return len(kept), len(pairs), corrections


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  for seq in FLAGS.sequences:
    try:
      n, m, corr = process_sequence(FLAGS.kitti_root, seq, FLAGS.out, FLAGS.spacing,
                                    FLAGS.pair_distance, FLAGS.voxel_size, FLAGS.normal_radius,
                                    FLAGS.icp)
    except io.CloudFileError as e:
      raise SystemExit(f'error: {e}') from None
    line = f'sequence {seq}: {n} clouds, {m} pairs'
    if corr:
      dt = np.array([c['rte'] for c in corr])
      dr = np.array([c['rre_geodesic'] for c in corr])
      line += (f'; ICP moved KITTI poses by median {np.median(dt):.3f} m / {np.median(dr):.3f} deg,'
               f' max {dt.max():.3f} m / {dr.max():.3f} deg')
    print(line)


if __name__ == '__main__':
  cli.run(main)
