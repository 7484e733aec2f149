#!/usr/bin/env bash
# Expert demos for the baselines (docs/baselines.md), resumable across sessions: Object-Soft's
# (the first campaign, step 1), or another suite's with SUITE=object_rigid (findings campaign, step 2).
#   [SUITE=object_soft] bash campaign/scripts/campaign_demos.sh [ACCEPTED_PER_TASK=100] [WORKERS=1] [ROUND=10] [MAX_SEEDS=250]
#   HELP_FROM_LAST=1 ... : beside a run that holds the suite, record and render its tasks from the last down
# Episodes live outside the checkout (SOFTVT_DEMOS_DIR, default /root/softvt-demos): a new work
# tree on the same machine keeps them. The small products (manifest, QC logs, QC report, stats,
# R_max histogram) are copied back into demo-data/$SUITE/ for the commit. On a machine without
# the episodes, the committed QC logs are copied out first and `generate` records their accepted
# episodes again. Rounds of ROUND more accepted demos per task keep the tasks level if a session
# ends early. Each task draws training seeds in order until it has ACCEPTED demos (the expert fails
# on some seeds: pastry010 rocks in the basket after release), at most MAX_SEEDS seeds. After each
# round the new episodes are rendered (rgb+tactile, cameras at RENDER_SIZE, default 84x84: the cpu
# baselines' input; RENDER_SIZE=none skips it); renderings, like the episodes, stay in the store.
# SCREEN_ONLY=1: grow the QC logs only (generate --screen-only: the accepted episodes the committed
# logs list are not recorded again, nothing is merged or rendered): a set grown over sessions on
# machines that keep nothing; the machine that trains runs it once more without, which records the
# whole set (the same bits under the pinned numerics), merges and renders it.
set -euo pipefail
cd "$(dirname "$0")/../.."
# This checkout's campaign first: a worktree run with another checkout's venv (its editable install of
# softvt_campaign points there) must train, export and study with the code of the commit it runs.
export PYTHONPATH="$PWD/campaign${PYTHONPATH:+:$PYTHONPATH}"
NUM=${1:-100}; WORKERS=${2:-1}; ROUND=${3:-10}; MAX_SEEDS=${4:-250}
(( NUM > 0 && WORKERS > 0 && ROUND > 0 && MAX_SEEDS >= NUM )) || {
  echo "usage: $0 [ACCEPTED>0] [WORKERS>0] [ROUND>0] [MAX_SEEDS>=ACCEPTED]" >&2; exit 2; }
export SOFTVT_DEMOS_DIR=${SOFTVT_DEMOS_DIR:-/root/softvt-demos}
PY=${PY:-.venv/bin/python}
SUITE=${SUITE:-object_soft}
store=$SOFTVT_DEMOS_DIR/$SUITE
mkdir -p "$store"
# Two runs over one store (the campaign's lanes) copy files in and out one at a time.
exec 8>"$store/.sync.lock"
# The committed small products go to the store where it lacks them or holds shorter logs (a store
# left by an older session); the store's own, longer logs are kept. A helper (HELP_FROM_LAST) skips
# this: the run it helps, which holds the suite, did it and is writing those files now.
if [ -d "demo-data/$SUITE" ] && [ -z "${HELP_FROM_LAST:-}" ]; then
  flock 8
  (cd "demo-data/$SUITE" && find . -type f -print0) | while IFS= read -r -d '' f; do
    if [ ! -e "$store/$f" ] || [ "$(wc -l < "demo-data/$SUITE/$f")" -gt "$(wc -l < "$store/$f")" ]; then
      mkdir -p "$(dirname "$store/$f")" && cp "demo-data/$SUITE/$f" "$store/$f"
    fi
  done
  flock -u 8
fi
sync_back() {
  mkdir -p "demo-data/$SUITE"
  flock 8
  (cd "$store" && find . \( -name manifest.json -o -name qc_report.json -o -name stats.json -o -name r_max_hist.png \
      -o -name qc.jsonl \) -print0 | xargs -0 -I{} cp --parents {} "$OLDPWD/demo-data/$SUITE/")
  flock -u 8
}
trap sync_back EXIT
generate() {  # ACCEPTED [generate's other flags]
  local k=$1; shift
  "$PY" -m mani_skill_softvt.demos generate --suite "$SUITE" --accepted "$k" --num "$MAX_SEEDS" --out "$SOFTVT_DEMOS_DIR" \
    $([ "${SCREEN_ONLY:-0}" = 1 ] && echo --screen-only) "$@"
}
render() {  # [render's other flags]
  if [ "${RENDER_SIZE:-84x84}" != none ] && [ "${SCREEN_ONLY:-0}" != 1 ]; then
    "$PY" -m mani_skill_softvt.demos render --suite "$SUITE" --obs-mode rgb+tactile --camera-size "${RENDER_SIZE:-84x84}" \
      --out "$SOFTVT_DEMOS_DIR" "$@"
  fi
}
if [ -n "${HELP_FROM_LAST:-}" ]; then
  # Another run holds the suite (the campaign's other lane, going from the first task): help it
  # from the last task down, one task at a time. A process records, merges or renders a task only
  # under that task's lock, so each waits for a task the other holds and finds it done. In a set's
  # last round (a store recorded again from the committed QC logs) the two meet in the middle; in
  # an earlier round the helper takes its tasks to ACCEPTED while the other run goes in rounds.
  tasks=$("$PY" -c 'from mani_skill_softvt.tasks.suites import NUM_TASKS; print(NUM_TASKS)')
  for ((t = tasks - 1; t >= 0; t--)); do
    generate "$NUM" --tasks "$t"
    render --tasks "$t"
  done
  exit 0
fi
# Rounds the QC logs hold already are not run: generate records every accepted seed a log lists
# (again, where its file is missing) whatever round it is in, and each round re-reads every
# episode (stats, the rendering check), one to two minutes. The first round run is the one above
# the fewest accepted demos any task lists; a set already complete gets one round (it checks,
# merges and renders what is missing).
held=$("$PY" -c 'import sys
from mani_skill_softvt.data.demo_set import DemoSet
from mani_skill_softvt.tasks.suites import NUM_TASKS
demos = DemoSet(sys.argv[1], sys.argv[2])
print(min(demos.accepted_listed(t) for t in range(NUM_TASKS)))' "$SOFTVT_DEMOS_DIR" "$SUITE") || {
  echo "could not count the accepted demos the QC logs under $SOFTVT_DEMOS_DIR/$SUITE list; every round runs" >&2
  held=0; }
first=$(( held >= NUM ? NUM : ((held / ROUND + 1) * ROUND < NUM ? (held / ROUND + 1) * ROUND : NUM) ))
(( held == 0 )) || echo "the QC logs list at least $held accepted demos a task: from the round of $first"
for ((n = first; n < NUM + ROUND; n += ROUND)); do
  k=$(( n < NUM ? n : NUM ))
  generate "$k" --workers "$WORKERS"
  "$PY" -m mani_skill_softvt.demos stats --suite "$SUITE" --out "$SOFTVT_DEMOS_DIR" || true
  render --workers "$WORKERS"
  sync_back
done
