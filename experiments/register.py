r"""Register two point clouds: print T_12, the 4 x 4 that maps cloud 2 into cloud 1's frame.

    python -m experiments.register --cloud1=A.bin --cloud2=B.bin \
        [--keypoints=auto|iss|learned|random] [--descriptor=learned|fpfh|learned,fpfh] \
        [--checkpoint=ours|RUN_DIR|EXPORT_DIR] [--groundtruth=DIR/groundtruths.txt] \
        [--voxel=SIZE] [--verify=K] [--bev=B] [--icp] [--draws=N] [--json=OUT.json] [--plot=OUT.png]
    # many pairs in one process: a list of pairs, or the consecutive scans of a folder
    python -m experiments.register --pairs=PAIRS.txt --out=DIR [--descriptor=fpfh]
    python -m experiments.register --sequence=SCANS_DIR --out=DIR [--groundtruth=...]

Every cloud is first put on the voxel grid the model was trained on (0.2 m for the shipped
models and FPFH; --voxel=SIZE another, --voxel=0 every point as given), and the command
says so with the point counts: a dense scan or a map tile of millions of points costs
what a 0.2 m-voxel scan does. On a terminal each stage shows its progress (--progress
forces it on a pipe too, --noprogress turns it off).

By default: the shipped learned descriptor (`ours`; --descriptor=fpfh for Open3D's FPFH),
1,024 farthest-point keypoints, upright RANSAC, and RANSAC's 10 best distinct poses, with
the 5 best of a bird's-eye-view search over every yaw and shift, checked against the
clouds by ICP (--verify, --bev; docs/cross_sensor.md).

Reads .bin (N x 3 / 4 / 6 float32 or float64 rows, detected or --format), .npy, .ply, .pcd,
.las, .laz. Learned descriptors and keypoints come from the shipped pretrained models
(`ours`, and `ours_detector` for learned keypoints) unless --checkpoint names another.
With --groundtruth (a `groundtruths.txt` listing the pair by the clouds' file
stems, e.g. 000000.bin / 000001.bin), the errors against it are printed too.

In batch mode each cloud's features are computed once; DIR receives registrations.csv
(one row per pair: T_12, inliers, RANSAC trials, seconds, errors with --groundtruth, and
the seconds of each stage),
written as the pairs complete, and for --sequence poses.txt (each scan's pose in the
first scan's frame, KITTI's 12 numbers per line) and trajectory.png. PAIRS.txt holds
"cloud1 cloud2" per line, paths relative to its folder.
"""

import csv
import dataclasses
import json
import os
import sys
import time

from absl import app
from absl import flags
import numpy as np
from tqdm import auto as tqdm

from ssd_jax import cli, geometry, pretrained, viz
from ssd_jax.data import clean, groundtruth, io
from ssd_jax.logging_utils import quiet_libraries
from ssd_jax.registration import batch, features, metrics, pipeline, uncertainty

FLAGS = flags.FLAGS
flags.DEFINE_string('cloud1', None, 'Target cloud (its frame is the output frame).')
flags.DEFINE_string('cloud2', None, 'Source cloud, mapped into cloud 1 by T_12.')
flags.DEFINE_enum('format', 'auto', ['auto', *io.BIN_FORMATS],
                  '.bin layout (float32 rows; *64: float64 rows); auto refuses to guess.')
flags.DEFINE_enum('keypoints', 'auto', pipeline.KEYPOINTS,
                  'Keypoint detector. auto: 1,024 farthest-point keypoints (found again across '
                  'sensors and standpoints); iss: the paper\'s ISS, on a cloud too sparse for '
                  'it wider ISS radii, then farthest-point keypoints (says which).')
flags.DEFINE_enum('ransac', 'upright', pipeline.ESTIMATORS,
                  "RANSAC's motion model: rigid (3-point samples, any rotation: the paper's) "
                  'or upright (2-point samples of a turn about z and a shift, for scans whose '
                  'z axis is up; refit in 6 degrees of freedom).')
flags.DEFINE_integer('verify', 10, "Check RANSAC's this many distinct best poses against the "
                     'clouds (ICP each, keep the one that lays the most of what rises from '
                     "cloud 2's ground on cloud 1); 0 keeps RANSAC's best as it is.")
flags.DEFINE_integer('bev', 5, "With upright RANSAC and --verify: also check the bird's-eye-"
                     'view search\'s this many best poses (every yaw and shift of the two '
                     'top-down maps of what rises above the ground); 0: RANSAC\'s only.')
# Learned by default: with these defaults it registers as many pairs as FPFH or more on
# every set of the README's table, and on a dense grid it takes a third of FPFH's time
# (4 m / 1,000-neighbour histograms; docs/benchmarks.md).
flags.DEFINE_list('descriptor', ['learned'], 'Descriptor(s): learned, fpfh; a list runs each.')
flags.DEFINE_string('checkpoint', None, 'Shipped model name, export folder or training workdir '
                    'for learned (default: the shipped ours / ours_detector).')
flags.DEFINE_string('groundtruth', None, 'groundtruths.txt holding this pair (optional).')
flags.DEFINE_bool('icp', False, 'Refine with point-to-plane ICP (1 m, then 0.5 m) after RANSAC.')
flags.DEFINE_integer('seed', 0, 'RANSAC / random-keypoint seed.')
flags.DEFINE_integer('draws', None, 'Learned descriptors: average this many random samplings '
                     "of each ball (0: the model's own setting). Default: where the poses are "
                     'verified (--verify > 0), one sampling of 32 points '
                     "(pipeline.verified_model), else the model's own.")
flags.DEFINE_integer('fpfh_max_nn', features.FPFH_MAX_NN, 'Neighbour cap of the 4 m FPFH '
                     'search, 0 for none (normals: 1 m, 30 neighbours).')
flags.DEFINE_float('voxel', None, "Put each cloud on this grid (metres) first; default the "
                   "model's (0.2 m: the shipped models and FPFH), 0 keeps every point.")
flags.DEFINE_bool('progress', None, 'Show each stage on stderr (default: when stderr is a '
                  'terminal).')
flags.DEFINE_string('json', None, 'Write the results here.')
flags.DEFINE_string('plot', None, 'Draw the clouds and inlier matches here (PNG).')
flags.DEFINE_string('pairs', None, 'Batch mode: a file of "cloud1 cloud2" lines.')
flags.DEFINE_string('sequence', None, 'Batch mode: register each scan of this folder to the '
                    'next (sorted by name) and chain the poses.')
flags.DEFINE_string('out', None, 'Batch mode: output folder. A rerun into the same folder '
                    'keeps the pairs its registrations.csv holds without an error.')
flags.DEFINE_bool('allow_degenerate', False, 'Return a pose the scans do not fix (a corridor, '
                  'tunnel, road between barriers: a shift along it is free) with the verdict, '
                  'instead of refusing it.')
flags.DEFINE_bool('stop_on_error', False, 'Batch mode: stop at the first pair that fails '
                  '(default: record its error in its row and register the others).')


def _ground_truth(path, cloud1, cloud2, required=True, pairs=None):
  """T_12 of the pair from a groundtruths.txt (`pairs`: its entries, read once by the
  caller), by the clouds' file stems; None when the file does not list the pair and
  not `required`."""
  stem = lambda p: os.path.splitext(os.path.basename(p))[0]
  try:
    i1, i2 = int(stem(cloud1)), int(stem(cloud2))
  except ValueError:
    raise SystemExit('error: --groundtruth needs clouds named by their index (e.g. 000001.bin)')
  for pair in groundtruth.read_groundtruths(path) if pairs is None else pairs:
    if (pair.idx1, pair.idx2) == (i1, i2):
      return pair.transform
    if (pair.idx1, pair.idx2) == (i2, i1):
      return geometry.invert_transform(pair.transform)
  if not required:
    return None
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


def _show_progress() -> bool:
  return FLAGS.progress if FLAGS.progress is not None else sys.stderr.isatty()


def _voxel(model) -> float:
  if FLAGS.voxel is not None and FLAGS.voxel < 0:
    raise ValueError(f'--voxel must be >= 0 metres (0: every point), got {FLAGS.voxel}')
  return pipeline.voxel_size_of(model) if FLAGS.voxel is None else FLAGS.voxel


def _read(path: str) -> np.ndarray:
  """The cloud at `path`, float64 in the caller's coordinates, NaN rows dropped; one
  that does not look like metres is a CloudDataError saying so."""
  cloud = clean.clean_cloud(io.read_cloud(path, FLAGS.format), path, np.float64)
  problem = clean.units_problem(cloud)
  if problem:
    raise clean.CloudDataError(f'{path}: {problem}')
  return cloud


def _refusal(reg) -> str:
  """'' when the pose may be returned, else the one-line reason it is refused."""
  free = reg.uncertainty.free if reg.uncertainty is not None else ''
  if free and not FLAGS.allow_degenerate:
    return f'degenerate: {free}; --allow_degenerate returns the pose with this verdict'
  return ''


def _read_on_grid(path: str, voxel: float, say, seconds: dict | None = None) -> np.ndarray:
  """The cloud at `path` (float64, the caller's coordinates) on the `voxel` m grid;
  `say(line)` gets the one line of what was done, `seconds` the time of each step."""
  t0 = time.perf_counter()
  cloud = _read(path)
  t1 = time.perf_counter()
  cloud, note = pipeline.to_grid(cloud, voxel)
  if seconds is not None:
    seconds.update(read=t1 - t0, grid=time.perf_counter() - t1)
  if note:
    say(f'voxel: {os.path.basename(path)}: {note}')
  return cloud


def _read_pairs(path: str) -> list[tuple[str, str]]:
  """'cloud1 cloud2' lines ('#' comments) -> paths, relative ones from the file's folder."""
  folder = os.path.dirname(os.path.abspath(path))
  try:
    with open(path) as f:
      lines = [l.split('#')[0].split() for l in f]
  except OSError as e:
    raise ValueError(f'--pairs {path}: {e.strerror}') from None
  pairs = []
  for n, parts in enumerate(lines, 1):
    if not parts:
      continue
    if len(parts) != 2:
      raise ValueError(f'{path}, line {n}: expected "cloud1 cloud2", got {" ".join(parts)!r}')
    pairs.append(tuple(os.path.join(folder, p) for p in parts))
  if not pairs:
    raise ValueError(f'--pairs {path}: no pairs listed')
  return pairs


def _csv_header() -> list[str]:
  return ['cloud1', 'cloud2', 'keypoints1', 'keypoints2', 'inliers', 'trials', 'seconds',
          *[f'T_12[{i}][{j}]' for i in range(4) for j in range(4)], 'rte', 'rre', 'success',
          'error', 'degenerate', 'translation_constraint',
          *[f'least_fixed_translation[{i}]' for i in range(3)], 'smallest_eigenvalue',
          *[f'smallest_direction[{i}]' for i in range(6)],
          *[f'information[{i}][{j}]' for i in range(6) for j in range(6)],
          *[f'seconds_{s}' for s in batch.STAGES]]


def _registered_before(path: str, header: list[str]) -> dict:
  """The rows without an error of an earlier run's registrations.csv at `path`, by pair."""
  if not os.path.exists(path):
    return {}
  with open(path, newline='') as f:
    rows = list(csv.reader(f))
  if not rows or rows[0] != header:
    raise ValueError(f'{path}: written by another version of this command (its columns '
                     'differ); give another --out or remove it')
  error = header.index('error')
  return {(r[0], r[1]): r for r in rows[1:] if len(r) == len(header) and not r[error]}


def _batch(descriptor: str, model, checkpoint: str) -> None:
  """Register every pair of --pairs or consecutive scans of --sequence into --out. A pair
  that fails (a missing or bad file, too few keypoints, a degenerate scene) gets its row
  with the error and the others go on (--stop_on_error: the run stops there); the
  command then ends non-zero naming how many failed. A rerun keeps the rows of the pairs
  registered before."""
  if FLAGS.sequence:
    scans = [str(p) for p in io.list_clouds(FLAGS.sequence)]
    if len(scans) < 2:
      raise ValueError(f'--sequence {FLAGS.sequence}: {len(scans)} cloud(s), 2 or more needed')
    pairs = list(zip(scans[:-1], scans[1:]))
  else:
    pairs = _read_pairs(FLAGS.pairs)
  os.makedirs(FLAGS.out, exist_ok=True)
  gt_pairs = groundtruth.read_groundtruths(FLAGS.groundtruth) if FLAGS.groundtruth else None
  say = tqdm.tqdm.write if _show_progress() else print
  registrar = batch.Registrar(_read, keypoints=FLAGS.keypoints,
                              descriptor=descriptor, model=model, seed=FLAGS.seed,
                              fpfh_max_nn=FLAGS.fpfh_max_nn, voxel=_voxel(model),
                              estimator=FLAGS.ransac, verify=FLAGS.verify,
                              bev=_bev_candidates(), say=say)
  header, path = _csv_header(), os.path.join(FLAGS.out, 'registrations.csv')
  before = _registered_before(path, header)
  # Rewritten whole before any new row is added: a run stopped at any moment keeps them.
  with open(path + '.tmp', 'w', newline='') as f:
    csv.writer(f).writerows([header, *(before[p] for p in pairs if p in before)])
  os.replace(path + '.tmp', path)
  transforms, failed = [], []
  t_index = header.index('T_12[0][0]')
  with open(path, 'a', newline='') as f:
    writer = csv.writer(f)
    for cloud1, cloud2 in tqdm.tqdm(pairs, desc='registration', unit='pair',
                                    disable=not _show_progress()):
      if (cloud1, cloud2) in before:
        row = before[cloud1, cloud2]
        transforms.append(np.array(row[t_index:t_index + 16], np.float64).reshape(4, 4))
        failed.append(False)
        continue
      start = time.perf_counter()
      keypoints, inliers, trials, stages, assessed = (0, 0), 0, 0, {}, None
      try:
        reg, f1, f2 = registrar.register(cloud1, cloud2)
        keypoints, inliers, trials = (len(f1.xyz), len(f2.xyz)), int(reg.inliers.sum()), reg.trials
        stages, assessed, error = reg.seconds, reg.uncertainty, _refusal(reg)
      except (io.CloudFileError, clean.CloudDataError, OSError, ValueError) as e:
        error = str(e)   # a bad file, too few keypoints, a flat cloud: this pair only
      if error and FLAGS.stop_on_error:
        raise ValueError(f'{cloud1} / {cloud2}: {error}')
      t = reg.transform if not error else np.eye(4)
      transforms.append(t)
      failed.append(bool(error))
      t_gt = (_ground_truth(FLAGS.groundtruth, cloud1, cloud2, False, gt_pairs)
              if gt_pairs is not None and not error else None)
      gt = metrics.registration_errors(t_gt, t) if t_gt is not None else {}
      pose = ([assessed.free, f'{assessed.translation_constraint[0]:.6g}',
               *[f'{v:.6g}' for v in assessed.translation_directions[0]],
               f'{assessed.eigenvalues[0]:.6g}', *[f'{v:.6g}' for v in assessed.directions[0]],
               *[f'{v:.10g}' for v in assessed.information.ravel()]]
              if assessed is not None else [''] * 48)
      writer.writerow([cloud1, cloud2, *keypoints, inliers, trials,
                       f'{time.perf_counter() - start:.3f}', *t.ravel().tolist(),
                       gt.get('rte', ''), gt.get('rre', ''), gt.get('success', ''), error,
                       *pose, *[f'{stages[s]:.4f}' if s in stages else '' for s in batch.STAGES]])
      f.flush()   # a stopped run keeps the pairs it registered
  kept = sum(p in before for p in pairs)
  print(f'wrote {path}: {len(pairs)} pairs' + (f' ({kept} kept from an earlier run)' if kept else '')
        + f', {descriptor} descriptors ({checkpoint if descriptor == "learned" else "Open3D"})')
  if FLAGS.sequence:
    poses = [np.eye(4)]
    for t in transforms:   # T_{i,i+1} maps scan i+1 into scan i: P_{i+1} = P_i T_{i,i+1}
      poses.append(poses[-1] @ t)
    poses = np.stack(poses)
    np.savetxt(os.path.join(FLAGS.out, 'poses.txt'), poses[:, :3, :].reshape(len(poses), 12))
    viz.plot_trajectory(poses, os.path.join(FLAGS.out, 'trajectory.png'),
                        f'{len(scans)} scans of {FLAGS.sequence}', np.asarray(failed))
    print(f'wrote {os.path.join(FLAGS.out, "poses.txt")} and trajectory.png')
  if any(failed):
    raise ValueError(f'{sum(failed)} of {len(pairs)} pairs failed (the error column of {path} '
                     'says why; a rerun registers only those)')


def _load_model(checkpoint: str):
  """The model named by --checkpoint, describing with --draws samplings (by default as
  `pipeline.verified_model` where the poses are verified, else as the model's own)."""
  if FLAGS.draws is not None and FLAGS.draws < 0:
    raise ValueError(f'--draws must be >= 0, got {FLAGS.draws}')
  model = pretrained.load(checkpoint)
  if FLAGS.draws is None:
    return pipeline.verified_model(model) if FLAGS.verify > 0 else model
  return dataclasses.replace(model, draws=FLAGS.draws) if FLAGS.draws else model


def _bev_candidates() -> int:
  """--bev where it applies (upright scans, verified poses), else 0."""
  return FLAGS.bev if FLAGS.ransac == 'upright' and FLAGS.verify > 0 else 0


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  bad = [d for d in FLAGS.descriptor if d not in pipeline.DESCRIPTORS]
  if bad:
    raise SystemExit(f'error: --descriptor must be among {pipeline.DESCRIPTORS}, got {bad}')
  batch = bool(FLAGS.pairs or FLAGS.sequence)
  if batch and (FLAGS.cloud1 or FLAGS.cloud2 or FLAGS.json or FLAGS.plot or FLAGS.icp
                or not FLAGS.out or bool(FLAGS.pairs) == bool(FLAGS.sequence)
                or len(FLAGS.descriptor) != 1):
    raise SystemExit('error: batch mode takes one of --pairs / --sequence, --out and one '
                     '--descriptor (not --cloud1/--cloud2/--json/--plot/--icp)')
  if FLAGS.verify < 0:
    raise SystemExit(f'error: --verify must be >= 0 (0: no verification), got {FLAGS.verify}')
  if FLAGS.bev < 0:
    raise SystemExit(f'error: --bev must be >= 0 (0: no BEV search), got {FLAGS.bev}')
  if FLAGS['bev'].present and FLAGS.bev > 0 and not _bev_candidates():
    raise SystemExit('error: --bev needs --ransac=upright and --verify > 0 (its poses turn '
                     'about z only, and are checked with RANSAC\'s)')
  if not batch and not (FLAGS.cloud1 and FLAGS.cloud2):
    raise SystemExit('error: give --cloud1 and --cloud2 (or --pairs / --sequence with --out)')
  needs_model = 'learned' in FLAGS.descriptor or FLAGS.keypoints == 'learned'
  # The shipped descriptor model's attention is untrained; learned keypoints need the
  # shipped self-supervised detector.
  checkpoint = FLAGS.checkpoint or ('ours_detector' if FLAGS.keypoints == 'learned' else 'ours')
  if batch:
    try:
      _batch(FLAGS.descriptor[0], _load_model(checkpoint) if needs_model else None,
             checkpoint)
    except (io.CloudFileError, clean.CloudDataError, FileNotFoundError, ValueError) as e:
      raise SystemExit(f'error: {e}') from None
    return
  # Reading each cloud onto the grid, then per descriptor the keypoints and descriptors of
  # both clouds and RANSAC (and ICP): one step of the bar each.
  stages = 2 + len(FLAGS.descriptor) * (5 + (FLAGS.verify > 0) + FLAGS.icp)
  bar = tqdm.tqdm(total=stages, unit='stage', leave=False, disable=not _show_progress(),
                  bar_format='register {n}/{total} [{elapsed}] {desc}')

  def stage(name):
    bar.set_description_str(name, refresh=False)
    bar.update(1)
    # update() redraws at most every 0.1 s: a long stage right after a short one would
    # show the short one's name throughout.
    bar.refresh()

  try:
    for out_path in (FLAGS.json, FLAGS.plot):
      _check_writable(out_path)
    model = _load_model(checkpoint) if needs_model else None
    voxel = _voxel(model)
    # float64 until register() has centred the pair: UTM-scale clouds keep their precision.
    clouds, read_seconds = [], {}
    for n, path in enumerate((FLAGS.cloud1, FLAGS.cloud2), 1):
      stage(f'reading {os.path.basename(path)}')
      seconds = {}
      clouds.append(_read_on_grid(path, voxel, lambda line: print(line) if bar.disable
                                  else bar.write(line), seconds))
      read_seconds.update({f'cloud{n}_{k}': v for k, v in seconds.items()})
    t_gt = _ground_truth(FLAGS.groundtruth, FLAGS.cloud1, FLAGS.cloud2) if FLAGS.groundtruth else None
  except (io.CloudFileError, clean.CloudDataError, FileNotFoundError, ValueError) as e:
    bar.close()
    raise SystemExit(f'error: {e}') from None
  results = []
  for descriptor in FLAGS.descriptor:
    try:
      start = time.perf_counter()
      reg, f1, f2 = pipeline.register(
          clouds[0], clouds[1], FLAGS.keypoints, descriptor, model, FLAGS.seed,
          FLAGS.fpfh_max_nn, icp=FLAGS.icp, estimator=FLAGS.ransac, voxel=0,
          verify_candidates=FLAGS.verify, bev_candidates=_bev_candidates(),
          progress=lambda name: stage(f'{descriptor}: {name}') if 'grid' not in name else None)
    except ValueError as e:
      bar.close()
      raise SystemExit(f'error: {e}') from None
    if _refusal(reg):
      bar.close()
      raise SystemExit(f'error: {_refusal(reg)}')
    if descriptor == FLAGS.descriptor[-1]:
      bar.close()
    else:
      bar.clear()   # redrawn at its next stage, below this descriptor's report
    transform = reg.transform
    out = {'keypoints': FLAGS.keypoints, 'descriptor': descriptor,
           'num_keypoints': [len(f1.xyz), len(f2.xyz)], 'keypoint_levels': reg.levels_tried,
           'inliers': int(reg.inliers.sum()), 'trials': reg.trials, 'model': checkpoint if descriptor == 'learned' else None,
           'notes': reg.notes, 'fitness': reg.fitness, 'inlier_rmse': reg.inlier_rmse,
           'voxel': voxel, 'points': [len(clouds[0]), len(clouds[1])],
           'correspondence_set_size': reg.correspondence_set_size,
           'draws': model.draws if descriptor == 'learned' else None,
           'num_samples': model.num_samples if descriptor == 'learned' else None,
           'seconds': {**{f'cloud1_{k}': v for k, v in f1.seconds.items()},
                       **{f'cloud2_{k}': v for k, v in f2.seconds.items()}, **reg.seconds,
                       **read_seconds}}
    if reg.verified_fitness is not None:
      out['verified_fitness'] = reg.verified_fitness.tolist()
    out['uncertainty'] = reg.uncertainty.to_json()
    if FLAGS.icp:
      out['icp_fitness'] = reg.icp_fitness
    out['seconds']['total'] = time.perf_counter() - start + sum(read_seconds.values())
    out['T_12'] = transform.tolist()
    out['overlap_fitness'] = pipeline.overlap_fitness(clouds[0], clouds[1], transform)
    if t_gt is not None:
      out['errors'] = metrics.registration_errors(t_gt, transform)
    results.append(out)
    for note in reg.notes:
      print(f'keypoints: {note}')
    print(f'== {FLAGS.keypoints} keypoints + {descriptor} descriptors: '
          f'{out["num_keypoints"][0]} / {out["num_keypoints"][1]} keypoints, '
          f'{out["inliers"]} inliers, {out["trials"]} RANSAC trials, fitness '
          f'{reg.fitness:.3f}, inlier RMSE {reg.inlier_rmse:.3f} m, '
          f'{out["seconds"]["total"]:.2f} s')
    print('timings (s): ' + ', '.join(f'{k} {v:.2f}' for k, v in out['seconds'].items()))
    print('T_12 =\n' + np.array2string(transform, precision=4, suppress_small=True))
    print(f'overlap fitness (cloud-2 points within 0.5 m of cloud 1): {out["overlap_fitness"]:.3f}')
    u = reg.uncertainty
    least = uncertainty.describe_direction(np.append(np.zeros(3), u.translation_directions[0]))
    print(f'degenerate: {u.free}' if u.free else
          f'the scans fix the pose: least fixed {least}, constraint '
          f'{u.translation_constraint[0]:.3f} (free under {uncertainty.MIN_CONSTRAINT})')
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
  cli.run(main, fast_exit=True)


if __name__ == '__main__':
  console()
