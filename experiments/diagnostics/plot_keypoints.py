r"""Paper Fig. 3: ISS and learned keypoints as red dots on the same cloud, top view.

    python -m experiments.diagnostics.plot_keypoints --cloud=A.bin --out=keypoints.png \
        [--sources=iss,learned --checkpoint=runs/feat3dnet_small_varied]

`learned` keypoints are the checkpoint's detector (attention + NMS, docs/method.md §4);
it needs a checkpoint whose attention head was trained (the weakly supervised
3DFeat-Net baseline). Prints how many keypoints each source found.
"""

from absl import app
from absl import flags

from ssd_jax import pretrained, viz
from ssd_jax.infra import cli
from ssd_jax.data import clean, io
from ssd_jax.infra.logging_utils import quiet_libraries
from ssd_jax.registration import cloud_features
from ssd_jax.registration import options as options_lib

FLAGS = flags.FLAGS
flags.DEFINE_string('cloud', None, 'Cloud file (.bin, .npy, .ply, .pcd).')
flags.DEFINE_string('out', None, 'PNG to write.')
flags.DEFINE_list('sources', ['iss'], 'Keypoint sources: iss, learned, random.')
flags.DEFINE_string('checkpoint', None, 'Shipped model name (ours_detector), export folder or '
                    'training workdir for learned keypoints.')
flags.mark_flags_as_required(['cloud', 'out'])


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  bad = [s for s in FLAGS.sources if s not in options_lib.KEYPOINTS]
  if bad:
    raise SystemExit(f'error: unknown keypoint source(s) {bad}; choose from '
                     f'{options_lib.KEYPOINTS}')
  if 'learned' in FLAGS.sources and not FLAGS.checkpoint:
    raise SystemExit('error: learned keypoints need --checkpoint')
  points = clean.clean_cloud(io.read_cloud(FLAGS.cloud), FLAGS.cloud)
  model = None
  if FLAGS.checkpoint:
    model = pretrained.load(FLAGS.checkpoint)
  shown = {}
  for source in FLAGS.sources:
    idx, _ = cloud_features.compute_keypoints(points, source, model)
    shown[f'{source} keypoints'] = points[idx]
    print(f'{source}: {len(idx)} keypoints')
  viz.plot_keypoints(points, shown, FLAGS.out)
  print(f'wrote {FLAGS.out}')


if __name__ == '__main__':
  cli.run(main)
