"""The 3DFeat-Net baseline's CPU run on turn-distinctive training streets, 4 m clusters.

Commands (after `experiments.data.make_synthetic --config=configs/experiments/synthetic_small_varied.py
--out=data_cache/synthetic_small_varied`):

    python -m experiments.train --config=configs/experiments/feat3dnet_small_varied.py:pretrain \
        --workdir=runs/feat3dnet_small_varied_pretrain
    python -m experiments.train --config=configs/experiments/feat3dnet_small_varied.py \
        --workdir=runs/feat3dnet_small_varied

configs/experiments/feat3dnet_small.py with two changes: the training split of
configs/experiments/synthetic_small_varied.py, and a 4 m cluster radius on both stages. Under
Rotate1D, stage 2 of configs/experiments/feat3dnet_small.py stays at chance; each change alone moves
it little, and together they lower its loss (docs/notes/feat3dnet_baseline.md). Held-out
evaluation stays on `synthetic_small`'s test models.

Expected (2-core VM), `probe_loss` in metrics.jsonl (chance
0.19-0.20), accuracy in brackets. Stage 1 (600 steps, ~2 min): seed 0 0.190 (0.63) ->
0.093 (0.71); seed 1 0.192 (0.60) -> 0.112 (0.69). Stage 2 (3,000 steps, ~14 min,
Rotate1D on), step 0 -> probes at 500, 1,000, ... 3,000: seed 0 0.173 (0.56) -> 0.166,
0.140, 0.145, 0.151, 0.127, 0.141 (0.59); seed 1 0.177 (0.56) -> 0.172, 0.165, 0.170,
0.169, 0.175, 0.163 (0.58). The training loss, averaged over the first and the last 500
steps: seed 0 0.155 -> 0.141, seed 1 0.167 -> 0.149 (`--config.seed=1`).
"""

from ssd_jax.configs.experiments import feat3dnet_small as small


def get_config(stage: str = 'full'):
  config = small.get_config(stage)
  config.data.path = 'data_cache/synthetic_small_varied/train'
  config.model.radius = 4.0
  if stage != 'pretrain':
    config.train.init_from = 'runs/feat3dnet_small_varied_pretrain'
  return config
