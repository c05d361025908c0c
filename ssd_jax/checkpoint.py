"""Checkpoints through one small wrapper around orbax's `CheckpointManager`.

Each checkpoint holds the train state (params, optimizer and BatchNorm state,
step, PRNG key) and the config as JSON. Orbax writes into a temporary directory
and renames it when complete, so a killed run never leaves a half-written
checkpoint that restore would pick up.
"""

from __future__ import annotations

import os
from typing import Any

import jax
import ml_collections
import orbax.checkpoint as ocp


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

  def restore(self, abstract_state: Any, step: int | None = None) -> tuple[Any, dict]:
    """Restore `step` (default latest) into the structure, shapes, dtypes and
    shardings of `abstract_state` (a pytree of `jax.ShapeDtypeStruct`)."""
    step = self.latest_step() if step is None else step
    if step is None:
      raise FileNotFoundError(f'no checkpoint in {self.directory}')
    restored = self._manager.restore(
        step, args=ocp.args.Composite(state=ocp.args.StandardRestore(abstract_state),
                                      config=ocp.args.JsonRestore()))
    return restored['state'], restored['config']

  def restore_config(self, step: int | None = None) -> dict:
    """The config stored with a checkpoint (default latest), without the state."""
    step = self.latest_step() if step is None else step
    if step is None:
      raise FileNotFoundError(f'no checkpoint in {self.directory}')
    return self._manager.restore(step, args=ocp.args.Composite(config=ocp.args.JsonRestore()))['config']

  def wait_until_finished(self) -> None:
    self._manager.wait_until_finished()

  def close(self) -> None:
    self._manager.close()


def abstract_like(tree: Any) -> Any:
  """Shape/dtype/sharding skeleton of a pytree of arrays, for `Checkpointer.restore`."""
  return jax.tree.map(ocp.utils.to_shape_dtype_struct, tree)
