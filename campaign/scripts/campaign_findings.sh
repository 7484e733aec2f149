#!/usr/bin/env bash
# The findings campaign's remaining runs (docs/baselines.md "What runs next"), as two lanes of one
# core each, both resumable: run the same command again, in any later session, and each step
# skips what it finds done (the demos' QC logs, a training's checkpoint, an evaluation's records).
#   bash campaign/scripts/campaign_findings.sh rigid   # VT-C on Object-Rigid, its closure study; then vt-c seed 1, vt-b
#   bash campaign/scripts/campaign_findings.sh soft    # the Object-Soft demos; then vo-c seed 1, vo-b
# Run it from a git worktree at a fixed commit (no code change under a running evaluation), e.g.
#   git worktree add /work/camp HEAD && cd /work/camp && PY=/work/main/.venv/bin/python nohup bash \
#     campaign/scripts/campaign_findings.sh rigid > /work/lane-rigid.log 2>&1 &
# Its products (policies, records, reports, QC logs) land in that worktree's campaign-data/ and demo-data/,
# to be copied into main and committed as each finishes. Stores stay outside the checkout
# (SOFTVT_DEMOS_DIR, SOFTVT_RUNS_DIR): on a machine without them the demos are recorded again from
# the committed QC logs and a training starts again from step 0 (a checkpoint is too large to commit).
# The two lanes share the Object-Soft demo store: whichever lane needs it first holds the suite's
# lock while it records and renders it from the first task; a lane that arrives meanwhile helps
# from the last task down (each task is locked while a process records or renders it), then waits
# for the lock and finds the set complete. The Object-Rigid
# demos come first and take both cores (two recording, then two rendering processes: about 16 and
# 60 min on a new machine, 2 min on a machine that holds them): the soft lane waits for them, so
# VT-C's rigid training starts about an hour sooner than beside the soft recording, and the soft
# recording loses nothing (start the rigid lane first). The closure study
# writes into its own directory (campaign-data/results/closure_rigid_vo-c_vt-c/), beside the VO-C-only
# study that docs/findings.md cites, and runs two workers (one per policy) for its few minutes.
set -euo pipefail
cd "$(dirname "$0")/../.."
# This checkout's campaign first: a worktree run with another checkout's venv (its editable install of
# softvt_campaign points there) must train, export and study with the code of the commit it runs.
export PYTHONPATH="$PWD/campaign${PYTHONPATH:+:$PYTHONPATH}"
LANE=${1:-}
export SOFTVT_DEMOS_DIR=${SOFTVT_DEMOS_DIR:-/root/softvt-demos}
export SOFTVT_RUNS_DIR=${SOFTVT_RUNS_DIR:-/root/softvt-runs}
export PY=${PY:-.venv/bin/python}
BUDGET=${BUDGET_MIN:-100000}  # minutes a training may run before it stops at a checkpoint
mkdir -p "$SOFTVT_DEMOS_DIR"

step() { printf '\n[campaign %s] %s  %s\n' "$LANE" "$(date -u +%H:%M:%S)" "$*"; }

case "$LANE" in rigid|soft) ;; *)
  echo "usage: $0 rigid|soft  (two lanes of the findings campaign, one core each; see the header)" >&2; exit 2 ;;
esac
mkdir -p "$SOFTVT_RUNS_DIR"
exec 9>"$SOFTVT_RUNS_DIR/.lane-$LANE.lock"  # one process per lane: two would train into one run directory
flock -n 9 || { echo "the $LANE lane is already running (lock $SOFTVT_RUNS_DIR/.lane-$LANE.lock)" >&2; exit 1; }

RIGID_DEMOS_LOCK=$SOFTVT_RUNS_DIR/.object_rigid-demos.lock
rigid_demos() {  # 1,000 Object-Rigid demos rendered at 84 px, on both cores while the soft lane waits
  step "Object-Rigid demos (both cores: the soft lane waits)"
  SUITE=object_rigid flock "$RIGID_DEMOS_LOCK" bash campaign/scripts/campaign_demos.sh 100 2
}

soft_demos() {  # 1,000 accepted Object-Soft demos rendered at 84 px
  local lock=$SOFTVT_DEMOS_DIR/.object_soft.lock
  if ! flock -n "$lock" true; then  # the other lane records them: help it from the last task down
    step "Object-Soft demos: the other lane records them from the first task; this one helps from the last"
    SUITE=object_soft HELP_FROM_LAST=1 bash campaign/scripts/campaign_demos.sh 100 1
  fi
  step "Object-Soft demos (waits while the other lane completes them)"
  SUITE=object_soft flock "$lock" bash campaign/scripts/campaign_demos.sh 100 1
}

train_and_score() {  # SUITE VARIANT NAME [SET]: the recipe of the committed Object-Soft policies
  local suite=$1 variant=$2 name=$3 set=${4:-}
  local sub; sub=$([ "$suite" = object_soft ] || echo "$suite/")
  step "$variant on $suite as $name: training (24,000 steps), export, 500 ID episodes, report"
  SUITE=$suite SET="steps=24000 $set" bash campaign/scripts/campaign_protocol.sh "$variant" noaug 1 "$BUDGET" "$name"
  if [ ! -f "$SOFTVT_RUNS_DIR/final/$sub$name/policy.pt" ]; then
    step "$name stopped at its time budget (BUDGET_MIN=$BUDGET); run the lane again to continue"; exit 0
  fi
}

closure_study() {  # TASK: both rigid policies' closures on 10 ID seeds; skipped once its report exists
  local task=$1 out=campaign-data/results/closure_rigid_vo-c_vt-c
  local report=$out/closure_object_rigid_task$task.json
  if [ -f "$report" ]; then step "closure study task $task: done ($report)"; return; fi
  step "closure study, Object-Rigid task $task, VO-C and VT-C"
  mkdir -p "$out"
  local rc=0
  "$PY" -m softvt_campaign.studies.closure campaign-data/policies/object_rigid/vo-c-cpu.pt \
    campaign-data/policies/object_rigid/vt-c-cpu.pt --suite object_rigid --task "$task" --episodes 10 \
    --demos "$SOFTVT_DEMOS_DIR" --out "$out" || rc=$?
  # Exit status 1 with its report written: some records differ from the committed ones (another
  # machine rounds differently; the report says whether the outcomes held). Anything else is a failure.
  if [ "$rc" -ne 0 ] && { [ "$rc" -ne 1 ] || [ ! -f "$report" ]; }; then
    step "closure study task $task failed (exit status $rc)"; exit "$rc"
  fi
}

case "$LANE" in
  rigid)
    rigid_demos
    train_and_score object_rigid vt-c vt-c-cpu
    for task in 2 7; do  # does touch keep the closure the rigid VO-C redraws? (findings.md, Finding 2)
      closure_study "$task"
    done
    soft_demos
    train_and_score object_soft vt-c vt-c-cpu-seed1 seed=1
    train_and_score object_soft vt-b vt-b-cpu
    ;;
  soft)
    sleep 5  # the rigid lane, started first, takes its lock
    step "waits while the rigid lane records and renders the Object-Rigid demos on both cores"
    flock -s "$RIGID_DEMOS_LOCK" true
    soft_demos
    train_and_score object_soft vo-c vo-c-cpu-seed1 seed=1
    train_and_score object_soft vo-b vo-b-cpu
    ;;
esac
step "lane done"
