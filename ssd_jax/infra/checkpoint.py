"""Checkpoints through one small wrapper around orbax's `CheckpointManager`.

Each checkpoint holds the train state (params, optimizer and BatchNorm state,
step, PRNG key) and the config as JSON. Orbax writes into a temporary directory
and renames it when complete, so a killed run never leaves a half-written
checkpoint that restore would pick up.
"""

from __future__ import annotations

import gc
import logging as py_logging
import os
import sys
from typing import Any, Callable

from absl import logging
import jax
import ml_collections
import orbax.checkpoint as ocp

from ssd_jax.infra import distributed, errors, library_text

# Appended to a damaged step folder's name when training moves it aside: orbax reads
# only integer step names, and nothing is deleted.
DAMAGED_SUFFIX = '.damaged'


class CheckpointError(errors.UserError):
  """A checkpoint is missing, damaged (truncated or corrupt files) or unreadable."""


def _drop_failed_reads() -> None:
  """From now on, drop the tracebacks of a failed restore's sibling reads: each array of
  a damaged checkpoint fails alike, and Python would print every one ("Exception
  ignored in coroutine", a hundred lines) whenever they are garbage-collected, even at
  exit; the first failure is reported as a CheckpointError. Anything else still goes to
  the previous hook."""
  previous = sys.unraisablehook
  if getattr(previous, 'drops_failed_reads', False):
    return

  def hook(unraisable):
    if not library_text.is_failed_array_read(unraisable):
      previous(unraisable)

  hook.drops_failed_reads = True
  sys.unraisablehook = hook
  # A future that held such a read's error is logged by asyncio instead when the event
  # loop collects it (which of the two happens depends on timing).
  py_logging.getLogger('asyncio').addFilter(_drop_failed_read_records)


def _drop_failed_read_records(record: py_logging.LogRecord) -> bool:
  error = record.exc_info[1] if record.exc_info else ''
  return not library_text.names_a_failed_array_read(f'{record.getMessage()} {error}')


def _drop_peer_failure_records(record: py_logging.LogRecord) -> bool:
  """False for orbax's traceback of a background save that failed because another process
  of the run is gone: `distributed` ends the run with one line saying so."""
  error = record.exc_info[1] if record.exc_info else None
  return not (error is not None and 'background save thread' in record.getMessage()
              and library_text.names_a_peer_failure(f'{error} {error.__cause__}'))


class Checkpointer:
  """Save every `every` steps, keep the newest `keep`, restore the latest."""

  def __init__(self, directory: str | os.PathLike, every: int = 1000, keep: int = 3,
               asynchronous: bool = True):
    self.every = every
    # The save rule lives in `should_save`; orbax only keeps the newest `keep`.
    options = ocp.CheckpointManagerOptions(
        max_to_keep=keep, create=True, enable_async_checkpointing=asynchronous)
    self._manager = ocp.CheckpointManager(os.path.abspath(directory), options=options,
                                          item_names=('state', 'config'))
    absl_logger = py_logging.getLogger('absl')
    if _drop_peer_failure_records not in absl_logger.filters:
      absl_logger.addFilter(_drop_peer_failure_records)

  @property
  def directory(self) -> str:
    return str(self._manager.directory)

  def latest_step(self) -> int | None:
    return self._manager.latest_step()

  def all_steps(self) -> list[int]:
    """The steps of every checkpoint kept, ascending."""
    return sorted(self._manager.all_steps())

  def should_save(self, step: int) -> bool:
    """Checkpoints are taken at every multiple of `every` steps."""
    return step % self.every == 0

  def save(self, step: int, state: Any, config: ml_collections.ConfigDict,
           force: bool = False) -> bool:
    """Save (asynchronously) if `step` is a save step or `force`; True if saved."""
    if not (force or self.should_save(step)) or step == self.latest_step():
      return False
    return self._manager.save(
        step, args=ocp.args.Composite(state=ocp.args.StandardSave(state),
                                      config=ocp.args.JsonSave(config.to_dict())),
        force=True)

  def _step_path(self, step: int) -> str:
    return os.path.join(self.directory, str(step))

  def _restore(self, step: int | None, **items) -> dict:
    step = self.latest_step() if step is None else step
    if step is None:
      raise FileNotFoundError(f'no checkpoint in {self.directory}')
    if step not in self._manager.all_steps():
      raise FileNotFoundError(f'no checkpoint at step {step} in {self.directory} '
                              f'(kept: {self.all_steps()})')
    # Before the read: a failing array's siblings may be collected while it unwinds.
    _drop_failed_reads()
    try:
      return self._manager.restore(step, args=ocp.args.Composite(**items))
    except Exception as e:  # pylint: disable=broad-except
      # orbax surfaces a damaged file as tensorstore, JSON or plain exceptions.
      reason = library_text.first_line(e)
    gc.collect()
    raise CheckpointError(f'{self._step_path(step)}: damaged checkpoint ({reason})')

  def restore(self, abstract_state: Any | None, step: int | None = None) -> tuple[Any, dict]:
    """Restore `step` (default latest) into the structure, shapes, dtypes and
    shardings of `abstract_state` (a pytree of `jax.ShapeDtypeStruct`), or as stored
    (nested dicts of arrays) when it is None.

    Raises FileNotFoundError when there is no such checkpoint and CheckpointError,
    naming the step's folder, when its files are damaged."""
    restored = self._restore(step, state=ocp.args.StandardRestore(abstract_state),
                             config=ocp.args.JsonRestore())
    return restored['state'], restored['config']

  def restore_config(self, step: int | None = None) -> dict:
    """The config stored with a checkpoint (default latest), without the state."""
    return self._restore(step, config=ocp.args.JsonRestore())['config']

  def restore_latest_intact(self, abstract_state: Any,
                            check_config: Callable[[dict], None] = lambda config: None,
                            ) -> tuple[Any, dict]:
    """Restore the newest checkpoint that reads back whole; each damaged newer one is
    logged in one line and moved aside to `<step>.damaged` (so that training can save
    that step again). Raises CheckpointError when none is intact.

    `check_config(stored_config)` runs before the state is read and may raise: a run
    stored with another model is refused as such, never taken for a damaged one."""
    damaged = []
    for step in reversed(self.all_steps()):
      try:
        config = self.restore_config(step)
        check_config(config)
        state, _ = self.restore(abstract_state, step)
        return state, config
      except CheckpointError as e:
        aside = self._step_path(step) + DAMAGED_SUFFIX
        if distributed.is_main():   # the processes of a run share the folder
          os.replace(self._step_path(step), aside)
        distributed.barrier(f'checkpoint-aside-{step}')
        self._manager.reload()
        logging.warning('%s; moved it to %s and fell back to the checkpoint before it',
                        e, aside)
        damaged.append(aside)
    raise CheckpointError(f'{self.directory}: no intact checkpoint (damaged, moved aside: '
                          f'{", ".join(damaged)}); start a new --workdir or remove them')

  def wait_until_finished(self) -> None:
    self._manager.wait_until_finished()

  def close(self) -> None:
    self._manager.close()


def abstract_like(tree: Any) -> Any:
  """Shape/dtype/sharding skeleton of a pytree of arrays, for `Checkpointer.restore`."""
  return jax.tree.map(ocp.utils.to_shape_dtype_struct, tree)
