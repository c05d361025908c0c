r"""Register two point clouds: print T_12, the 4 x 4 that maps cloud 2 into cloud 1's frame.

    python -m experiments.register --cloud1=A.bin --cloud2=B.bin [--descriptor=learned,fpfh]
        [--keypoints=auto|iss|learned|random] [--checkpoint=ours_mined|RUN_DIR|EXPORT_DIR] [--icp]
        [--groundtruth=groundtruths.txt] [--voxel=SIZE] [--verify=K] [--bev=B] [--json=OUT.json]
    python -m experiments.register --pairs=PAIRS.txt --out=DIR      # many pairs, one process
    python -m experiments.register --sequence=SCANS_DIR --out=DIR   # consecutive scans

The defaults are `options.Options()` (docs/registration.md). Each cloud is put on the
model's 0.2 m grid first (--voxel=0: every point). Batch mode (`pipeline.register_many`)
describes each cloud once and writes DIR/registrations.csv row by row (a failed pair gets
its error and the rest go on; a rerun registers only the pairs without a row), and for
--sequence poses.txt (KITTI's 12 numbers per scan) and trajectory.png.
"""

import json
import os
import sys
import time

from absl import app
from absl import flags
import numpy as np
from tqdm import auto as tqdm

from ssd_jax import pretrained, viz
from ssd_jax.infra import cli, errors
from ssd_jax.data import clean, groundtruth, io
from ssd_jax.infra.logging_utils import quiet_libraries
from ssd_jax.registration import features, metrics, outputs, pipeline
from ssd_jax.registration import pair_stages
from ssd_jax.registration import options as options_lib

FLAGS = flags.FLAGS
DEFAULTS = options_lib.Options()
flags.DEFINE_string('cloud1', None, 'Target cloud (its frame is the output frame).')
flags.DEFINE_string('cloud2', None, 'Source cloud, mapped into cloud 1 by T_12.')
flags.DEFINE_enum('format', 'auto', ['auto', *io.BIN_FORMATS],
                  '.bin layout (float32 rows; *64: float64 rows); auto refuses to guess.')
flags.DEFINE_enum('keypoints', DEFAULTS.keypoints, options_lib.KEYPOINTS, 'auto: 1,024 farthest-'
                  "point keypoints (of the points above the ground for a model whose config "
                  "says inference.keypoints='structure', as experiments.adapt may set); iss: "
                  "the paper's; learned: a detector model's.")
flags.DEFINE_enum('ransac', DEFAULTS.estimator, options_lib.ESTIMATORS,
                  'upright: 2-point samples of a turn about z and a shift (z up); rigid: '
                  "3-point samples, any rotation (the paper's).")
flags.DEFINE_enum('sampling', DEFAULTS.sampling, options_lib.SAMPLINGS, "Upright RANSAC's "
                  'matches and samples: compatible (matches both ways, samples among pairs '
                  'that one turn and shift fit), uniform (nearest neighbours, uniform '
                  'draws), auto (compatible with --verify=0, else uniform).')
flags.DEFINE_integer('verify', DEFAULTS.verify, "Check RANSAC's this many distinct best poses "
                     "against the clouds by ICP; 0 keeps RANSAC's best.")
flags.DEFINE_integer('bev', DEFAULTS.bev, "Also check the bird's-eye-view search's this many "
                     'best poses (needs --ransac=upright and --verify > 0).')
flags.DEFINE_list('descriptor', [DEFAULTS.descriptor], 'learned, fpfh; a list runs each.')
flags.DEFINE_enum('level', DEFAULTS.level, options_lib.LEVELS,
                  'ground: level each tilted scan by its ground first; none: take z as up.')
flags.DEFINE_list('retry', list(DEFAULTS.retry), 'A pose the verdict refuses is registered '
                  'again with each in turn: structure (keypoints above the ground), learned '
                  "(the model's own sampling), fpfh, bev (the banded BEV search), robust (its "
                  'candidates again, aligned by a robust ICP); none.')
flags.DEFINE_string('checkpoint', None, 'Shipped model, export or run (default: '
                    f'{pretrained.DEFAULT}, or ours_detector for learned keypoints).')
flags.DEFINE_string('groundtruth', None, 'groundtruths.txt holding the pairs (optional).')
flags.DEFINE_bool('icp', DEFAULTS.icp, 'Refine with point-to-plane ICP (1 m, then 0.5 m).')
flags.DEFINE_bool('free_space', DEFAULTS.free_space, "Judge free space from each cloud's origin "
                  "as its sensor; --nofree_space for scans in a world frame or in the other's.")
flags.DEFINE_integer('seed', DEFAULTS.seed, 'RANSAC / random-keypoint seed.')
flags.DEFINE_integer('draws', None, 'Learned descriptors: samplings of each ball (0: the '
                     "model's own; default one of 32 points where poses are verified).")
flags.DEFINE_integer('fpfh_max_nn', features.FPFH_MAX_NN, 'FPFH neighbour cap (0: none).')
flags.DEFINE_float('voxel', None, "Grid (m) for each cloud; default the model's, 0: none.")
flags.DEFINE_bool('progress', None, 'Show each stage on stderr (default: on a terminal).')
flags.DEFINE_string('json', None, 'Write the results here.')
flags.DEFINE_string('plot', None, 'Draw the clouds and inlier matches here (PNG).')
flags.DEFINE_string('pairs', None, 'Batch mode: a file of "cloud1 cloud2" lines.')
flags.DEFINE_string('sequence', None, 'Batch mode: each scan of this folder to the next.')
flags.DEFINE_string('out', None, 'Batch mode: output folder (a rerun keeps its rows).')
flags.DEFINE_bool('stop_on_error', False, 'Batch mode: stop at the first pair that fails.')


def _options(descriptor: str) -> options_lib.Options:
  if FLAGS['bev'].present and FLAGS.bev > 0 and (FLAGS.ransac != 'upright' or FLAGS.verify <= 0):
    raise errors.UserError("--bev needs --ransac=upright and --verify > 0 (its poses turn "
                           "about z only, and are checked with RANSAC's)")
  return options_lib.Options(FLAGS.keypoints, descriptor, FLAGS.ransac, FLAGS.verify, FLAGS.bev,
                             FLAGS.icp, FLAGS.draws, FLAGS.voxel, FLAGS.fpfh_max_nn, FLAGS.seed,
                             FLAGS.level, FLAGS.sampling, ','.join(FLAGS.retry),
                             free_space=FLAGS.free_space)


def _read(path: str) -> np.ndarray:
  return clean.read_metres(path, FLAGS.format)


def _show_progress() -> bool:
  return sys.stderr.isatty() if FLAGS.progress is None else FLAGS.progress


def _batch(options: options_lib.Options, model, model_name: str) -> None:
  """Every pair of --pairs, or consecutive scans of --sequence, into --out (`register_many`)."""
  pairs = (outputs.sequence_pairs(FLAGS.sequence) if FLAGS.sequence
           else outputs.read_pairs(FLAGS.pairs))
  os.makedirs(FLAGS.out, exist_ok=True)
  truth = groundtruth.read_groundtruths(FLAGS.groundtruth) if FLAGS.groundtruth else None
  written = outputs.RegistrationsFile(os.path.join(FLAGS.out, 'registrations.csv'), pairs)
  todo = [p for p in pairs if p not in written.rows]
  results = pipeline.register_many(todo, _read, model=model, options=options,
                                   say=tqdm.tqdm.write if _show_progress() else print)
  for result in tqdm.tqdm(results, total=len(todo), desc='registration', unit='pair',
                          disable=not _show_progress()):
    if result.error and FLAGS.stop_on_error:
      raise errors.UserError(f'{result.target} / {result.source}: {result.error}')
    t_gt = (outputs.ground_truth(FLAGS.groundtruth, result.target, result.source, False, truth)
            if truth is not None and not result.error else None)
    written.add(result, t_gt)
  failed, registered = written.failed(pairs), written.registered(pairs)
  print(f'wrote {written.path}: {len(pairs)} pairs'
        + (f' ({written.kept} kept from an earlier run)' if written.kept else '')
        + f', {options.descriptor} descriptors ({model_name if model else "Open3D"}): '
        f'{sum(registered)} registered, {len(pairs) - sum(registered) - sum(failed)} not '
        '(the verdict column says why)' + (f', {sum(failed)} failed' if any(failed) else ''))
  if FLAGS.sequence:
    poses = outputs.chain(written.transforms(pairs))
    np.savetxt(os.path.join(FLAGS.out, 'poses.txt'), poses[:, :3, :].reshape(len(poses), 12))
    viz.plot_trajectory(poses, os.path.join(FLAGS.out, 'trajectory.png'),
                        f'{len(pairs) + 1} scans of {FLAGS.sequence}',
                        ~np.asarray(registered))
    print(f'wrote {os.path.join(FLAGS.out, "poses.txt")} and trajectory.png')
  if any(failed):
    raise errors.UserError(f'{sum(failed)} of {len(pairs)} pairs failed (the error column of '
                           f'{written.path} says why; a rerun registers only those)')


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  batch = bool(FLAGS.pairs or FLAGS.sequence)
  if batch and (FLAGS.cloud1 or FLAGS.cloud2 or FLAGS.json or FLAGS.plot or not FLAGS.out
                or bool(FLAGS.pairs) == bool(FLAGS.sequence) or len(FLAGS.descriptor) != 1):
    raise errors.UserError('batch mode takes one of --pairs / --sequence, --out and one '
                           '--descriptor (not --cloud1/--cloud2/--json/--plot)')
  if not batch and not (FLAGS.cloud1 and FLAGS.cloud2):
    raise errors.UserError('give --cloud1 and --cloud2 (or --pairs / --sequence with --out)')
  options = [_options(d) for d in FLAGS.descriptor]
  # Learned keypoints need the shipped detector: the descriptor models' attention is untrained.
  name = FLAGS.checkpoint or ('ours_detector' if FLAGS.keypoints == 'learned'
                              else pretrained.DEFAULT)
  loaded = pretrained.load(name) if any(o.needs_model for o in options) else None
  if batch:
    return _batch(options[0], loaded, name)
  for out_path in (FLAGS.json, FLAGS.plot):
    cli.check_writable(out_path)
  # Per descriptor: each cloud read and gridded, its keypoints and descriptors, then the
  # pair's stages: one step of the bar each.
  bar = cli.StageBar(sum(7 + (o.verify > 0) + o.icp for o in options), _show_progress(),
                     'register')
  try:
    _register_pair(options, loaded, name, bar)
  finally:
    bar.close()


def _register_pair(options, loaded, name: str, bar: cli.StageBar) -> None:
  t_gt = (outputs.ground_truth(FLAGS.groundtruth, FLAGS.cloud1, FLAGS.cloud2)
          if FLAGS.groundtruth else None)
  results = []
  for o in options:
    start, said = time.perf_counter(), []
    registrar = pipeline.Registrar(
        _read, model=loaded, options=o, say=lambda line: said.append(line) or bar.say(line),
        progress=lambda s, d=o.descriptor: bar.stage(f'{d}: {s}'))
    reg, f1, f2 = registrar.register(FLAGS.cloud1, FLAGS.cloud2)
    bar.close() if o is options[-1] else bar.clear()   # redrawn below this report
    clouds = [registrar.points(p) for p in (FLAGS.cloud1, FLAGS.cloud2)]
    out = outputs.pair_json(reg, f1, f2, o, o.describing(loaded), name,
                            (len(clouds[0]), len(clouds[1])), registrar.voxel)
    out['notes'] = said + reg.notes
    out['seconds']['total'] = time.perf_counter() - start
    out['overlap_fitness'] = pair_stages.overlap_fitness(clouds[0], clouds[1], reg.transform)
    if t_gt is not None:
      out['errors'] = metrics.registration_errors(t_gt, reg.transform)
    results.append(out)
    print(*(f'note: {n}' for n in reg.notes), outputs.summary(out, reg), sep='\n')
    if FLAGS.plot:
      root, ext = os.path.splitext(FLAGS.plot)
      path = FLAGS.plot if len(options) == 1 else f'{root}_{o.descriptor}{ext or ".png"}'
      viz.plot_registration(clouds[0], clouds[1], f1.xyz[reg.matches[:, 0]],
                            f2.xyz[reg.matches[:, 1]], reg.inliers, path,
                            f'{o.keypoints} + {o.descriptor}: {out["inliers"]} inliers')
      print(f'plot: {path}')
  if FLAGS.json:
    with open(FLAGS.json, 'w') as f:
      json.dump(results[0] if len(results) == 1 else results, f, indent=1)


def console():
  """The `ssd-jax-register` command (pyproject.toml)."""
  cli.run(main, fast_exit=True)


if __name__ == '__main__':
  console()
