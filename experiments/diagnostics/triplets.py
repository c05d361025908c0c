r"""What a triplet-trained checkpoint learned, and what its triplets offer at all.

    python -m experiments.diagnostics.triplets --config=configs/experiments/feat3dnet_small.py:pretrain \
        --workdir=runs/feat3dnet_small_pretrain

On the trainer's fixed probe triplets (see `objective.probe_triplets`), prints a Markdown
table: the untrained network and the checkpoint with the clouds as stored and with
every cloud turned by its own random angle (Rotate1D), and FPFH (rotation invariant)
as the reference point. For a model with a detector it also prints how well the
predicted orientation turns with the cloud (`evaluation.orientation`). `--config` is
the run's training config. Last, how fast the checkpoint's gain fades as the clouds
turn: its probe with each cloud turned by its own angle within ±10°, ±20°, ... ±180°.
"""

from absl import app
from absl import flags
import jax
import numpy as np

from ssd_jax import inference, objective, pretrained, train
from ssd_jax.infra import cli
from ssd_jax.config_tools import checks
from ssd_jax.evaluation import orientation, triplets
from ssd_jax.infra.logging_utils import quiet_libraries

FLAGS = flags.FLAGS
flags.DEFINE_string('workdir', None, 'The triplet-trained model: its training workdir, an '
                    'export folder or a shipped name (feat3dnet).')
flags.DEFINE_bool('fpfh', True, 'Also measure FPFH on the probe triplets (~1 s per triplet).')
cli.define_config_file('config', None, 'The run\'s training config.')
flags.mark_flags_as_required(['workdir', 'config'])

STORED = ('jitter', 'rotate_small', 'shift')
ROTATED = STORED + ('rotate_1d',)
TURNS = np.radians([45.0, 90.0, 135.0, 180.0])
TURN_RANGES_DEG = (0, 10, 20, 45, 90, 180)


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  config = FLAGS.config
  checks.check_config(config)
  probe = objective.probe_triplets(train.triplet_dataset(config), config)
  trained = pretrained.load(FLAGS.workdir)
  fresh = jax.device_get(train.create_train_state(config, jax.random.key(config.seed)))
  untrained = inference.Model.from_config(
      config, {'params': fresh.params, 'batch_stats': fresh.batch_stats})
  if jax.tree.structure(trained.variables) != jax.tree.structure(untrained.variables):
    raise ValueError(f'{FLAGS.workdir} holds a different network than --config describes '
                     '(model.use_orientation, model.descriptor_dim); pass its training config')
  models = (('untrained', untrained), (f'{FLAGS.workdir} (step {trained.step})', trained))
  rows = []
  for name, model in models:
    for clouds, augs in (('as stored', STORED), ('each turned at random (Rotate1D)', ROTATED)):
      rows.append((name, clouds, triplets.checkpoint_probe(model, config, probe, augs)))
  if FLAGS.fpfh:
    rows.append(('FPFH (rotation invariant)', 'any',
                 triplets.fpfh_probe(probe, config.model.num_clusters, config.seed,
                                     config.model.margin,
                                     hinge=config.model.triplet_hinge)))
  print(f'{len(probe)} probe triplets of {config.data.path}, {config.data.num_points} points, '
        f'{config.model.num_clusters} clusters per cloud\n')
  print('| descriptor | clouds | triplet loss | accuracy (d_pos < d_neg) |\n|---|---|---|---|')
  for name, clouds, m in rows:
    print(f"| {name} | {clouds} | {m['loss']:.4f} | {m['triplet_accuracy']:.3f} |")
  if config.model.use_orientation:
    anchors = probe[:, 0]
    rng = np.random.default_rng(config.seed)
    centers = [a[rng.choice(len(a), config.model.num_clusters, replace=False)] for a in anchors]
    print(f'\nOrientation after turning each anchor cloud by {np.degrees(TURNS).astype(int)} deg '
          f'({len(anchors)} clouds x {config.model.num_clusters} clusters). Error 0: the '
          'orientation turns with the cloud; error = the turn (median 112.5 deg): it ignores '
          'the turn; median 90 deg: unrelated\n')
    print('| detector | median error (deg) | share within 15 deg |\n|---|---|---|')
    for name, model in models:
      errors = np.concatenate([orientation.orientation_errors(model, a, c, TURNS)
                               for a, c in zip(anchors, centers)], axis=1)
      o = orientation.summarize(errors)
      print(f"| {name} | {o['median_deg']:.1f} | {o['within']:.3f} |")
  name, checkpoint = models[1]
  print(f'\n{name} with each cloud turned by its own uniform angle within the range '
        '(±180°: Rotate1D)\n')
  print('| turns within | triplet loss | accuracy |\n|---|---|---|')
  for deg in TURN_RANGES_DEG:
    turned = triplets.turn_clouds(probe, np.radians(deg), config.seed)
    m = triplets.checkpoint_probe(checkpoint, config, turned, STORED)
    print(f"| ±{deg}° | {m['loss']:.4f} | {m['triplet_accuracy']:.3f} |")


if __name__ == '__main__':
  cli.run(main)
