"""Real drives: two scans of one real drive, 0-30 m apart, as driven and turned ~180
degrees, scored against the drive's own poses; success by drive, distance and overlap, the
verdict's precision and recall, and the outside anchors beside the register defaults.

Command (the sets first: the five drives beside the project; from the Fast-LIO2_SC-SLAM
output folders, wherever they were put, a Livox Avia run with revisits and the whole
OS1-64 run along a river whose first 32 keyframes are among the five):

    python -m experiments.data.make_real_pairs --drives='real_drives/*' --out=data_cache/real_drives
    python -m experiments.data.make_real_pairs --real=PATH/TO/Fast-LIO2_SC-SLAM/output \
        --drives=HKU_MB_2020-09-20-13-34-51_bag --out=data_cache/hku_mb_pairs
    python -m experiments.data.make_real_pairs --real=PATH/TO/Fast-LIO2_SC-SLAM/output \
        --drives=new_Riverside02_bag_281 --per_bin=16 --out=data_cache/riverside02_pairs
    python -m experiments.evaluate --config=configs/evals/real_drives.py --workdir=runs/real_drives

Rows: the register command's defaults with its model (`pretrained.DEFAULT`, `ours_mined`)
and with FPFH, and its model alone (--verify=0 --bev=0), run through the command's own
path (`pipeline.Registrar`) with its verdict; the BEV search alone, verified; Open3D's ISS +
FPFH pipeline; KISS-Matcher + ICP where `kiss-matcher` is installed (pip install
'.[bench]'). A set not made is skipped and the report says so. Open3D's row takes ~13 s a
pair on the five drives' scans: drop it (`--config.evals.drives.rows=...`) for a quick run.

Expected (2-core VM): the defaults register 94.9 % of the five drives' 214 pairs, 73.8 %
of the Livox drive's 80 and 100 % of Riverside02's 128 (`--config.checkpoints.ours_mined=ours`
for `ours`), and their verdict trusts 98.0, 98.3 and 98.4 % of the right poses and refuses
90.9 and 95.2 % of the wrong ones (Riverside02 has none); docs/notes/real_drives.md has the
tables and what each stage loses.
"""

import ml_collections

from ssd_jax.configs.evals import evaluation

ROWS = ('register', 'register_fpfh', 'register_descriptor', 'bev', 'open3d', 'kiss_matcher')
DISTANCE_BINS = ((0.0, 2.0), (2.0, 5.0), (5.0, 10.0), (10.0, 20.0), (20.0, 30.0))
# Shares of cloud 2 within 0.5 m of cloud 1 under the true pose.
OVERLAP_BINS = ((0.0, 0.2), (0.2, 0.3), (0.3, 0.4), (0.4, 0.5), (0.5, 0.7), (0.7, 1.01))


def real_drives(dataset: str, title: str) -> ml_collections.ConfigDict:
  return ml_collections.ConfigDict({
      'type': 'cross_sensor', 'kind': 'real_drives', 'dataset': dataset, 'title': title,
      'rows': ROWS, 'distance_bins': DISTANCE_BINS, 'overlap_bins': OVERLAP_BINS})


def get_config() -> ml_collections.ConfigDict:
  config = evaluation.get_config()
  config.evals.drives = real_drives('data_cache/real_drives',
                                    'Real drives beside the project (five units)')
  config.evals.livox = real_drives('data_cache/hku_mb_pairs',
                                   'A Livox Avia drive with revisits (HKU_MB)')
  config.evals.riverside = real_drives('data_cache/riverside02_pairs',
                                       'An OS1-64 drive along a river, all 281 keyframes')
  return config
