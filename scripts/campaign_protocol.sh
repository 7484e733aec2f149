#!/usr/bin/env bash
# Baselines campaign, steps 3, 4 and 6 (docs/baselines.md): one variant on the paper's ID protocol.
#   bash scripts/campaign_protocol.sh [VARIANT=vo-c] [RECIPE=base] [WORKERS=1] [BUDGET_MIN=150] [NAME]
#   SET="tactile_inputs=rgb" bash scripts/campaign_protocol.sh vt-c long 1 150 vt-c-rgb-cpu
# 1. trains the recipe (SET: more overrides) on every accepted demo (SOFTVT_DEMOS_DIR, rendered at
#    84x84) into $SOFTVT_RUNS_DIR/final/NAME, until BUDGET_MIN minutes are spent (run again to
#    continue; nothing below runs before training ends);
# 2. exports the policy to baselines/policies/NAME.pt (float16, at most 20 MiB; left as it is if
#    already exported from the same policy, so its records stay reproducible);
# 3. evaluates it on the ID protocol, 50 episodes per task (resumable), into baselines/results/;
# 4. writes the report beside the paper's numbers, the old-physics rows kept apart.
# NAME defaults to <variant>-cpu, or <variant>-cpu-<recipe> for a recipe other than base.
set -euo pipefail
cd "$(dirname "$0")/.."
VARIANT=${1:-vo-c}; RECIPE=${2:-base}; WORKERS=${3:-1}; BUDGET=${4:-150}
NAME=${5:-$VARIANT-cpu$([ "$RECIPE" = base ] || echo "-$RECIPE")}
export SOFTVT_DEMOS_DIR=${SOFTVT_DEMOS_DIR:-/root/softvt-demos}
export SOFTVT_RUNS_DIR=${SOFTVT_RUNS_DIR:-/root/softvt-runs}
PY=${PY:-.venv/bin/python}
run=$SOFTVT_RUNS_DIR/final/$NAME
read -r -a sets <<< "${SET:-}"
"$PY" -m mani_skill_softvt.baselines.train --variant "$VARIANT" --recipe "$RECIPE" --set threads=1 "${sets[@]}" \
  --demos "$SOFTVT_DEMOS_DIR" --out "$run" --cache "$SOFTVT_RUNS_DIR/data_cache" --budget-min "$BUDGET" \
  --snapshot-every 3000
if [ ! -f "$run/policy.pt" ]; then
  echo "training stopped at its time budget; run the same command again to continue"; exit 0
fi
"$PY" -m mani_skill_softvt.baselines.export "$run/policy.pt" "baselines/policies/$NAME.pt" --if-changed
"$PY" -m mani_skill_softvt.evaluate --policy "baselines/policies/$NAME.pt" --tasks all --episodes-per-task 50 \
  --workers "$WORKERS" --out baselines/results
shopt -s nullglob
"$PY" -m mani_skill_softvt.studies.results baselines/results/object_soft_id_*.jsonl \
  --legacy baselines/results/old_physics/*.jsonl --out baselines/results
