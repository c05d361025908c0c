r"""Register two point clouds: print T_12, the 4 x 4 that maps cloud 2 into cloud 1's frame.

    python -m experiments.register --cloud1=A.bin --cloud2=B.bin \
        [--keypoints=iss|learned|random] [--descriptor=fpfh|learned|learned,fpfh] \
        [--checkpoint=ours|RUN_DIR|EXPORT_DIR] [--groundtruth=DIR/groundtruths.txt] \
        [--icp] [--json=OUT.json] [--plot=OUT.png]

Reads .bin (N x 3 / 4 / 6 float32 or float64 rows, detected or --format), .npy, .ply, .pcd. Learned
descriptors and keypoints come from the shipped pretrained models (`ours`, and
`ours_detector` for learned keypoints) unless --checkpoint names another.
With --groundtruth (a `groundtruths.txt` listing the pair by the clouds' file
stems, e.g. 000000.bin / 000001.bin), the errors against it are printed too.
"""

import json
import os
import time

from absl import app
from absl import flags
import numpy as np

from ssd_jax import cli, geometry, pretrained, viz
from ssd_jax.data import clean, groundtruth, io
from ssd_jax.logging_utils import quiet_libraries
from ssd_jax.registration import metrics, pipeline

FLAGS = flags.FLAGS
flags.DEFINE_string('cloud1', None, 'Target cloud (its frame is the output frame).')
flags.DEFINE_string('cloud2', None, 'Source cloud, mapped into cloud 1 by T_12.')
flags.DEFINE_enum('format', 'auto', ['auto', *io.BIN_FORMATS],
                  '.bin layout (float32 rows; *64: float64 rows); auto refuses to guess.')
flags.DEFINE_enum('keypoints', 'iss', pipeline.KEYPOINTS, 'Keypoint detector.')
flags.DEFINE_list('descriptor', ['fpfh'], 'Descriptor(s): fpfh, learned; a list runs each.')
flags.DEFINE_string('checkpoint', None, 'Shipped model name, export folder or training workdir '
                    'for learned (default: the shipped ours / ours_detector).')
flags.DEFINE_string('groundtruth', None, 'groundtruths.txt holding this pair (optional).')
flags.DEFINE_bool('icp', False, 'Refine with point-to-point ICP (Open3D) after RANSAC.')
flags.DEFINE_integer('seed', 0, 'RANSAC / random-keypoint seed.')
flags.DEFINE_integer('fpfh_max_nn', 1000, 'Neighbour cap of the 4 m normal / FPFH searches.')
flags.DEFINE_string('json', None, 'Write the results here.')
flags.DEFINE_string('plot', None, 'Draw the clouds and inlier matches here (PNG).')
flags.mark_flags_as_required(['cloud1', 'cloud2'])


def _ground_truth(path, cloud1, cloud2):
  stem = lambda p: os.path.splitext(os.path.basename(p))[0]
  try:
    i1, i2 = int(stem(cloud1)), int(stem(cloud2))
  except ValueError:
    raise SystemExit('error: --groundtruth needs clouds named by their index (e.g. 000001.bin)')
  for pair in groundtruth.read_groundtruths(path):
    if (pair.idx1, pair.idx2) == (i1, i2):
      return pair.transform
    if (pair.idx1, pair.idx2) == (i2, i1):
      return geometry.invert_transform(pair.transform)
  raise SystemExit(f'error: {path} does not list the pair ({i1}, {i2})')


def _check_writable(path: str | None) -> None:
  """Create an output file's folder now, so that a bad path fails before the work."""
  if not path:
    return
  folder = os.path.dirname(os.path.abspath(path))
  try:
    os.makedirs(folder, exist_ok=True)
  except OSError as e:
    raise ValueError(f'cannot create the folder of {path}: {e.strerror}') from None
  if os.path.isdir(path) or not os.access(folder, os.W_OK):
    raise ValueError(f'{path}: cannot write a file there')


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  bad = [d for d in FLAGS.descriptor if d not in pipeline.DESCRIPTORS]
  if bad:
    raise SystemExit(f'error: --descriptor must be among {pipeline.DESCRIPTORS}, got {bad}')
  needs_model = 'learned' in FLAGS.descriptor or FLAGS.keypoints == 'learned'
  # The shipped descriptor model's attention is untrained; learned keypoints need the
  # shipped self-supervised detector.
  checkpoint = FLAGS.checkpoint or ('ours_detector' if FLAGS.keypoints == 'learned' else 'ours')
  try:
    for out_path in (FLAGS.json, FLAGS.plot):
      _check_writable(out_path)
    # float64 until register() has centred the pair: UTM-scale clouds keep their precision.
    clouds = [clean.clean_cloud(io.read_cloud(p, FLAGS.format), p, np.float64)
              for p in (FLAGS.cloud1, FLAGS.cloud2)]
    t_gt = _ground_truth(FLAGS.groundtruth, FLAGS.cloud1, FLAGS.cloud2) if FLAGS.groundtruth else None
    model = None
    if needs_model:
      model = pretrained.load(checkpoint)
  except (io.CloudFileError, clean.CloudDataError, FileNotFoundError, ValueError) as e:
    raise SystemExit(f'error: {e}') from None
  results = []
  for descriptor in FLAGS.descriptor:
    try:
      start = time.perf_counter()
      reg, f1, f2 = pipeline.register(clouds[0], clouds[1], FLAGS.keypoints, descriptor, model,
                                      FLAGS.seed, FLAGS.fpfh_max_nn, icp=FLAGS.icp)
    except ValueError as e:
      raise SystemExit(f'error: {e}') from None
    transform = reg.transform
    out = {'keypoints': FLAGS.keypoints, 'descriptor': descriptor,
           'num_keypoints': [len(f1.xyz), len(f2.xyz)], 'inliers': int(reg.inliers.sum()),
           'trials': reg.trials, 'model': checkpoint if descriptor == 'learned' else None,
           'seconds': {**{f'cloud1_{k}': v for k, v in f1.seconds.items()},
                       **{f'cloud2_{k}': v for k, v in f2.seconds.items()}, **reg.seconds}}
    if FLAGS.icp:
      out['icp_fitness'] = reg.icp_fitness
    out['seconds']['total'] = time.perf_counter() - start
    out['T_12'] = transform.tolist()
    out['overlap_fitness'] = pipeline.overlap_fitness(clouds[0], clouds[1], transform)
    if t_gt is not None:
      out['errors'] = metrics.registration_errors(t_gt, transform)
    results.append(out)
    print(f'== {FLAGS.keypoints} keypoints + {descriptor} descriptors: '
          f'{out["num_keypoints"][0]} / {out["num_keypoints"][1]} keypoints, '
          f'{out["inliers"]} inliers, {out["trials"]} RANSAC trials, '
          f'{out["seconds"]["total"]:.2f} s')
    print('timings (s): ' + ', '.join(f'{k} {v:.2f}' for k, v in out['seconds'].items()))
    print('T_12 =\n' + np.array2string(transform, precision=4, suppress_small=True))
    print(f'overlap fitness (cloud-2 points within 0.5 m of cloud 1): {out["overlap_fitness"]:.3f}')
    if t_gt is not None:
      e = out['errors']
      print(f'vs ground truth: RTE {e["rte"]:.3f} m, RRE {e["rre"]:.2f} deg (Euler sum), '
            f'{e["rre_geodesic"]:.2f} deg (geodesic), success {e["success"]}')
    if FLAGS.plot:
      root, ext = os.path.splitext(FLAGS.plot)
      path = FLAGS.plot if len(FLAGS.descriptor) == 1 else f'{root}_{descriptor}{ext or ".png"}'
      viz.plot_registration(clouds[0], clouds[1], f1.xyz[reg.matches[:, 0]],
                            f2.xyz[reg.matches[:, 1]], reg.inliers, path,
                            f'{FLAGS.keypoints} + {descriptor}: {out["inliers"]} inliers')
      print(f'plot: {path}')
  if FLAGS.json:
    with open(FLAGS.json, 'w') as f:
      json.dump(results[0] if len(results) == 1 else results, f, indent=1)


def console():
  """The `ssd-jax-register` command (pyproject.toml)."""
  cli.run(main)


if __name__ == '__main__':
  console()
