#!/usr/bin/env bash
# The Spatial campaign's demonstrations (docs/baselines.md, "The Spatial suites"), one core, resumable:
# 1,000 accepted Spatial-Rigid demos (100 a task; about 1 s each), then 1,000 Spatial-Soft ones
# (about 22 s each), each screened as the Object sets are (the instructed instance on the plate, no
# drop, R_max <= 1), rendered for training (rgb+tactile, 84x84 cameras) in rounds of 10 a task,
# their small products (manifest, QC logs, QC report, stats, R_max histogram) copied into demo-data/ after
# every round for the commit. Run it again in any later session: each round skips what its QC logs
# list; on a machine without the episodes they are recorded again from the committed logs.
# SCREEN_ONLY=1 (passed on to campaign_demos.sh): grow the QC logs only, without recording again the
# accepted episodes a new machine lacks, nor merging or rendering; the training machine runs it once
# more without.
# Recorded under the pinned numerics (mani_skill_softvt/provenance/numerics.py): the episodes replay anywhere.
# Run it from a git worktree at a fixed commit (no code change under a running job), e.g.
#   git worktree add /work/camp HEAD && cd /work/camp && PY=/work/main/.venv/bin/python nohup bash \
#     campaign/scripts/campaign_spatial.sh > /work/lane-spatial.log 2>&1 &
set -euo pipefail
cd "$(dirname "$0")/../.."
# This checkout's campaign first: a worktree run with another checkout's venv (its editable install of
# softvt_campaign points there) must train, export and study with the code of the commit it runs.
export PYTHONPATH="$PWD/campaign${PYTHONPATH:+:$PYTHONPATH}"
export SOFTVT_DEMOS_DIR=${SOFTVT_DEMOS_DIR:-/root/softvt-demos}
export PY=${PY:-.venv/bin/python}
mkdir -p "$SOFTVT_DEMOS_DIR"
exec 9>"$SOFTVT_DEMOS_DIR/.lane-spatial.lock"
flock -n 9 || { echo "the spatial lane is already running (lock $SOFTVT_DEMOS_DIR/.lane-spatial.lock)" >&2; exit 1; }
for suite in spatial_rigid spatial_soft; do
  printf '\n[campaign spatial] %s  demos of %s\n' "$(date -u +%H:%M:%S)" "$suite"
  SUITE=$suite bash campaign/scripts/campaign_demos.sh 100 1 10 250
done
printf '\n[campaign spatial] %s  demos done\n' "$(date -u +%H:%M:%S)"
