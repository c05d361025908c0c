"""What a registration writes and reads around it: the rows of `registrations.csv` (one per
pair of `pipeline.register_many`), the one-pair JSON, pair lists, a sequence's chained
poses, and the ground truth of a pair by its files' names.

T_12 maps cloud 2 (the source) into cloud 1's frame (the target) everywhere.
"""

from __future__ import annotations

import csv
import os

import numpy as np

from ssd_jax import geometry
from ssd_jax.infra import errors
from ssd_jax.data import groundtruth, io
from ssd_jax.registration import metrics, pipeline, uncertainty
from ssd_jax.registration import cloud_features, pair_stages
from ssd_jax.registration import options as options_lib

CSV_HEADER = [
    'cloud1', 'cloud2', 'keypoints1', 'keypoints2', 'inliers', 'trials', 'seconds',
    *[f'T_12[{i}][{j}]' for i in range(4) for j in range(4)], 'rte', 'rre', 'success',
    'error', 'notes', 'registered', 'verdict', 'structure_fitness', 'free_space_conflict',
    'seen_from_behind', 'degenerate',
    'translation_constraint',
    *[f'least_fixed_translation[{i}]' for i in range(3)], 'smallest_eigenvalue',
    *[f'smallest_direction[{i}]' for i in range(6)],
    *[f'information[{i}][{j}]' for i in range(6) for j in range(6)],
    *[f'seconds_{s}' for s in pipeline.STAGES]]
TRANSFORM_COLUMN = CSV_HEADER.index('T_12[0][0]')
ERROR_COLUMN = CSV_HEADER.index('error')
REGISTERED_COLUMN = CSV_HEADER.index('registered')


def csv_row(result: pipeline.PairResult, truth: np.ndarray | None = None) -> list:
  """The `CSV_HEADER` row of one pair; `truth`: its ground-truth T_12 (errors filled in).
  The verdict (`registered` 1 / 0 and its reason) is empty where the pair failed; `notes`:
  the registration's fallbacks, '; '-joined (e.g. registered again with FPFH)."""
  reg, error = result.registration, result.error
  t = reg.transform if reg is not None and not error else np.eye(4)
  keypoints = ((len(result.target_features.xyz), len(result.source_features.xyz))
               if reg is not None else (0, 0))
  gt = metrics.registration_errors(truth, t) if truth is not None and not error else {}
  u = reg.uncertainty if reg is not None else None
  pose = ([u.free, f'{u.translation_constraint[0]:.6g}',
           *[f'{v:.6g}' for v in u.translation_directions[0]], f'{u.eigenvalues[0]:.6g}',
           *[f'{v:.6g}' for v in u.directions[0]], *[f'{v:.10g}' for v in u.information.ravel()]]
          if u is not None else [''] * 48)
  stages = reg.seconds if reg is not None else {}
  v = reg.verdict if reg is not None and not error else None
  verdict = ([int(v.registered), v.reason, f'{v.fitness:.4f}',
              *['' if x is None else f'{x:.4f}' for x in (v.conflict, v.behind)]]
             if v is not None else [''] * 5)
  return [result.target, result.source, *keypoints,
          int(reg.inliers.sum()) if reg is not None else 0, reg.trials if reg is not None else 0,
          f'{result.seconds:.3f}', *t.ravel().tolist(), gt.get('rte', ''), gt.get('rre', ''),
          gt.get('success', ''), error, '; '.join(reg.notes) if reg is not None else '',
          *verdict, *pose,
          *[f'{stages[s]:.4f}' if s in stages else '' for s in pipeline.STAGES]]


def transform_of(row: list) -> np.ndarray:
  """T_12 [4, 4] of a `CSV_HEADER` row."""
  return np.array(row[TRANSFORM_COLUMN:TRANSFORM_COLUMN + 16], np.float64).reshape(4, 4)


def registered_before(path: str) -> dict:
  """The rows without an error of an earlier run's registrations.csv at `path`, by pair."""
  if not os.path.exists(path):
    return {}
  with open(path, newline='') as f:
    rows = list(csv.reader(f))
  if not rows or rows[0] != CSV_HEADER:
    raise errors.UserError(f'{path}: written by another version of this command (its '
                           'columns differ); give another --out or remove it')
  return {(r[0], r[1]): r for r in rows[1:] if len(r) == len(CSV_HEADER) and not r[ERROR_COLUMN]}


class RegistrationsFile:
  """A batch's registrations.csv at `path` for `pairs` [(cloud1, cloud2)]: the rows without
  an error of an earlier run into it are kept (`kept`; their pairs need no new run), the
  file is rewritten with them at once (a run stopped at any moment keeps them), and each
  new row is appended and flushed as its pair completes (`add`)."""

  def __init__(self, path: str, pairs: list[tuple[str, str]]):
    self.path = path
    before = registered_before(path)
    self.rows = {p: before[p] for p in pairs if p in before}
    self.kept = len(self.rows)
    with open(path + '.tmp', 'w', newline='') as f:
      csv.writer(f).writerows([CSV_HEADER, *self.rows.values()])
    os.replace(path + '.tmp', path)

  def add(self, result: pipeline.PairResult, truth: np.ndarray | None = None) -> None:
    """Append the pair's `csv_row`."""
    row = self.rows[result.target, result.source] = csv_row(result, truth)
    with open(self.path, 'a', newline='') as f:
      csv.writer(f).writerow(row)

  def failed(self, pairs) -> list[bool]:
    return [bool(self.rows[p][ERROR_COLUMN]) for p in pairs]

  def registered(self, pairs) -> list[bool]:
    """Whether each pair's pose is to be trusted (its verdict; False where it failed)."""
    return [str(self.rows[p][REGISTERED_COLUMN]) == '1' for p in pairs]

  def transforms(self, pairs) -> list[np.ndarray]:
    """T_12 of each pair (the identity where it failed)."""
    return [transform_of(self.rows[p]) for p in pairs]


def read_pairs(path: str) -> list[tuple[str, str]]:
  """'cloud1 cloud2' lines ('#' comments) -> paths, relative ones from the file's folder."""
  folder = os.path.dirname(os.path.abspath(path))
  try:
    with open(path) as f:
      lines = [l.split('#')[0].split() for l in f]
  except OSError as e:
    raise errors.UserError(f'--pairs {path}: {e.strerror}') from None
  pairs = []
  for n, parts in enumerate(lines, 1):
    if not parts:
      continue
    if len(parts) != 2:
      raise errors.UserError(f'{path}, line {n}: expected "cloud1 cloud2", got '
                             f'{" ".join(parts)!r}')
    pairs.append(tuple(os.path.join(folder, p) for p in parts))
  if not pairs:
    raise errors.UserError(f'--pairs {path}: no pairs listed')
  return pairs


def sequence_pairs(folder: str) -> list[tuple[str, str]]:
  """Each cloud of `folder` (sorted by name) with the next."""
  scans = [str(p) for p in io.list_clouds(folder)]
  if len(scans) < 2:
    raise errors.UserError(f'--sequence {folder}: {len(scans)} cloud(s), 2 or more needed')
  return list(zip(scans[:-1], scans[1:]))


def chain(transforms: list[np.ndarray]) -> np.ndarray:
  """T_{i,i+1} of consecutive scans (each maps scan i+1 into scan i) -> the poses [n+1,
  4, 4] of every scan in the first one's frame: P_{i+1} = P_i T_{i,i+1}."""
  poses = [np.eye(4)]
  for t in transforms:
    poses.append(poses[-1] @ t)
  return np.stack(poses)


def ground_truth(path: str, cloud1: str, cloud2: str, required: bool = True,
                 pairs: list | None = None) -> np.ndarray | None:
  """T_12 of the pair from a groundtruths.txt (`pairs`: its entries, read once by the
  caller), by the clouds' file stems (e.g. 000000.bin / 000001.bin); None when the file
  does not list the pair and not `required`."""
  stem = lambda p: os.path.splitext(os.path.basename(p))[0]
  try:
    i1, i2 = int(stem(cloud1)), int(stem(cloud2))
  except ValueError:
    raise errors.UserError('--groundtruth needs clouds named by their index '
                           '(e.g. 000001.bin)') from None
  for pair in groundtruth.read_groundtruths(path) if pairs is None else pairs:
    if (pair.idx1, pair.idx2) == (i1, i2):
      return pair.transform
    if (pair.idx1, pair.idx2) == (i2, i1):
      return geometry.invert_transform(pair.transform)
  if not required:
    return None
  raise errors.UserError(f'{path} does not list the pair ({i1}, {i2})')


def pair_json(reg: pair_stages.Registration, f1: cloud_features.CloudFeatures,
              f2: cloud_features.CloudFeatures, options: options_lib.Options, model,
              model_name: str, points: tuple[int, int], voxel: float) -> dict:
  """The one-pair JSON of the register command (docs/registration.md)."""
  learned = options.descriptor == 'learned'
  # Where 'auto' keypoints were sampled (`cloud_features.keypoint_domain`): 'all' points, or the
  # 'structure' above the ground for a model `experiments.adapt` set so.
  domain = cloud_features.domain_of(model) if options.keypoints == 'auto' else None
  out = {'keypoints': options.keypoints, 'keypoint_domain': domain,
         'descriptor': options.descriptor,
         'num_keypoints': [len(f1.xyz), len(f2.xyz)], 'keypoint_levels': reg.levels_tried,
         'inliers': int(reg.inliers.sum()), 'trials': reg.trials,
         'model': model_name if learned else None, 'notes': reg.notes,
         'fitness': reg.fitness, 'inlier_rmse': reg.inlier_rmse, 'voxel': voxel,
         'points': list(points), 'correspondence_set_size': reg.correspondence_set_size,
         'draws': model.draws if learned else None,
         'num_samples': model.num_samples if learned else None,
         'seconds': dict(reg.seconds)}
  if reg.verified_fitness is not None:
    out['verified_fitness'] = reg.verified_fitness.tolist()
  out['registered'] = reg.verdict.registered
  out['verdict'] = reg.verdict.to_json()
  out['uncertainty'] = reg.uncertainty.to_json()
  if options.icp:
    out['icp_fitness'] = reg.icp_fitness
  out['T_12'] = reg.transform.tolist()
  return out


def summary(out: dict, reg: pair_stages.Registration) -> str:
  """The lines the register command prints for one pair (`out`: `pair_json`'s, with the
  total seconds, the overlap fitness and, against ground truth, 'errors')."""
  u = reg.uncertainty
  least = uncertainty.describe_direction(np.append(np.zeros(3), u.translation_directions[0]))
  domain = ' (structure)' if out.get('keypoint_domain') == 'structure' else ''
  lines = [f'== {out["keypoints"]}{domain} keypoints + {out["descriptor"]} descriptors: '
           f'{out["num_keypoints"][0]} / {out["num_keypoints"][1]} keypoints, '
           f'{out["inliers"]} inliers, {out["trials"]} RANSAC trials, fitness '
           f'{reg.fitness:.3f}, inlier RMSE {reg.inlier_rmse:.3f} m, '
           f'{out["seconds"]["total"]:.2f} s: {reg.verdict.line()}',
           'timings (s): ' + ', '.join(f'{k} {v:.2f}' for k, v in out['seconds'].items()),
           'T_12 =\n' + np.array2string(reg.transform, precision=4, suppress_small=True),
           'overlap fitness (cloud-2 points within 0.5 m of cloud 1): '
           f'{out["overlap_fitness"]:.3f}',
           f'degenerate: {u.free}' if u.free else
           f'the scans fix the pose: least fixed {least}, constraint '
           f'{u.translation_constraint[0]:.3f} (free under {uncertainty.MIN_CONSTRAINT})']
  if 'errors' in out:
    e = out['errors']
    lines.append(f'vs ground truth: RTE {e["rte"]:.3f} m, RRE {e["rre"]:.2f} deg (Euler sum), '
                 f'{e["rre_geodesic"]:.2f} deg (geodesic), success {e["success"]}')
  return '\n'.join(lines)
