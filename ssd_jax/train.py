"""Self-supervised training: `create_train_state`, `train_step`, `train_and_evaluate`.

The whole step - self-rotation, jitter, center sampling, grouping, both network
branches, CF, loss, Adam update and BatchNorm statistics - is one `jax.jit`
with the train state donated. The batch is sharded over every device of the run
along its first axis (data parallel; with several processes each builds only its
own rows, `distributed`), and the state is replicated.
"""

from __future__ import annotations

import json
import os
import time
from typing import Any, Callable

from absl import logging
import flax
import jax
import jax.numpy as jnp
import ml_collections
import numpy as np
import optax
from tqdm import auto as tqdm

from ssd_jax import network, objective, pretrained
from ssd_jax.infra import checkpoint, distributed, errors
from ssd_jax.config_tools import checks
from ssd_jax.config_tools.checks import ConfigError
from ssd_jax.data import datasets, io, mined_pairs


class TrainingDiverged(errors.UserError, FloatingPointError):
  """The loss or the gradient became NaN/Inf (a setting to change: one line, as bad input)."""


@flax.struct.dataclass
class TrainState:
  """Everything a run needs to continue, and nothing static.

  Pure data (no optimizer or apply function inside), so every state - fresh,
  restored or returned by the step - has the same pytree structure and the
  jitted step never retraces.
  """
  step: jax.Array         # int32 []
  params: Any
  batch_stats: Any        # BatchNorm running statistics
  opt_state: Any          # Adam moments
  rng: jax.Array          # raw uint32 key data, so orbax can store it


def create_model(config: ml_collections.ConfigDict) -> network.FeatureNet:
  return network.create(config.model)


def create_optimizer(config: ml_collections.ConfigDict) -> optax.GradientTransformation:
  """Adam at train.learning_rate, constant (the paper) or cosine-decayed to 0 at
  train.num_steps (`train.lr_schedule`)."""
  t = config.train
  if t.lr_schedule == 'cosine':
    # At a constant rate and batch 2 the weights keep wandering: registration success moved
    # by 2-4 points between checkpoints 1,000 steps apart. Decayed, the last one settles.
    return optax.adam(optax.cosine_decay_schedule(t.learning_rate, t.num_steps))
  return optax.adam(t.learning_rate)


def create_train_state(config: ml_collections.ConfigDict, key: jax.Array) -> TrainState:
  """Randomly initialised state; `key` from `jax.random.key(seed)`."""
  init_key, train_key = jax.random.split(key)
  model = create_model(config)
  dummy = jnp.zeros((1, config.model.num_clusters, config.model.num_samples, 3), jnp.float32)
  variables = jax.jit(lambda k: model.init(k, dummy, train=False))(init_key)
  params = variables['params']
  return TrainState(step=jnp.zeros((), jnp.int32), params=params,
                    batch_stats=variables['batch_stats'],
                    opt_state=create_optimizer(config).init(params),
                    rng=jax.random.key_data(train_key))


def train_step(state: TrainState, points: jax.Array, *, model: network.FeatureNet,
               config: ml_collections.ConfigDict) -> tuple[TrainState, dict[str, jax.Array]]:
  """One Adam step of `config.objective`: self-supervised on clouds [B, N, 3] metres,
  or triplet on [B, 3, N, 3] (anchor, positive, negative).

  A non-finite loss or gradient leaves params, optimizer and BatchNorm state
  untouched (the step counter still advances) and reports `finite = False`.
  """
  key = jax.random.fold_in(jax.random.wrap_key_data(state.rng), state.step)
  valid = jnp.ones(points.shape[:-1], bool)
  loss_of = objective.OBJECTIVES[config.objective]

  def loss_fn(params):
    variables = {'params': params, 'batch_stats': state.batch_stats}
    return loss_of(model, variables, key, points, valid, config.model)

  (loss, (metrics, batch_stats)), grads = jax.value_and_grad(loss_fn, has_aux=True)(state.params)
  grad_norm = optax.tree.norm(grads)
  finite = jnp.isfinite(loss) & jnp.isfinite(grad_norm)
  updates, opt_state = create_optimizer(config).update(grads, state.opt_state, state.params)
  params = optax.apply_updates(state.params, updates)
  keep = lambda new, old: jax.tree.map(lambda a, b: jnp.where(finite, a, b), new, old)
  new_state = state.replace(step=state.step + 1, params=keep(params, state.params),
                            opt_state=keep(opt_state, state.opt_state),
                            batch_stats=keep(batch_stats, state.batch_stats))
  return new_state, {**metrics, 'grad_norm': grad_norm, 'finite': finite}


def eval_step(state: TrainState, points: jax.Array, key: jax.Array, *, model: network.FeatureNet,
              config: ml_collections.ConfigDict,
              objective_name: str = 'self_supervised') -> dict[str, jax.Array]:
  """Metrics of `objective_name` with running BatchNorm statistics: the loss and CF
  rotation error of held-out clouds [B, N, 3], or the triplet loss of fixed triplets
  [B, 3, N, 3]."""
  variables = {'params': state.params, 'batch_stats': state.batch_stats}
  valid = jnp.ones(points.shape[:-1], bool)
  _, (metrics, _) = objective.OBJECTIVES[objective_name](model, variables, key, points, valid,
                                                         config.model, train=False)
  return metrics


def probe_step(state: TrainState, triplets: jax.Array, key: jax.Array, *,
               model: network.FeatureNet, config: ml_collections.ConfigDict) -> dict[str, jax.Array]:
  """`objective.triplet_probe` of fixed triplets [M * B, 3, N, 3] with the state's
  weights and running BatchNorm statistics (B the training batch size)."""
  variables = {'params': state.params, 'batch_stats': state.batch_stats}
  return objective.triplet_probe(model, variables, key, triplets, config.model,
                                 config.train.batch_size)


def make_mesh(devices=None) -> jax.sharding.Mesh:
  """A 1-D data-parallel mesh over `devices` (default: every device of every process)."""
  devices = jax.devices() if devices is None else devices
  return jax.sharding.Mesh(np.asarray(devices), ('data',))


def jit_train_step(config: ml_collections.ConfigDict, mesh: jax.sharding.Mesh) -> Callable:
  """`train_step` jitted for `mesh`: (state, points [B, N, 3]) -> (state, metrics).

  The state is donated and replicated; points are split over the mesh's
  'data' axis.
  """
  replicated = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec())
  batch = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec('data'))
  step = lambda state, points: train_step(state, points, model=create_model(config),
                                          config=config)
  return jax.jit(step, in_shardings=(replicated, batch), out_shardings=replicated,
                 donate_argnums=0)


def replicate(tree: Any, mesh: jax.sharding.Mesh) -> Any:
  """A copy of `tree` (the same values in every process) on every device of `mesh`."""
  sharding = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec())
  return jax.tree.map(lambda x: jax.make_array_from_process_local_data(sharding, np.asarray(x)),
                      jax.device_get(tree))


def shard_batch(local_points: np.ndarray, mesh: jax.sharding.Mesh,
                global_batch: int) -> jax.Array:
  """This process's rows `distributed.local_rows(global_batch)` of a batch -> the global
  batch [global_batch, ...] split over the mesh's 'data' axis."""
  sharding = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec('data'))
  return jax.make_array_from_process_local_data(sharding, local_points,
                                                (global_batch, *local_points.shape[1:]))


class MetricsWriter:
  """Appends one JSON object per logged step to `metrics.jsonl`.

  On resume, lines logged after the restored step (by a run that was killed
  before its next checkpoint) are dropped, so the file reads like one
  uninterrupted run. A fresh start (`resume_step` 0) drops them all: its step-0
  line is written again. Inactive (every process but the first of a run), it
  writes nothing.
  """

  def __init__(self, path: str, resume_step: int, active: bool = True):
    self.path, self.active = path, active
    if active and os.path.exists(path):
      with open(path) as f:
        kept = [line for line in f if line.strip() and 0 < resume_step
                and json.loads(line)['step'] <= resume_step]
      with open(path, 'w') as f:
        f.writelines(kept)

  def write(self, record: dict[str, Any]) -> None:
    if not self.active:
      return
    with open(self.path, 'a') as f:
      f.write(json.dumps(record) + '\n')


def _mean_metrics(host_metrics: list[dict[str, Any]]) -> dict[str, float]:
  """Mean of each metric over the logging window (metrics already on the host)."""
  return {k: float(np.mean([m[k] for m in host_metrics]))
          for k in host_metrics[0] if k != 'finite'}


def _check_finite(pending: list[tuple[int, dict]], ckpt: checkpoint.Checkpointer) -> None:
  for step, m in pending:
    if not bool(m['finite']):
      last = ckpt.latest_step()
      raise TrainingDiverged(
          f'non-finite loss or gradient at step {step} (loss={float(m["loss"])}, '
          f'grad_norm={float(m["grad_norm"])}); that update was skipped and training stopped. '
          f'Last good checkpoint: '
          + (f'step {last} in {ckpt.directory}' if last is not None else 'none yet'))


# Model keys added after runs were written, with the value those runs used.
INIT_SCOPES = ('descriptor', 'model')


def initialize_from(state: TrainState, source: str,
                    config: ml_collections.ConfigDict) -> TrainState:
  """`state` (fresh) with weights and BatchNorm statistics of `source` (a shipped name, an
  export folder or a training run), the optimizer started anew.

  `config.train.init_scope` says which: 'descriptor' is 3DFeat-Net's stage hand-over (the
  detector keeps its fresh initialisation); 'model' copies every weight, to fine-tune a
  trained model (e.g. the shipped `ours` on a user's own sensor)."""
  scope = config.train.init_scope
  try:
    src = pretrained.load(source).variables
  except (FileNotFoundError, ValueError) as e:
    raise ConfigError(f'train.init_from: {e}') from None
  parts = ['descriptor'] if scope == 'descriptor' else list(state.params)
  for part in parts:
    mine, theirs = state.params.get(part), src['params'].get(part)
    if theirs is None or jax.tree.structure(mine) != jax.tree.structure(theirs) or any(
        a.shape != b.shape for a, b in zip(jax.tree.leaves(theirs), jax.tree.leaves(mine))):
      raise ConfigError(f'train.init_from: {source} has a different {part} network (the '
                        'model settings, e.g. model.descriptor_dim or model.orientation_head, '
                        'must match)')
  params = {**state.params, **{p: src['params'][p] for p in parts}}
  batch_stats = {**state.batch_stats,
                 **{p: src['batch_stats'][p] for p in parts if p in src['batch_stats']}}
  return state.replace(params=params, batch_stats=batch_stats,
                       opt_state=create_optimizer(config).init(params))


def triplet_dataset(config: ml_collections.ConfigDict) -> datasets.TripletDataset:
  """The triplets of `config.data`."""
  return datasets.TripletDataset(config.data.path, axes=config.data.triplet_axes,
                                 positives=config.data.triplet_positives,
                                 fmt=config.data.format, crop_radius=config.data.crop_radius,
                                 min_points=config.data.min_points)


def train_and_evaluate(config: ml_collections.ConfigDict, workdir: str,
                       until: int | None = None) -> TrainState:
  """Train (or resume) `config` in `workdir` up to step `until` (default, and at most,
  `train.num_steps`: the schedules keep their length); returns the final state.

  Writes `workdir/metrics.jsonl` and `workdir/checkpoints/`. Rerunning with the
  same workdir resumes from the latest checkpoint and continues the identical
  run (same batches, same PRNG stream).
  """
  checks.check_config(config)
  if not config.data.path:
    raise ConfigError('data.path is empty: point it at a directory of clouds, an Oxford '
                      'train.txt or a cloud file (--config.data.path=...)')
  try:
    os.makedirs(workdir, exist_ok=True)
  except OSError as e:
    raise ConfigError(f'--workdir {workdir}: cannot create it as a folder ({e.strerror})') from None
  t_cfg = config.train
  data_kwargs = dict(fmt=config.data.format, crop_radius=config.data.crop_radius,
                     min_points=config.data.min_points)
  if config.objective == 'triplet':
    dataset = triplet_dataset(config)
  elif config.data.pairs:
    dataset = datasets.MinedPairDataset(
        io.list_clouds(config.data.path),
        mined_pairs.chained(mined_pairs.read_kept(config.data.pairs), config.data.pairs_links),
        rate=config.data.pairs_rate, weight=config.data.pairs_weight, **data_kwargs)
  elif config.data.rescan_rate > 0:
    d = config.data
    dataset = datasets.RescanPairDataset.from_source(
        d.path, rate=d.rescan_rate, sensors=tuple(d.rescan_sensors),
        min_shift=d.rescan_shift[0], max_shift=d.rescan_shift[1], views_per_cloud=d.rescan_views,
        beams=d.rescan_beams, seed=config.seed, **data_kwargs)
  else:
    dataset = datasets.CloudDataset.from_source(config.data.path, **data_kwargs)
  eval_points = None
  if config.data.eval_path:
    eval_set = datasets.CloudDataset.from_source(config.data.eval_path, **data_kwargs)
    eval_points = eval_set.batch(config.seed + 1, 0, t_cfg.batch_size, config.data.num_points)

  mesh = make_mesh()
  ckpt = checkpoint.Checkpointer(os.path.join(workdir, 'checkpoints'), t_cfg.checkpoint_every,
                                 t_cfg.keep_checkpoints)
  state = replicate(create_train_state(config, jax.random.key(config.seed)), mesh)
  if ckpt.latest_step() is not None:
    state, _ = ckpt.restore_latest_intact(
        checkpoint.abstract_like(state),
        lambda stored: checks.check_resumable(config, stored, ckpt.directory))
    logging.info('Resumed from step %d in %s', int(state.step), ckpt.directory)
  elif t_cfg.get('init_from'):
    state = replicate(initialize_from(jax.device_get(state), t_cfg.init_from, config), mesh)
    logging.info('%s initialised from %s', t_cfg.init_scope, t_cfg.init_from)
  start = int(state.step)
  until = t_cfg.num_steps if until is None else min(until, t_cfg.num_steps)
  writer = MetricsWriter(os.path.join(workdir, 'metrics.jsonl'), start, distributed.is_main())
  step_fn = jit_train_step(config, mesh)
  # The evaluation key is made inside the jitted function: with several processes an
  # argument would have to be a global array.
  eval_fn = jax.jit(lambda s, p: eval_step(s, p, jax.random.key(config.seed + 2),
                                           model=create_model(config), config=config))
  # The triplet loss of a random batch is too noisy to read a trend from; the same
  # triplets, augmentations and centers at every evaluation are not.
  probe_points, probe_fn = None, None
  if config.objective == 'triplet':
    probe_points = objective.probe_triplets(dataset, config)
    probe_fn = jax.jit(lambda s, p: probe_step(s, p, jax.random.key(config.seed + 2),
                                               model=create_model(config), config=config))

  def evaluate(state) -> dict[str, float]:
    record = {}
    for prefix, fn, pts in (('eval', eval_fn, eval_points), ('probe', probe_fn, probe_points)):
      if pts is not None:
        ev = jax.device_get(fn(state, replicate(pts, mesh)))
        record.update({f'{prefix}_{k}': float(v) for k, v in ev.items()})
    return record

  if start == 0 and (eval_points is not None or probe_points is not None):
    writer.write({'step': 0, **evaluate(state)})   # the untrained baseline of each curve

  rows = distributed.local_rows(t_cfg.batch_size)
  make_batch = lambda step: dataset.batch(config.seed, step, t_cfg.batch_size,
                                          config.data.num_points, rows)
  batches = datasets.prefetch(make_batch, range(start, until), config.data.prefetch)
  bar = tqdm.tqdm(total=until, initial=start, desc='train', unit='step',
                  dynamic_ncols=True, disable=not (config.progress_bar and distributed.is_main()))
  pending: list[tuple[int, dict]] = []
  t_last, steps_since = time.perf_counter(), 0
  try:
    for step, points in zip(range(start, until), batches):
      state, metrics = step_fn(state, shard_batch(points, mesh, t_cfg.batch_size))
      pending.append((step + 1, metrics))
      steps_since += 1
      bar.update(1)
      done = step + 1 == until
      if (step + 1) % t_cfg.log_every == 0 or done or ckpt.should_save(step + 1):
        pending = jax.device_get(pending)  # the only host transfer: at logging steps
        _check_finite(pending, ckpt)
        if (step + 1) % t_cfg.log_every == 0 or done:
          now = time.perf_counter()
          record = {'step': step + 1, **_mean_metrics([m for _, m in pending]),
                    'steps_per_sec': steps_since / (now - t_last)}
          if (step + 1) % t_cfg.eval_every == 0 or done:
            record.update(evaluate(state))
          writer.write(record)
          shown = {'loss': f"{record['loss']:.4f}"}
          if 'rotation_error_deg' in record:
            shown['rot_err'] = f"{record['rotation_error_deg']:.2f}deg"
          if 'triplet_accuracy' in record:
            shown['acc'] = f"{record['triplet_accuracy']:.3f}"
          bar.set_postfix(**shown, sps=f"{record['steps_per_sec']:.2f}")
          t_last, steps_since, pending = time.perf_counter(), 0, []
        ckpt.save(step + 1, state, config, force=done)
  finally:
    bar.close()
    ckpt.wait_until_finished()
  ckpt.close()
  return state
