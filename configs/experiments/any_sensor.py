"""The shipped `ours` fine-tuned, without labels, with branches that look like other sensors
(an experiment; not shipped).

Command (the synthetic set comes first):

    python -m experiments.train --config=configs/experiments/any_sensor.py --workdir=runs/any_sensor

`configs/experiments/finetune.py` (`ours` fine-tuned at a third of its learning rate for 3,000 steps),
with two branches that differ the way two sensors differ: with chance 1/2 a branch keeps only the rings of a sparser spinning
unit (virtual beams 0.7-2.5 degrees apart: an HDL-32E is 1.33, a VLP-16 2), with chance
1/4 only a horizontal sector of 90-180 degrees (a front-facing or solid-state unit), and
the branch crops stand up to 8 m apart instead of 4 m. Everything else, the loss
included, is the paper's self-supervision: no poses, no labels.
docs/notes/cross_sensor.md has the measurement on the cross-sensor test sets.
"""

from ssd_jax.configs.experiments import finetune


def get_config():
  config = finetune.get_config()
  config.model.branch_sensor_rate = 0.5
  config.model.branch_beam_spacing = (0.7, 2.5)
  config.model.branch_fov_rate = 0.25
  config.model.branch_fov = (90.0, 180.0)
  config.model.branch_crop_shift = 8.0
  return config
