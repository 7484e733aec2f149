#!/usr/bin/env bash
# One training of the seed-level and Spatial campaigns (docs/baselines.md, "The seed-level and Spatial
# campaigns"), planned for a session whose machine keeps nothing from the last one:
#   bash campaign/scripts/campaign_session.sh SUITE VARIANT NAME [SEED=0] [PER_TASK=50]
#   bash campaign/scripts/campaign_session.sh object_rigid vo-c vo-c-cpu-seed1 1 25    # an extra seed, the pre-registered 250
#   bash campaign/scripts/campaign_session.sh spatial_rigid vo-c vo-c-cpu 0 50         # a Spatial policy's seed 0, all 500
# 1. SUITE's demo set, as its committed QC logs list it, recorded again (the same episodes, bit for
#    bit, under the pinned numerics), merged and rendered at 84 px, on both cores: about 16 + 60 min
#    for a rigid suite on a new machine, nothing where the store already holds it;
# 2. VARIANT trained with the committed policies' recipe (noaug, 24,000 steps) and seed SEED into
#    $SOFTVT_RUNS_DIR, exported to campaign-data/policies/SUITE/NAME.pt (commit it as soon as it is
#    there: a training outlives a session only as its exported policy), then scored on PER_TASK ID
#    episodes of each task into campaign-data/results/ (resumable: run the same command again).
#    The training takes both cores (THREADS, default 2: torch's intra-op threads, which change the
#    order of its float sums, not the recipe; 7.2 steps/s, 56 min for VO on an AMD EPYC, against about
#    5.5 on one), and so does the scoring (WORKERS, default 2). Two trainings side by side take
#    THREADS=1 WORKERS=1 each.
# Run again in a later session once the policy is committed, it skips the demos and the training and
# scores what is left.
# A rigid suite's VO training fits one session after its demos; a soft suite's
# demos alone take about two hours of both cores, so its trainings wait for a machine that keeps the
# stores between sessions. Run it from a worktree at a fixed commit, e.g.
#   git worktree add /work/camp HEAD && cd /work/camp && PY=/work/main/.venv/bin/python nohup bash \
#     campaign/scripts/campaign_session.sh object_rigid vo-c vo-c-cpu-seed1 1 25 > /work/lane-session.log 2>&1 &
set -euo pipefail
cd "$(dirname "$0")/../.."
# This checkout's campaign first: a worktree run with another checkout's venv (its editable install of
# softvt_campaign points there) must train, export and study with the code of the commit it runs.
export PYTHONPATH="$PWD/campaign${PYTHONPATH:+:$PYTHONPATH}"
(( $# >= 3 )) || { echo "usage: $0 SUITE VARIANT NAME [SEED=0] [PER_TASK=50]" >&2; exit 2; }
SUITE=$1; VARIANT=$2; NAME=$3; SEED=${4:-0}; PER_TASK=${5:-50}
export SOFTVT_DEMOS_DIR=${SOFTVT_DEMOS_DIR:-/root/softvt-demos}
export SOFTVT_RUNS_DIR=${SOFTVT_RUNS_DIR:-/root/softvt-runs}
export PY=${PY:-.venv/bin/python}
THREADS=${THREADS:-2}
# Scoring workers (default 2, both cores); 1 where another training shares the machine.
WORKERS=${WORKERS:-2}
sub=$([ "$SUITE" = object_soft ] || echo "$SUITE/")
if [ -f "campaign-data/policies/$sub$NAME.pt" ]; then
  # Trained and exported in an earlier session: only its scoring is left, which needs no demos.
  printf '\n[campaign session] %s  %s is committed: scoring it only\n' "$(date -u +%H:%M:%S)" "campaign-data/policies/$sub$NAME.pt"
else
  printf '\n[campaign session] %s  %s demos: recorded again, merged, rendered (two workers)\n' "$(date -u +%H:%M:%S)" "$SUITE"
  SCREEN_ONLY=0 HELP_FROM_LAST= RENDER_SIZE=84x84 SUITE=$SUITE bash campaign/scripts/campaign_demos.sh 100 2
fi
printf '\n[campaign session] %s  %s %s seed %s: train, export, %s ID episodes a task\n' "$(date -u +%H:%M:%S)" \
  "$SUITE" "$VARIANT" "$SEED" "$PER_TASK"
SUITE=$SUITE PER_TASK=$PER_TASK SET="steps=24000 seed=$SEED threads=$THREADS" bash campaign/scripts/campaign_protocol.sh "$VARIANT" noaug "$WORKERS" 100000 "$NAME"
printf '\n[campaign session] %s  done\n' "$(date -u +%H:%M:%S)"
