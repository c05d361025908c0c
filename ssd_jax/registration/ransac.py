"""RANSAC for rigid registration from putative correspondences (docs/method.md §4).

The rule is P. Kovesi's MATLAB `ransac.m`, as 3DFeat-Net evaluates. Each trial
takes a minimal sample of 3 correspondences, fits it with Kabsch and counts the
inliers within 1 m. After every trial that ties or beats the best inlier count,
the adaptive trial count is updated to N = log(1 - p) / log(1 - w^3), at least
`min_trials`. RANSAC stops when trials >= N or trials > max_trials. The best
hypothesis is then refit on all its inliers.

Both implementations consume the same pre-drawn sequence of minimal samples
(`draw_minimal_samples`), so they agree trial for trial:
  * `ransac_sequential`: the straightforward loop (the reference);
  * `ransac`: scores hypotheses in batches and replays the sequential stopping rule
    over their inlier counts, so the stopping point and the reported trial count are
    the sequential ones. Batches start small (32) and double up to `batch_size`, so a
    pair that stops after a few hundred trials scores a few hundred, not thousands.
"""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class RansacResult:
  transform: np.ndarray   # [4, 4] T_12: maps cloud 2 into cloud 1's frame
  inliers: np.ndarray     # [C] bool over the correspondences
  trials: int
  # [k, 4, 4]: the best hypotheses that differ from each other (`distinct_best`), refit,
  # the first being `transform`; for a check against the clouds (`verification`).
  candidates: np.ndarray | None = None


def kabsch(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
  """Least-squares rigid T [..., 4, 4] with T src ≈ dst; src, dst [..., n, 3], n >= 3
  (a batch of fits at once when there are leading axes)."""
  mu_s, mu_d = src.mean(-2, keepdims=True), dst.mean(-2, keepdims=True)
  u, _, vt = np.linalg.svd(np.swapaxes(src - mu_s, -1, -2) @ (dst - mu_d))
  v, ut = np.swapaxes(vt, -1, -2), np.swapaxes(u, -1, -2)
  d = np.sign(np.linalg.det(v @ ut))
  d = np.where(d == 0, 1.0, d)
  flip = np.ones(d.shape + (3,))
  flip[..., 2] = d
  rot = (v * flip[..., None, :]) @ ut
  t = np.zeros(src.shape[:-2] + (4, 4))
  t[..., :3, :3] = rot
  t[..., :3, 3] = mu_d[..., 0, :] - (rot @ mu_s[..., 0, :, None])[..., 0]
  t[..., 3, 3] = 1.0
  return t


def _degenerate(p: np.ndarray, eps: float = 1e-6) -> np.ndarray:
  """Samples [..., 3, 3] whose points are (nearly) collinear or coincident -> [...] bool."""
  return np.linalg.norm(np.cross(p[..., 1, :] - p[..., 0, :], p[..., 2, :] - p[..., 0, :]),
                        axis=-1) < eps


def _draw_samples(rng: np.random.Generator, n: int, size: int, num_trials: int, accept,
                  degenerate: str) -> np.ndarray:
  """[num_trials, size] indices into n correspondences, rows drawn uniformly and kept when
  `accept(rows [R, size]) -> [R] bool` says so (redrawn otherwise, as Kovesi's
  `maxDataTrials` loop does); ValueError(`degenerate`) when almost none pass."""
  out = np.empty((0, size), np.int64)
  for _ in range(100):
    cand = rng.integers(0, n, (max(num_trials - len(out), 1) * 2 + 16, size))
    out = np.concatenate([out, cand[accept(cand)]])[:num_trials]
    if len(out) == num_trials:
      return out
  raise ValueError(degenerate)


def draw_minimal_samples(rng: np.random.Generator, xyz2: np.ndarray, num_trials: int) -> np.ndarray:
  """The random minimal samples of `num_trials` trials: [T, 3] indices, three distinct
  correspondences per trial whose cloud-2 points are not collinear."""
  n = len(xyz2)
  if n < 3:
    raise ValueError(f'RANSAC needs at least 3 correspondences, got {n}')
  return _draw_samples(
      rng, n, 3, num_trials,
      lambda c: ((c[:, 0] != c[:, 1]) & (c[:, 0] != c[:, 2]) & (c[:, 1] != c[:, 2])
                 & ~_degenerate(xyz2[c])),
      'RANSAC: every minimal sample is degenerate (all cloud-2 keypoints collinear or '
      'coincident)')


def _check_samples(samples: np.ndarray, max_trials: int) -> None:
  if len(samples) < max_trials + 1:
    raise ValueError(f'RANSAC may run max_trials + 1 = {max_trials + 1} trials but got '
                     f'{len(samples)} samples; draw them with draw_minimal_samples(rng, xyz2, '
                     f'{max_trials + 1})')


def _adaptive_trials(score: int, n: int, confidence: float, min_trials: int,
                     sample_size: int = 3, pairs: int = 0) -> float:
  """N = log(1 - p) / log(1 - w^s), at least `min_trials`: the trials after which a sample
  of s correspondences all inliers (w = score / n of them) has been drawn with
  probability p. Samples drawn among `pairs` > 0 compatible pairs (`compatible_pairs`)
  are all inliers with probability score (score - 1) / 2 / pairs instead: the inliers'
  pairs among them."""
  if pairs > 0:
    good = score * (score - 1) / 2.0 / pairs
  else:
    good = (score / n) ** sample_size
  p_no_outliers = min(max(1.0 - good, np.finfo(float).eps),
                      1.0 - np.finfo(float).eps)
  return max(float(min_trials), np.log(1.0 - confidence) / np.log(p_no_outliers))


def ransac_sequential(xyz1: np.ndarray, xyz2: np.ndarray, samples: np.ndarray,
                      inlier_threshold: float = 1.0, confidence: float = 0.99,
                      max_trials: int = 10_000, min_trials: int = 10) -> RansacResult:
  """Correspondences xyz1[i] <-> xyz2[i] ([C, 3] metres each) -> T_12, one trial at a
  time over samples [>= max_trials + 1, 3]."""
  _check_samples(samples, max_trials)
  n = len(xyz1)
  best_score, best_inliers, trials, needed = -1, None, 0, float(min_trials)
  while needed > trials:
    inliers = _sample_inliers(xyz1, xyz2, samples[trials], inlier_threshold)
    score = int(inliers.sum())
    if score >= best_score:
      best_score, best_inliers = score, inliers
      needed = _adaptive_trials(score, n, confidence, min_trials)
    trials += 1
    if trials > max_trials:
      break
  transform = kabsch(xyz2[best_inliers], xyz1[best_inliers]) if best_score >= 3 else np.eye(4)
  return RansacResult(transform, best_inliers, trials)


def _sample_inliers(xyz1: np.ndarray, xyz2: np.ndarray, sample: np.ndarray,
                    threshold: float) -> np.ndarray:
  """The inliers [C] bool of the Kabsch fit to one minimal sample [3]."""
  model = kabsch(xyz2[sample], xyz1[sample])
  return np.linalg.norm(xyz2 @ model[:3, :3].T + model[:3, 3] - xyz1, axis=1) < threshold


FIRST_BATCH = 32
# A batch's [batch, C] float64 residual planes hold at most this many entries (4 MB):
# thousands of ISS matches score in smaller batches.
MAX_BATCH_ENTRIES = 512 * 1024


def _numpy_scorer(xyz1: np.ndarray, xyz2: np.ndarray, threshold: float):
  """samples [B, 3] -> inlier counts [B], as `ransac_sequential` counts them."""
  planes = [np.ascontiguousarray(xyz2[:, k]) for k in range(3)]
  thr2 = threshold * threshold

  def score(samples: np.ndarray) -> np.ndarray:
    t = kabsch(xyz2[samples], xyz1[samples])                       # [B, 4, 4]
    # Each residual coordinate as a [B, C] plane, summed in place: 2x faster than
    # [B, C, 3] products with the 3 x 3 rotations.
    total = np.zeros((len(samples), len(xyz1)))
    for i in range(3):
      d = t[:, i, 0, None] * planes[0]
      d += t[:, i, 1, None] * planes[1]
      d += t[:, i, 2, None] * planes[2]
      d += t[:, i, 3, None] - xyz1[:, i]
      d *= d
      total += d
    return np.sum(total < thr2, axis=1)
  return score


def ransac(xyz1: np.ndarray, xyz2: np.ndarray, samples: np.ndarray,
           inlier_threshold: float = 1.0, confidence: float = 0.99, max_trials: int = 10_000,
           min_trials: int = 10, batch_size: int = 512) -> RansacResult:
  """`ransac_sequential`'s result, scoring hypotheses in batches: they grow 32, 64, ...
  up to `batch_size` (fewer where C correspondences would pass MAX_BATCH_ENTRIES), and
  trials after the one at which the sequential rule stops are never scored."""
  _check_samples(samples, max_trials)
  batch_size = max(1, min(batch_size, MAX_BATCH_ENTRIES // max(len(xyz1), 1)))
  trials, best_trial, best_score, _ = _replay(
      _numpy_scorer(xyz1, xyz2, inlier_threshold), samples, len(xyz1), confidence,
      max_trials, min_trials, batch_size)
  inliers = _sample_inliers(xyz1, xyz2, samples[best_trial], inlier_threshold)
  transform = kabsch(xyz2[inliers], xyz1[inliers]) if best_score >= 3 else np.eye(4)
  return RansacResult(transform, inliers, trials)


def _replay(score, samples, n, confidence, max_trials, min_trials, batch_size,
            pairs: int = 0) -> tuple[int, int, int, np.ndarray]:
  """The sequential stopping rule over batches of inlier counts: the one RANSAC loop of
  both motion models. score(samples [B, s]) -> inlier counts [B] of the hypotheses of a
  batch of samples [T, s] (s = 3 rigid, 2 upright: the rule's N uses w^s, or the
  inliers' share of `pairs` compatible pairs, `_adaptive_trials`). Batches grow
  FIRST_BATCH, 2x, ... up to `batch_size`. The loop also ends with the samples.
  -> (trials, index of the best trial, its inlier count, the counts of the trials [trials])."""
  sample_size = samples.shape[1]
  best_score, best_trial, trials, needed = -1, 0, 0, float(min_trials)
  size, scored = min(FIRST_BATCH, batch_size), []
  while needed > trials and trials <= max_trials and trials < len(samples):
    batch = samples[trials: min(trials + size, max_trials + 1)]
    scores = np.asarray(score(batch))
    scored.append(scores)
    for s in scores.tolist():
      if s >= best_score:
        best_score, best_trial = s, trials
        needed = _adaptive_trials(s, n, confidence, min_trials, sample_size, pairs)
      trials += 1
      if not needed > trials or trials > max_trials or trials == len(samples):
        break
    size = min(2 * size, batch_size)
  return trials, best_trial, best_score, np.concatenate(scored)[:trials]


# Upright RANSAC: scans whose z axis is up (a vehicle's LiDAR, a levelled tripod) differ by
# a turn about z and a translation, 4 degrees of freedom that 2 correspondences fix. A
# 2-point sample is all-inlier with probability w^2 instead of w^3: at 2 % correct matches
# 10,000 trials find the pose with 98 % chance, where 3-point samples need 575,000.
UPRIGHT_MIN_SEPARATION = 0.5   # metres: a 2-point sample closer than this fixes no yaw


def upright_fit(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
  """Least-squares turn about z and translation T [..., 4, 4] with T src ≈ dst;
  src, dst [..., n, 3] (n >= 2)."""
  w = np.full(src.shape[:-1], 1.0 / src.shape[-2])
  mu_s = np.einsum('...n,...nk->...k', w, src)
  mu_d = np.einsum('...n,...nk->...k', w, dst)
  s, d = src - mu_s[..., None, :], dst - mu_d[..., None, :]
  # The yaw maximising sum <R s, d> in the xy-plane (2-D Kabsch).
  sxx = np.einsum('...n,...n->...', w, s[..., 0] * d[..., 0] + s[..., 1] * d[..., 1])
  sxy = np.einsum('...n,...n->...', w, s[..., 0] * d[..., 1] - s[..., 1] * d[..., 0])
  yaw = np.arctan2(sxy, sxx)
  c, si = np.cos(yaw), np.sin(yaw)
  t = np.zeros(src.shape[:-2] + (4, 4))
  t[..., 0, 0], t[..., 0, 1], t[..., 1, 0], t[..., 1, 1] = c, -si, si, c
  t[..., 2, 2] = t[..., 3, 3] = 1.0
  t[..., :3, 3] = mu_d - np.einsum('...ij,...j->...i', t[..., :3, :3], mu_s)
  return t


def draw_upright_samples(rng: np.random.Generator, xyz2: np.ndarray, num_trials: int) -> np.ndarray:
  """[T, 2] indices: two correspondences per trial whose cloud-2 points lie at least
  UPRIGHT_MIN_SEPARATION apart horizontally."""
  n = len(xyz2)
  if n < 2:
    raise ValueError(f'upright RANSAC needs at least 2 correspondences, got {n}')
  return _draw_samples(
      rng, n, 2, num_trials,
      lambda c: np.linalg.norm(xyz2[c[:, 0], :2] - xyz2[c[:, 1], :2], axis=1)
      >= UPRIGHT_MIN_SEPARATION,
      'RANSAC: every minimal sample is degenerate (all cloud-2 keypoints within '
      f'{UPRIGHT_MIN_SEPARATION} m of each other horizontally)')


PAIR_BLOCK = 512   # correspondences a block of `compatible_pairs` compares with all others


# Compatible pairs (Open3D's edge-length checker, used to draw samples rather than to
# reject them): two correct matches of upright scans keep their horizontal distance and
# share one height shift. Far apart scans of one street leave ~1-2 % of the
# nearest-neighbour matches correct; a uniform 2-point sample is then all-inlier once in
# 2,500-10,000 draws, while ~2 % of all pairs pass the check and the inliers' pairs are
# among them: one compatible sample in ~100-1,000 is all-inlier.
def compatible_pairs(xyz1: np.ndarray, xyz2: np.ndarray, tolerance: float,
                     min_separation: float = UPRIGHT_MIN_SEPARATION) -> np.ndarray:
  """Pairs (i < j) [E, 2] of correspondences xyz1[i] <-> xyz2[i] ([C, 3] metres) that one
  turn about z and shift can map onto each other: horizontal distances within
  `tolerance` metres of each other (at least `min_separation` in cloud 2, else the pair
  fixes no yaw) and height shifts within `tolerance`."""
  p, q = np.asarray(xyz1, np.float32).T, np.asarray(xyz2, np.float32).T   # [3, C]
  shift = p[2] - q[2]
  found = [np.zeros((0, 2), np.int64)]

  def distances(c, rows, cols):   # horizontal, [rows, cols], as [B, C] planes
    dx = c[0, rows, None] - c[0, None, cols]
    dy = c[1, rows, None] - c[1, None, cols]
    dx *= dx
    dy *= dy
    dx += dy
    return np.sqrt(dx, out=dx)

  # Rows in blocks against the columns after the block's first row: [block, C] matrices,
  # not [C, C] (ISS keypoints may number thousands), and only pairs i < j computed.
  for start in range(0, p.shape[1], PAIR_BLOCK):
    rows, cols = slice(start, start + PAIR_BLOCK), slice(start + 1, None)
    d2 = distances(q, rows, cols)
    ok = d2 >= min_separation
    d2 -= distances(p, rows, cols)
    ok &= np.abs(d2) < tolerance
    ok &= np.abs(shift[rows, None] - shift[None, cols]) < tolerance
    i, j = np.nonzero(ok)
    j += start + 1
    keep = j > i + start
    found.append(np.stack([i[keep] + start, j[keep]], 1).astype(np.int64))
  return np.concatenate(found)


def draw_compatible_samples(rng: np.random.Generator, xyz1: np.ndarray, xyz2: np.ndarray,
                            num_trials: int, tolerance: float) -> tuple[np.ndarray, int]:
  """Upright RANSAC's samples drawn among the `compatible_pairs` without repeats: -> (up
  to `num_trials` of them [T, 2], how many pairs there are). Where no pair is
  compatible, `draw_upright_samples`' uniform draws and 0."""
  pairs = compatible_pairs(xyz1, xyz2, tolerance)
  if not len(pairs):
    return draw_upright_samples(rng, xyz2, num_trials), 0
  return pairs[rng.permutation(len(pairs))[:num_trials]], len(pairs)


# Two hypotheses closer than this (metres, degrees) are one candidate pose.
CANDIDATE_SEPARATION = (2.0, 5.0)
# With candidates, RANSAC scores at least this many trials: where a repeated structure's
# matches outnumber the true ones, the stopping rule is met within tens of trials, before a
# 2-point sample of the true matches has been drawn (1,000 draw ~40 at 20 % true matches).
CANDIDATE_MIN_TRIALS = 1000


def same_pose(a: np.ndarray, b: np.ndarray,
              separation: tuple[float, float] = CANDIDATE_SEPARATION) -> bool:
  """Whether two poses [4, 4] are one candidate: closer than `separation` (metres of
  translation and degrees of rotation) in both."""
  cos = (np.sum(a[:3, :3] * b[:3, :3]) - 1.0) / 2.0
  return bool(np.linalg.norm(a[:3, 3] - b[:3, 3]) < separation[0]
              and np.clip(cos, -1.0, 1.0) > np.cos(np.deg2rad(separation[1])))


def distinct_best(transforms: np.ndarray, scores: np.ndarray, k: int,
                  separation: tuple[float, float] = CANDIDATE_SEPARATION) -> list[int]:
  """Indices of up to k hypotheses [T, 4, 4], best score [T] first (earliest on ties),
  each at least `separation` (metres of translation or degrees of rotation) from every
  one chosen before it: the runners-up a repetitive scene leaves, not copies of the best."""
  transforms = np.asarray(transforms, np.float64)
  # Rotation angle between R_i and R_j from trace(R_i R_j^T) = sum(R_i * R_j).
  cos_min = np.cos(np.deg2rad(separation[1]))
  chosen = []
  for i in np.argsort(-np.asarray(scores), kind='stable'):
    if len(chosen) == k:
      break
    if chosen:
      others = transforms[chosen]
      near = np.linalg.norm(others[:, :3, 3] - transforms[i, :3, 3], axis=1) < separation[0]
      cos = (np.sum(others[:, :3, :3] * transforms[i, :3, :3], axis=(1, 2)) - 1.0) / 2.0
      if np.any(near & (np.clip(cos, -1.0, 1.0) > cos_min)):
        continue
    chosen.append(int(i))
  return chosen


def ransac_upright(xyz1: np.ndarray, xyz2: np.ndarray, samples: np.ndarray,
                   inlier_threshold: float = 1.0, confidence: float = 0.99,
                   max_trials: int = 10_000, min_trials: int = 10,
                   batch_size: int = 512, candidates: int = 1, pairs: int = 0
                   ) -> RansacResult:
  """RANSAC over 2-point upright hypotheses (`upright_fit`) with the adaptive stopping rule
  of `ransac_sequential` for 2-point samples (N = log(1 - p) / log(1 - w^2); `_replay`).
  Correspondences xyz1[i] <-> xyz2[i] ([C, 3] metres), samples [>= max_trials + 1, 2]
  from `draw_upright_samples`; or, with `pairs` > 0, up to max_trials + 1 of that many
  compatible pairs (`draw_compatible_samples`), the stopping rule then counting the
  inliers' pairs among them. The best hypothesis is refit on its inliers in all 6
  degrees of freedom (Kabsch), its inliers recounted and the pose refit once more, so a
  scan tilted by a few degrees still comes out exact. With `candidates` > 1 the
  result's `candidates` holds up to that many distinct best hypotheses of the trials
  scored (`distinct_best`), each refit alike, and at least CANDIDATE_MIN_TRIALS are
  scored."""
  if not pairs:
    _check_samples(samples, max_trials)
  thr2 = inlier_threshold * inlier_threshold
  if candidates > 1:
    min_trials = max(min_trials, min(CANDIDATE_MIN_TRIALS, max_trials))

  x2, y2, z2 = (np.ascontiguousarray(xyz2[:, k]) for k in range(3))
  dz0 = z2 - xyz1[:, 2]

  def score(batch):
    # A turn about z: x and y of each residual from the yaw's cosine and sine, z a shift
    # ([B, C] planes, not [B, C, 3] products with a 3 x 3 that is mostly 0 and 1).
    t = upright_fit(xyz2[batch], xyz1[batch])
    c, s = t[:, 0, 0, None], t[:, 1, 0, None]
    dx = c * x2 - s * y2 + (t[:, 0, 3, None] - xyz1[:, 0])
    dy = s * x2 + c * y2 + (t[:, 1, 3, None] - xyz1[:, 1])
    dz = dz0 + t[:, 2, 3, None]
    dx *= dx
    dy *= dy
    dz *= dz
    dx += dy
    dx += dz
    return np.sum(dx < thr2, axis=1)

  trials, best_trial, _, scores = _replay(score, samples, len(xyz1), confidence, max_trials,
                                          min_trials, batch_size, pairs=pairs)
  residual = lambda t: np.sum((xyz2 @ t[:3, :3].T + t[:3, 3] - xyz1) ** 2, -1)

  def refit(trial):
    transform = upright_fit(xyz2[samples[trial]], xyz1[samples[trial]])
    inliers = residual(transform) < thr2
    for _ in range(2):
      if inliers.sum() < 3:
        break
      transform = kabsch(xyz2[inliers], xyz1[inliers])
      inliers = residual(transform) < thr2
    return transform, inliers

  transform, inliers = refit(best_trial)
  if candidates <= 1:
    return RansacResult(transform, inliers, trials)
  # Every scored trial up to the stop; the best one first, as the loop chose it.
  scores[best_trial] = np.iinfo(scores.dtype).max
  fits = upright_fit(xyz2[samples[:trials]], xyz1[samples[:trials]])
  others = [refit(i)[0] for i in distinct_best(fits, scores, candidates)[1:]]
  return RansacResult(transform, inliers, trials, np.stack([transform, *others]))
