"""Where a model's keypoints should be sampled on a sensor, chosen on pairs mined from its
own scans: no pose is read.

Two scans of one spinning unit draw the same rings on the ground at the same ranges from
their sensors, and the ground's descriptors carry that range: for some units the matches
among those rings outvote the structure's and pull two standpoints together
(docs/notes/cross_sensor.md). So `experiments.adapt` registers mined pairs with the
adapted model's descriptor alone, once from each keypoint domain of
`inference.KEYPOINT_SELECTIONS`, and keeps the domain that registers more; on a tie,
'structure' (a user's pairs are two scans of that one unit, whose rings can only
mislead). The pairs are where the two can differ: farther apart than the miner's own,
each composed of two kept pairs (`mined_pairs.chained`): with G the largest gap at which
the miner kept CHOICE_PAIRS pairs, the gaps G+1 to 2G, as many pairs of each.
Measured choices: docs/notes/real_drives.md and docs/notes/cross_sensor.md.
"""

from __future__ import annotations

import collections
import dataclasses
from typing import Callable, Sequence

import numpy as np

from ssd_jax import inference
from ssd_jax.data import mined_pairs
from ssd_jax.registration import metrics, pipeline
from ssd_jax.registration import options as options_lib

# Pairs registered per domain (~1 minute each on 2 cores).
CHOICE_PAIRS = 32


@dataclasses.dataclass(frozen=True)
class Choice:
  keypoints: str           # the domain kept (`inference.KEYPOINT_SELECTIONS`)
  registered: dict         # domain -> pairs registered (RTE < 2 m, RRE < 5° from the miner's)
  pairs: int               # pairs tried per domain
  gaps: tuple              # the smallest and largest gap among them (scans apart)

  def line(self) -> str:
    counts = ', '.join(f"'{k}' {v}" for k, v in self.registered.items())
    return (f"keypoints from '{self.keypoints}' points: of {self.pairs} mined pairs "
            f'{self.gaps[0]}-{self.gaps[1]} scans apart (chained), the descriptor alone '
            f'registers {counts}')


def choice_pairs(pairs: Sequence[mined_pairs.MinedPair],
                 count: int = CHOICE_PAIRS) -> list[mined_pairs.MinedPair]:
  """Up to `count` pairs beyond the miner's reach: with G the largest gap at which
  `count` of `pairs` are kept (else their largest gap), the kept and two-link chained
  pairs (`mined_pairs.chained`) with gaps G+1 to 2G, the same number of each gap where
  they have it (capture order within a gap, evenly spaced), the largest gaps first."""
  kept = [p for p in pairs if p.kept]
  if not kept:
    return []
  by_gap = collections.Counter(p.gap for p in kept)
  enough = [g for g, n in by_gap.items() if n >= count]
  reach = max(enough) if enough else max(by_gap)
  pool: dict[int, list] = collections.defaultdict(list)
  for p in mined_pairs.chained(kept, 2):
    if reach < p.gap <= 2 * reach:
      pool[p.gap].append(p)
  out, gaps = [], sorted(pool, reverse=True)
  for i, gap in enumerate(gaps):
    # This gap's share of what is left, so a gap with fewer pairs leaves its share to the rest.
    share = (count - len(out)) // (len(gaps) - i)
    group = pool[gap]
    take = min(share, len(group))
    if take:
      out += [group[j] for j in np.linspace(0, len(group) - 1, take).round().astype(int)]
  return out


def registered(model: inference.Model, pairs: Sequence[mined_pairs.MinedPair],
               read: Callable[[str], np.ndarray], keypoints: str) -> int:
  """How many of `pairs` the model's descriptor alone (`--verify=0 --bev=0`) registers
  with 'auto' keypoints from the `keypoints` domain, against the miner's T_12."""
  model = dataclasses.replace(model, keypoints=keypoints)
  options = options_lib.Options(verify=0, bev=0)
  results = pipeline.register_many([(p.cloud1, p.cloud2) for p in pairs], read, model=model,
                                   options=options, say=lambda line: None)
  return sum(metrics.registration_errors(p.transform, r.registration.transform)['success']
             for p, r in zip(pairs, results) if not r.error)


def choose(model: inference.Model, pairs: Sequence[mined_pairs.MinedPair],
           read: Callable[[str], np.ndarray], count: int = CHOICE_PAIRS) -> Choice | None:
  """The keypoint domain that registers more of the `choice_pairs` ('structure' unless
  'all' registers strictly more); None where there are none."""
  sample = choice_pairs(pairs, count)
  if not sample:
    return None
  counts = {k: registered(model, sample, read, k) for k in inference.KEYPOINT_SELECTIONS}
  best = 'all' if counts['all'] > counts['structure'] else 'structure'
  return Choice(best, counts, len(sample), (min(p.gap for p in sample),
                                            max(p.gap for p in sample)))
