#!/usr/bin/env bash
# The README's main job (under 10 minutes on 2 cores, after setup.sh): the small embedded
# synthetic dataset, 400 steps of the self-supervised descriptor, and every table and
# figure of the paper on it with the shipped models and that run. Each step is a command
# of the README; rerunning reuses the dataset and resumes the run.
set -euo pipefail
cd "$(dirname "$0")"
py=.venv/bin/python
# Simulated LiDAR streets with exact poses (~1-2 minutes; kept when present).
$py -m experiments.data.make_synthetic --config=configs/data/synthetic_small.py --out=data_cache/synthetic_small
# The shipped recipe of `ours` for 400 steps (~2 minutes).
$py -m experiments.train --config=configs/training/ours.py --workdir=runs/main_job --config.train.num_steps=400
# Tables I-III and Figs. 3-6 on 8 pairs of each held-out set: runs/reproduce_small/report.md.
$py -m experiments.evaluate --config=configs/evals/reproduce_small.py \
    --config.data_root=data_cache/synthetic_small --workdir=runs/reproduce_small
