"""Training pairs without labels: two scans of one place and the transform between them,
mined from a folder of unlabeled scans in capture order (a drive, a survey) by the
project's own classical registration, and kept only where it is self-consistent.

1. Candidates: every scan i with scan i + g for each gap g of `gaps` (capture order puts
   scans a few metres apart next to each other; growing gaps reach farther pairs, up to
   the first gap the teacher no longer registers).
2. Each candidate is registered by `pipeline.register_many` with `teacher_options()`
   (FPFH, RANSAC, the bird's-eye-view search, verification by ICP); no learned model and
   no pose is read.
3. Gate: a pair is *confident* when its verified pose lays `MIN_FITNESS` of scan 2's
   structure on scan 1 with no distinct pose close behind
   (`verification.clearly_confident`) and the register command's verdict trusts it. It
   is *kept* when it is also one side of a loop of three confident pairs (i, j), (j, k),
   (i, k) whose poses agree (T_ij T_jk within `CYCLE_ROTATION_DEG` and
   `CYCLE_TRANSLATION_M` of T_ik), or of four (T_ij T_jl against T_ik T_kl). Two wrong
   poses rarely compose into a third wrong pose found on its own: the loop, not the
   fitness, makes a label trustworthy.

Widening (EYOC's curriculum): a model trained on the kept pairs registers farther pairs
than its teacher did; `widened_gaps` names the next gaps, `mine(model=...)` registers them
with it, and `mine_to_file` gates every round's pairs together, so a far pair is also kept
through loops closed by nearer labels. `spread` thins a long drive to the scans mined, at
the stride `stride_for` finds its teacher closing loops at. `label_errors` measures the
kept labels against ground-truth poses where a user has them (the miner never reads them).
"""

from __future__ import annotations

import contextlib
from concurrent import futures
import functools
import multiprocessing
import os
import threading
import time
from typing import Callable, Sequence

import numpy as np

from ssd_jax import geometry
from ssd_jax.infra import errors
from ssd_jax.data import mined_pairs
from ssd_jax.data.mined_pairs import MinedPair
from ssd_jax.registration import metrics, pipeline, verification
from ssd_jax.registration import options as options_lib

DEFAULT_GAPS = (1, 2, 4, 8)
# A verified pose is a candidate label from this fitness up: sparse scans 10-25 m apart
# share little (VLP-16 drive scans 12-24 m apart fit 0.23-0.49 at the right pose; the
# register command's CONFIDENT_FITNESS, 0.5, would keep none of them). The loop check below
# keeps wrong poses out.
MIN_FITNESS = 0.2
# Loop closure tolerances of the gate: a pose good enough to train on (the paper's success
# is 2 m / 5 degrees; a label should be well inside it).
CYCLE_ROTATION_DEG = 2.0
CYCLE_TRANSLATION_M = 0.5
# Growing gaps stop at the first whose probe (every PROBE_EVERY-th pair, MIN_PROBE at
# least, evenly spread) registers fewer than MIN_YIELD of its pairs confidently.
PROBE_EVERY = 8
MIN_PROBE = 8
MIN_YIELD = 0.2
# Pairs a worker registers in one go (`mine(workers=...)`): consecutive pairs share clouds.
CHUNK = 16
# The commands' default: one process a core, at most 8.
DEFAULT_WORKERS = max(1, min(8, os.cpu_count() or 1))


def teacher_options() -> options_lib.Options:
  """The classical registration that labels pairs: the register command's defaults with
  FPFH descriptors (no learned model); the verification's ICP refines each pose."""
  return options_lib.Options(descriptor='fpfh')


def least_stride(num_scans: int, max_scans: int) -> int:
  """The least k for which every k-th of `num_scans` scans is at most `max_scans` of them."""
  if max_scans < 3:
    raise errors.UserError(f'max_scans must be 3 or more (a loop takes three), got {max_scans}')
  return -(-num_scans // max_scans) or 1


def spread(scans: Sequence[str], max_scans: int, stride: int | None = None) -> list[str]:
  """Every `stride`-th of `scans` (capture order; default `least_stride`): the growing gaps
  then reach as far in metres for a fraction of the registrations. Where that leaves more
  than `max_scans`, the middle `max_scans` of them, consecutive."""
  stride = least_stride(len(scans), max_scans) if stride is None else stride
  every = list(scans)[::stride]
  start = max(0, (len(every) - max_scans) // 2)
  return every[start:start + max_scans]


def stride_for(scans: Sequence[str], read: Callable[[str], np.ndarray], max_scans: int, *,
               say: Callable[[str], None] = print) -> int:
  """The stride to `spread` `scans` at: from `least_stride`, halved while the teacher
  registers confidently under MIN_YIELD of MIN_PROBE pairs two strides apart, the side
  that closes a loop of three (a drive of keyframes far apart, where every k-th scan
  leaves the loops too long to register, is mined at a shorter stride)."""
  stride = least_stride(len(scans), max_scans)
  while stride > 1 and len(scans) > 2 * stride:
    ends = np.linspace(0, len(scans) - 1 - 2 * stride, MIN_PROBE).round().astype(int)
    probe = [_judged(result, 2 * stride) for result in pipeline.register_many(
        [(str(scans[i]), str(scans[i + 2 * stride])) for i in ends], read,
        options=teacher_options(), say=lambda line: None)]
    share = np.mean([p.confident for p in probe])
    if share >= MIN_YIELD:
      break
    say(f'stride {stride}: {share:.0%} of {len(probe)} probed loop sides confident (< '
        f'{MIN_YIELD:.0%}): stride {stride // 2}')
    stride //= 2
  return stride


def widened_gaps(pairs: Sequence[MinedPair], count: int = 2) -> tuple[int, ...]:
  """The `count` gaps after the largest at which `pairs` kept MIN_YIELD of those
  registered, each twice the last (() when none was): a gap whose probe failed, with a
  stray pair kept, is widened to, not past."""
  reached = max((g for g in {p.gap for p in pairs}
                 if np.mean([p.kept for p in pairs if p.gap == g]) >= MIN_YIELD), default=0)
  return tuple(reached * 2 ** k for k in range(1, count + 1)) if reached else ()


def candidate_pairs(num_scans: int, gaps: Sequence[int] = DEFAULT_GAPS
                    ) -> list[tuple[int, int]]:
  """(i, i + g) for each scan i and gap g, ordered by i so that a batch registration
  meets each scan among its recent neighbours."""
  if not gaps or min(gaps) < 1:
    raise errors.UserError(f'gaps must be positive scan counts, got {tuple(gaps)}')
  return [(i, i + g) for i in range(num_scans) for g in sorted(set(gaps)) if i + g < num_scans]


def cycle_error(t_ab: np.ndarray, t_bc: np.ndarray, t_ac: np.ndarray) -> tuple[float, float]:
  """How far T_ab T_bc is from T_ac: (rotation degrees, translation metres)."""
  e = metrics.registration_errors(t_ac, t_ab @ t_bc)
  return e['rre_geodesic'], e['rte']


def apply_gate(pairs: list[MinedPair], index: dict[str, int]) -> list[MinedPair]:
  """Sets `kept` and `reason` of every pair (`index`: each cloud's capture position): kept
  where confident and a side of a consistent loop of three confident pairs (i, j, k), or
  of four (i, j, l and i, k, l: two far pairs joined at both ends by nearer ones, where a
  drive's near pairs are too sparse to close triangles with them)."""
  sure = {(index[p.cloud1], index[p.cloud2]): p for p in pairs if p.confident}
  after: dict[int, list[int]] = {}
  for i, j in sure:
    after.setdefault(i, []).append(j)
  consistent: set[tuple[int, int]] = set()

  def close(loop, via_a, via_b):   # T along via_a equals T along via_b
    compose = lambda path: functools.reduce(np.matmul, [sure[e].transform for e in path])
    rot, trans = cycle_error(compose(via_a), np.eye(4), compose(via_b))
    if rot <= CYCLE_ROTATION_DEG and trans <= CYCLE_TRANSLATION_M:
      consistent.update(loop)

  for (i, j) in sure:
    for k in after.get(j, []):
      if (i, k) in sure:
        close({(i, j), (j, k), (i, k)}, [(i, j), (j, k)], [(i, k)])
      for m in after.get(i, []):
        if m != j and (m, k) in sure:
          close({(i, j), (j, k), (i, m), (m, k)}, [(i, j), (j, k)], [(i, m), (m, k)])
  for p in pairs:
    p.kept = p.confident and (index[p.cloud1], index[p.cloud2]) in consistent
    if p.confident:   # the others keep their registration's reason
      p.reason = '' if p.kept else 'in no consistent loop'
  return pairs


def mine(scans: Sequence[str], read: Callable[[str], np.ndarray], *,
         gaps: Sequence[int] = DEFAULT_GAPS, options: options_lib.Options | None = None,
         model=None,
         done: dict[tuple[str, str], MinedPair] | None = None,
         on_pair: Callable[[MinedPair], None] | None = None,
         say: Callable[[str], None] = print, workers: int = 1) -> list[MinedPair]:
  """The candidate pairs of `scans` (paths in capture order) registered and gated.

  Gaps are mined from the smallest up. Each gap starts with a probe, every PROBE_EVERY-th
  of its pairs (MIN_PROBE at least); when under MIN_YIELD of them are confident, that gap
  and every larger one are left (the scans are too far apart there to register, and the
  teacher spends longest on pairs it cannot register). read: path -> [N, 3] points (metres,
  each scan in its sensor's frame); options: the registration (default `teacher_options()`,
  or the register command's defaults with `model`, a learned teacher registered in this
  process); done: pairs registered by an earlier run, by (cloud1, cloud2), not registered
  again (with `model`, those not confident are, once: the widening's model retries what the
  classical teacher could not); on_pair: called with each pair as it is registered (before
  the gate), e.g. to append it to a file; say: told the gap at which mining stopped;
  workers: processes registering chunks of CHUNK consecutive pairs at once (`read` must
  then be picklable, e.g. a module function or a `functools.partial` of one); the pairs and
  their poses do not depend on it. A pair whose file cannot be read is not confident (its
  reason says why); the others go on."""
  if options is None:
    options = teacher_options() if model is None else options_lib.Options()
  done = dict(done or {})
  scans = [str(s) for s in scans]
  out: list[MinedPair] = []
  with contextlib.ExitStack() as stack:
    pool = (stack.enter_context(futures.ProcessPoolExecutor(
        workers, mp_context=multiprocessing.get_context('spawn'), initializer=_end_with,
        initargs=(os.getpid(),))) if workers > 1 and model is None else None)

    tried = set()   # registered by this call

    def run(pairs, gap):
      # A learned teacher retries what an earlier one could not register, once.
      fresh = [p for p in pairs if p not in tried and (
          p not in done or (model is not None and not done[p].confident))]
      tried.update(fresh)
      if pool is None or len(fresh) <= CHUNK:
        stream = (_judged(result, gap) for result in pipeline.register_many(
            fresh, read, model=model, options=options, say=lambda line: None))
      else:   # each worker its own chunks of consecutive pairs (it keeps their clouds)
        stream = (pair for f in futures.as_completed(
            [pool.submit(_registered, fresh[k:k + CHUNK], read, options, gap)
             for k in range(0, len(fresh), CHUNK)]) for pair in f.result())
      for pair in stream:
        done[pair.cloud1, pair.cloud2] = pair
        if on_pair is not None:
          on_pair(pair)
      return [done[p] for p in pairs]

    for gap in sorted(set(gaps)):
      pairs = [(scans[i], scans[j]) for i, j in candidate_pairs(len(scans), [gap])]
      count = min(len(pairs), max(MIN_PROBE, -(-len(pairs) // PROBE_EVERY)))
      probe = run([pairs[k] for k in np.linspace(0, len(pairs) - 1, count).round().astype(int)]
                  if pairs else [], gap)
      if not probe or np.mean([p.confident for p in probe]) < MIN_YIELD:
        out += probe
        say(f'gap {gap}: {sum(p.confident for p in probe)} of {len(probe)} probed pairs '
            f'confident (< {MIN_YIELD:.0%}): gaps from {gap} up left')
        break
      out += run(pairs, gap)
  return apply_gate(out, {s: n for n, s in enumerate(scans)})


def _end_with(parent: int) -> None:
  """A mining worker's start: it ends when `parent` does (a killed command leaves no
  worker registering on)."""
  def watch():
    while os.getppid() == parent:
      time.sleep(1)
    os._exit(1)
  threading.Thread(target=watch, daemon=True).start()


def _registered(pairs: list[tuple[str, str]], read, options: options_lib.Options,
                gap: int) -> list[MinedPair]:
  """The pairs registered in turn (one `register_many`: their clouds kept) and judged."""
  return [_judged(result, gap) for result in
          pipeline.register_many(pairs, read, options=options, say=lambda line: None)]


def mine_to_file(path: str, scans: Sequence[str], read: Callable[[str], np.ndarray], *,
                 gaps: Sequence[int] = DEFAULT_GAPS, model=None,
                 progress: Callable[[], None] | None = None,
                 say: Callable[[str], None] = print, workers: int = 1) -> list[MinedPair]:
  """`mine` into the miner's CSV at `path` (`mined_pairs.PairsFile`): each pair appended as
  it is registered (`progress()` called), a rerun registering only what the file lacks,
  the file rewritten with every pair it holds (earlier rounds' too) gated together.
  -> every pair of the file among `scans`."""
  file = mined_pairs.PairsFile(path)

  def on_pair(pair):
    file.add(pair)
    if progress is not None:
      progress()
  pairs = mine(scans, read, gaps=gaps, model=model, done=file.done, on_pair=on_pair,
               say=say, workers=workers)
  index = {s: n for n, s in enumerate(scans)}
  every, others = [], []   # others: pairs of scans not mined now, kept in the file as found
  for p in {**file.done, **{(p.cloud1, p.cloud2): p for p in pairs}}.values():
    (every if p.cloud1 in index and p.cloud2 in index else others).append(p)
  file.write(apply_gate(every, index) + others)
  return every


def _judged(result: pipeline.PairResult, gap: int) -> MinedPair:
  reg = result.registration
  if reg is None:
    return MinedPair(result.target, result.source, gap, np.eye(4), 0.0, False,
                     reason=f'not registered: {result.error}')
  fitness = float(np.max(reg.verified_fitness)) if reg.verified_fitness is not None else 0.0
  sure = (reg.verified_fitness is not None
          and verification.clearly_confident(reg.verified_poses, reg.verified_fitness,
                                             MIN_FITNESS))
  reason = ('no confident pose' if not sure else
            '' if reg.verdict is None or reg.verdict.registered else reg.verdict.reason)
  return MinedPair(result.target, result.source, gap, reg.transform, fitness,
                   sure and not reason, reason=reason)


def label_errors(pairs: Sequence[MinedPair], poses: np.ndarray, index: dict[str, int]
                 ) -> dict[str, np.ndarray]:
  """Each pair's label against ground truth: poses [P, 4, 4] T_world_sensor of the scans,
  `index` each cloud's row in it. -> {'rte' [n] metres, 'rre' [n] degrees (Euler sum, as
  the paper), 'success' [n] bool (`metrics` thresholds)}."""
  rte, rre = [], []
  for p in pairs:
    truth = geometry.invert_transform(poses[index[p.cloud1]]) @ poses[index[p.cloud2]]
    e = metrics.registration_errors(truth, p.transform)
    rte.append(e['rte'])
    rre.append(e['rre'])
  rte, rre = np.array(rte), np.array(rre)
  return {'rte': rte, 'rre': rre,
          'success': (rte < metrics.MAX_RTE) & (rre < metrics.MAX_RRE)}
