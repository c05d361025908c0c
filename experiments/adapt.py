r"""Adapt a trained descriptor to your own sensor without labels: mine pairs of your scans,
fine-tune on them, then export the model with a model card.

    python -m experiments.adapt --scans=/data/my_drive --out=exports/my_sensor \
        [--pairs=auto|none|MINED.csv] [--keypoints=auto|all|structure] [--init=ours] \
        [--steps=1500] [--config=configs/training/adapt.py]
    python -m experiments.register --cloud1=A.bin --cloud2=B.bin --descriptor=learned \
        --checkpoint=exports/my_sensor

The scans (.bin/.npy/.ply/.pcd/.las/.laz/.xyz/.pts/.vtk, one sweep each, centred on the
sensor, z up) are read in name order as a drive. `--pairs=auto` first mines pairs of them
into OUT/mined_pairs.csv (`experiments.mine`: the classical registration, kept where the
verdict trusts its poses and they close loops; no pose is read), trains on them, widens
as EYOC does (the model trained so far mines farther gaps, then training goes on with
every kept pair) and, with `--keypoints=auto`, keeps the keypoint domain its descriptor
alone registers more mined pairs from (`adaptation.keypoint_choice`). The recipe and its
expected result: configs/training/adapt.py. Without pairs (scans not in capture order,
`--pairs=none`) it trains the paper's single-scan objective alone. OUT/run holds the
training run (rerun the command to resume it, mining too); OUT holds the exported model
(config.json, weights.msgpack) and MODEL_CARD.md (base model, scans, pairs, steps,
keypoints, wall time, machine, command). docs/notes/speed.md times it on 2 CPU cores.
"""

import datetime
import functools
import os
import platform
import sys
import time

from absl import app
from absl import flags
from tqdm import auto as tqdm

from ssd_jax import pretrained, train
from ssd_jax.infra import cli
from ssd_jax.data import clean, io, mined_pairs
from ssd_jax.infra.logging_utils import quiet_libraries
from ssd_jax.adaptation import keypoint_choice, mining

FLAGS = flags.FLAGS
flags.DEFINE_string('scans', None, 'Folder (or index .txt) of unlabeled scans of the sensor.')
flags.DEFINE_string('out', None, 'Output folder: the exported model, its card, and run/.')
flags.DEFINE_string('init', pretrained.DEFAULT, 'Model to start from: a shipped name, export '
                    'or run.')
flags.DEFINE_integer('steps', None, 'Training steps (default: the config\'s).')
flags.DEFINE_string('pairs', 'auto', 'auto: mine pairs of the scans first (OUT/mined_pairs.csv); '
                    "none: the paper's single-scan objective alone; or a miner's CSV.")
flags.DEFINE_enum('keypoints', 'auto', ('auto', 'all', 'structure'),
                  "auto: sample the exported model's keypoints from the domain that registers "
                  "more of the chained mined pairs past the miner's gaps "
                  "(registration.keypoint_choice); or that domain ('all' points, or the "
                  "'structure' above the ground).")
cli.define_config_file('config', 'configs/training/adapt.py', 'Adaptation config.')
flags.mark_flags_as_required(['scans', 'out'])

CARD = """# {name}: `{init}` adapted to the scans of {scans}

Fine-tuned without labels from `{init}`, every weight, on {num_scans} unlabeled scans:
{objective}

| | |
|---|---|
| base model | `{init}` |
| scans | `{scans}` ({num_scans} files) |
| mined pairs | {pairs} |
| config | `configs/training/adapt.py` ({steps} steps, learning rate {lr:g}, {schedule}) |
| keypoints | {keypoints} |
| wall time | {minutes:.1f} minutes |
| machine | {machine} |
| written | {date} |

Command:

    {command}

Use it: `--checkpoint={out}` (register, evaluate, learning_curve) or
`pretrained.load('{out}')`.
"""


SINGLE_OBJECTIVE = ("the paper's self-supervision, each scan against a turned, re-sampled "
                    'copy of itself.')
# The scans as every step of the command reads them (picklable: mining's workers take it).
_READ = functools.partial(clean.read_metres, fmt='auto')
PAIRS_OBJECTIVE = ("the paper's self-supervision with {rate:.0%} of the second branches a real "
                   'second scan of the place, moved into the first by the transform the '
                   'miner found (two-view training); the rest a turned copy of the scan.')


def _mine(path: str, scans: list[str], gaps: tuple[int, ...], model=None, desc='mining pairs'
          ) -> list[mined_pairs.MinedPair]:
  """Every pair of the miner's CSV at `path` after mining `gaps` of `scans` into it (with
  the classical teacher, or `model`)."""
  with tqdm.tqdm(total=len(mining.candidate_pairs(len(scans), gaps)), desc=desc,
                 unit='pair') as bar:
    pairs = mining.mine_to_file(path, scans, _READ, gaps=gaps, model=model,
                                progress=bar.update, say=bar.write,
                                workers=mining.DEFAULT_WORKERS)
    bar.total = bar.n   # the total counted every gap; mining stops at the first that fails
    bar.refresh()
  return pairs


def _pairs(scans: list[str]) -> str:
  """The miner's CSV to train on ('' for none), mined first with `--pairs=auto`."""
  if FLAGS.pairs != 'auto':
    return '' if FLAGS.pairs == 'none' else FLAGS.pairs
  os.makedirs(FLAGS.out, exist_ok=True)
  path = os.path.join(FLAGS.out, 'mined_pairs.csv')
  pairs = _mine(path, scans, mining.DEFAULT_GAPS)
  if not any(p.kept for p in pairs):
    print(f'no pair of {FLAGS.scans} passed the miner\'s gate (are the scans in capture '
          "order?): training the paper's single-scan objective alone")
    return ''
  return path


def _train(config, run_dir: str, scans: list[str]) -> list[tuple[int, ...]]:
  """Trains `config` in `run_dir`; with pairs mined here (`--pairs=auto`), the model
  trained so far widens them between its rounds. -> the gaps each round mined."""
  widening = FLAGS.pairs == 'auto' and bool(config.data.pairs)
  gaps = [mining.DEFAULT_GAPS] if widening else []
  rounds = config.mining.widen_rounds + 1 if widening else 1
  for r in range(1, rounds):
    train.train_and_evaluate(config, run_dir, until=config.train.num_steps * r // rounds)
    wider = mining.widened_gaps([p for p in mined_pairs.PairsFile(config.data.pairs).done
                                 .values() if p.gap <= max(gaps[-1])])
    if not wider:
      break
    gaps.append(wider)
    _mine(config.data.pairs, scans, wider, pretrained.load(run_dir),
          f'widening: gaps {", ".join(map(str, wider))}')
  train.train_and_evaluate(config, run_dir)
  return gaps


def _pairs_line(path: str, gaps: list[tuple[int, ...]]) -> str:
  """The model card's line about the mined pairs trained on."""
  if not path:
    return 'none (`--pairs=none`)' if FLAGS.pairs == 'none' else 'none passed the gate'
  kept = mined_pairs.read_kept(path)
  rounds = '; '.join(f'{"classical teacher" if r == 0 else f"widening {r}, the model"}, '
                     f'gaps {",".join(map(str, g))}: {sum(p.gap in g for p in kept)}'
                     for r, g in enumerate(gaps))
  return f'{len(kept)} (`{path}`)' + (f' ({rounds})' if rounds else '')


def _keypoints(run_dir: str, pairs_csv: str) -> tuple[str, str]:
  """The exported model's keypoint domain (`inference.KEYPOINT_SELECTIONS`) and the model
  card's line about it: `--keypoints`, or with 'auto' the one that registers more of the
  chained mined pairs beyond the miner's gaps ('all' without them)."""
  if FLAGS.keypoints != 'auto':
    return FLAGS.keypoints, f"'{FLAGS.keypoints}' points (`--keypoints`)"
  if not pairs_csv:
    return 'all', "'all' points (no mined pairs to choose on)"
  print('choosing where to sample keypoints, on mined pairs farther apart than the miner '
        'reached ...')
  choice = keypoint_choice.choose(pretrained.load(run_dir), mined_pairs.read_kept(pairs_csv), _READ)
  if choice is None:
    return 'all', "'all' points (no chain of mined pairs to choose on)"
  print(choice.line())
  return choice.keypoints, choice.line()


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  config = FLAGS.config
  config.data.path, config.train.init_from = FLAGS.scans, FLAGS.init
  if FLAGS.steps is not None:
    config.train.num_steps = FLAGS.steps
  run_dir = os.path.join(FLAGS.out, 'run')
  if config.mining.widen_rounds < 0:
    raise SystemExit(f'error: --config.mining.widen_rounds must be 0 or more, got '
                     f'{config.mining.widen_rounds}')
  try:
    scans = [str(p) for p in io.list_clouds(FLAGS.scans)]
    num_scans = len(scans)
    stride = (mining.stride_for(scans, _READ, config.mining.max_scans)
              if FLAGS.pairs == 'auto' else None)
    mined = mining.spread(scans, config.mining.max_scans, stride)
    start = time.perf_counter()
    config.data.pairs = _pairs(mined)
    objective = (PAIRS_OBJECTIVE.format(rate=config.data.pairs_rate) if config.data.pairs
                 else SINGLE_OBJECTIVE)
    pairs_line = _pairs_line(config.data.pairs, _train(config, run_dir, mined))
    keypoints, keypoints_line = _keypoints(run_dir, config.data.pairs)
    minutes = (time.perf_counter() - start) / 60
    card = CARD.format(
        name=os.path.basename(os.path.normpath(FLAGS.out)), init=FLAGS.init, scans=FLAGS.scans,
        num_scans=num_scans, objective=objective, pairs=pairs_line,
        steps=config.train.num_steps, lr=config.train.learning_rate,
        schedule=config.train.lr_schedule, keypoints=keypoints_line, minutes=minutes,
        machine=', '.join(filter(None, (platform.machine(), platform.processor(),
                                        f'{os.cpu_count()} cores', platform.system()))),
        date=datetime.date.today().isoformat(), command=' '.join(['python -m experiments.adapt']
                                                                  + sys.argv[1:]),
        out=FLAGS.out)
    model = pretrained.export_run(run_dir, FLAGS.out, card=card, keypoints=keypoints)
  except io.CloudFileError as e:
    raise SystemExit(f'error: --scans: {e}') from None
  print(f'wrote {FLAGS.out}: {FLAGS.init} adapted on {num_scans} scans of {FLAGS.scans} '
        f'({model.step} steps, {minutes:.1f} min); use it with --checkpoint={FLAGS.out}')


def console():
  """The `ssd-jax-adapt` command (pyproject.toml)."""
  cli.run(main)


if __name__ == '__main__':
  console()
