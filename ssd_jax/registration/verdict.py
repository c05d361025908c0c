"""Whether a registered pose is to be trusted: `registered` true or false, with the reason.

Every registration returns a pose; many real pairs (scans far apart, half overlapping, a
solid-state unit facing elsewhere) have no right one to find, and a wrong pose looks like
a right one by its fitness alone: the ground fits every upright pose. Each of these
refuses the final pose:

  * 'degenerate': the scans leave part of the pose free (`uncertainty.PoseUncertainty.free`;
    for a pose found after the first was refused, `free_under(RETRY_MIN_CONSTRAINT)`);
  * 'free-space conflict': more than MAX_CONFLICT of one scan's structure lies where the
    other scan's laser passed through (`free_space.conflict`);
  * 'seen from behind': more than MAX_BEHIND of the structure lying on the other scan
    lies on surfaces the two sensors face from opposite sides (`free_space.seen_from_behind`),
    where the pose fits under `verification.CONFIDENT_FITNESS`;
  * 'low overlap': under MIN_FITNESS of cloud 2's structure lies within
    `verification.FIT_DISTANCE` of cloud 1;
  * 'ambiguous candidates': a distinct pose (`ransac.CANDIDATE_SEPARATION` away) that also
    passes the free-space check fits within AMBIGUOUS_MARGIN of the best;
  * 'unsupported': fewer descriptor matches than one RANSAC sample (MIN_SUPPORT) agree
    with the pose (from the bird's-eye-view search or an ICP's slide), and under
    SUPPORTED_FITNESS of the structure fits.

Thresholds are round numbers between the right and the wrong poses' values on the
development drives (docs/notes/real_drives.md: the values, the verdict's precision and
recall); free space is judged only where both scans are in their sensors' frames
(`free_space.sensor_centred`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ssd_jax.registration import prepared, ransac, uncertainty, verification

# Right poses on the development drives conflict 0.005-0.08 outdoors (moving cars and
# people; up to 0.14 indoors among people), wrong ones 0.12-0.5.
MAX_CONFLICT = 0.1
# Right poses 20-30 m apart on a real road lay 0.16-0.17 of cloud 2's structure on cloud 1.
MIN_FITNESS = 0.15
AMBIGUOUS_MARGIN = 0.05
# Matches within the inlier threshold under the pose: an upright RANSAC sample is 2. Right
# poses so unsupported on the development drives fit >= 0.51 (far pairs of a coarse-posed
# drive), wrong ones <= 0.21 (a hand-held Livox unit's pairs 17-28 m apart).
MIN_SUPPORT = 2
SUPPORTED_FITNESS = 0.35
# A pose a retry found, after the first try's was refused (`Options.retry`), must hold every
# shift by RETRY_MIN_CONSTRAINT per correspondence: 4x `uncertainty.MIN_CONSTRAINT`, 0.03.
# The pairs that reach a retry share little, and there a wrong pose whose overlap holds a
# shift along it only weakly fits and leaves free space as empty as a right one: on the
# development drives (`ours_mined` and `ours`) the retries' wrong poses held 0.016-0.019
# (four) and 0.035-0.051 (four), their right ones 0.057 or more. A first try's right pose
# may hold less (0.02: a front-view unit on a road), so the bound is the retries' alone.
RETRY_MIN_CONSTRAINT = 4 * uncertainty.MIN_CONSTRAINT
# On the development drives a wrong pose seen from behind lays 0.04-0.29 of cloud 2's
# structure on cloud 1; right poses are seen from behind up to 0.03 on drives, but a
# re-scan from a virtual standpoint inside what the scan saw (its walls seen from the
# back) is, up to 0.995, and those fit 0.74-1.0: so the rule holds only for poses that fit
# under CONFIDENT_FITNESS.
MAX_BEHIND = 0.5
REASONS = ('degenerate', 'free-space conflict', 'seen from behind', 'low overlap',
           'ambiguous candidates', 'unsupported')


@dataclasses.dataclass(frozen=True)
class Verdict:
  """The verdict on one pose. fitness: share of cloud 2's structure within FIT_DISTANCE of
  cloud 1; conflict: `free_space.conflict` and behind: `free_space.seen_from_behind` (None
  where not judged); runner_up: the fitness of the best distinct candidate that passes the
  free-space checks, where one fits within AMBIGUOUS_MARGIN of the chosen pose (else None);
  support: the descriptor matches the pose explains (None where not counted)."""
  registered: bool
  reason: str            # '' where registered, else REASONS[k] + ': ' + what was measured
  fitness: float
  conflict: float | None = None
  runner_up: float | None = None
  support: int | None = None
  behind: float | None = None

  @property
  def kind(self) -> str:
    """The reason's name (`REASONS`), '' where registered."""
    return self.reason.split(':')[0]

  def to_json(self) -> dict:
    return {'registered': self.registered, 'reason': self.reason, 'fitness': self.fitness,
            'free_space_conflict': self.conflict, 'runner_up_fitness': self.runner_up,
            'support': self.support, 'seen_from_behind': self.behind}

  def line(self) -> str:
    """'registered' or 'NOT registered (reason)', for the one-line summaries."""
    return 'registered' if self.registered else f'NOT registered ({self.reason})'


def seen_from_behind(fitness: float, behind: float | None) -> bool:
  """Whether a pose fitting `fitness`, whose structure is seen from behind `behind` (None
  where not judged), is refused for it (`MAX_BEHIND`, under `CONFIDENT_FITNESS`)."""
  return behind is not None and behind > MAX_BEHIND and fitness < verification.CONFIDENT_FITNESS


def judge(fitness: float, conflict: float | None, free: str = '',
          runner_up: float | None = None, support: int | None = None,
          behind: float | None = None) -> Verdict:
  """The `Verdict` on a pose from what was measured at it: fitness, conflict and behind
  (None where free space was not judged), free (the uncertainty's line, '' where the scans
  fix the pose), runner_up (the fitness of the best distinct candidate that passes the
  free-space checks, None where there is none) and support (the descriptor matches the
  pose explains, None where not counted)."""
  reason = ''
  if free:
    reason = f'degenerate: {free}'
  elif conflict is not None and conflict > MAX_CONFLICT:
    reason = (f"free-space conflict: {conflict:.0%} of a scan's structure lies where the "
              f"other's rays passed (over {MAX_CONFLICT:.0%})")
  elif seen_from_behind(fitness, behind):
    reason = (f"seen from behind: {behind:.0%} of the structure on the other scan lies on "
              f'surfaces the two sensors face from opposite sides (over {MAX_BEHIND:.0%}), '
              f'and it fits {fitness:.2f}')
  elif fitness < MIN_FITNESS:
    reason = (f"low overlap: {fitness:.0%} of cloud 2's structure lies on cloud 1 (under "
              f'{MIN_FITNESS:.0%})')
  elif runner_up is not None and runner_up >= fitness - AMBIGUOUS_MARGIN:
    reason = (f'ambiguous candidates: a distinct pose fits {runner_up:.2f} against the '
              f'chosen {fitness:.2f}')
  elif support is not None and support < MIN_SUPPORT and fitness < SUPPORTED_FITNESS:
    reason = (f'unsupported: {support} of the descriptor matches agree with the pose, which '
              f"lays {fitness:.0%} of cloud 2's structure on cloud 1")
  return Verdict(not reason, reason, float(fitness), conflict, runner_up, support, behind)


def assess(pair: prepared.PreparedPair, transform: np.ndarray, free: str = '',
           candidates: np.ndarray | None = None,
           candidate_fitness: np.ndarray | None = None,
           support: int | None = None) -> Verdict:
  """The `Verdict` on T_12 [4, 4] of the clouds of `pair` (in their own frames); free and
  support as for `judge`; candidates [k, 4, 4] with their fitness [k]: the verification's poses
  (`verification.verify`), of which only those distinct from T_12 that fit within
  AMBIGUOUS_MARGIN of it are checked for free space and sides (None where a cloud's origin
  is no viewpoint: `prepared.PreparedCloud.range_image`)."""
  fitness = verification.fitness(pair.cloud1.target, pair.cloud2.source.scored, transform)
  runner_up = None
  if candidates is not None:
    for c in np.argsort(-np.asarray(candidate_fitness), kind='stable'):
      if ransac.same_pose(candidates[c], transform):
        continue
      if candidate_fitness[c] < fitness - AMBIGUOUS_MARGIN:
        break
      other = pair.conflict(candidates[c])
      if ((other is None or other <= MAX_CONFLICT)
          and not seen_from_behind(candidate_fitness[c], pair.behind(candidates[c]))):
        runner_up = float(candidate_fitness[c])
        break
  return judge(fitness, pair.conflict(transform), free, runner_up, support,
               pair.behind(transform))
