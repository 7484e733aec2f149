#!/usr/bin/env bash
# One baseline variant trained and scored on a suite's ID protocol (docs/baselines.md: the baselines
# campaign's steps 3, 4 and 6; the findings campaign's steps 2 to 4).
#   bash campaign/scripts/campaign_protocol.sh [VARIANT=vo-c] [RECIPE=base] [WORKERS=1] [BUDGET_MIN=150] [NAME]
#   SET="tactile_inputs=rgb" bash campaign/scripts/campaign_protocol.sh vt-c long 1 150 vt-c-rgb-cpu
#   SUITE=object_rigid SET="steps=24000" bash campaign/scripts/campaign_protocol.sh vo-c noaug 1 150 vo-c-cpu
#   SET="steps=24000 seed=1" bash campaign/scripts/campaign_protocol.sh vo-c noaug 1 150 vo-c-cpu-seed1
# 1. trains the recipe (SET: more overrides) on every accepted demo of SUITE (default object_soft;
#    SOFTVT_DEMOS_DIR, rendered at 84x84) into $SOFTVT_RUNS_DIR/final/[SUITE/]NAME, until BUDGET_MIN
#    minutes are spent (run again to continue; nothing below runs before training ends);
# 2. exports the policy to campaign-data/policies/[SUITE/]NAME.pt (float16, at most 20 MiB; left as it is
#    if already exported from the same policy, so its records stay reproducible);
# 3. evaluates it on SUITE's ID protocol, PER_TASK episodes per task (default 50, all of them; the
#    pre-registered design scores extra training seeds on the first 25), resumable, into campaign-data/results/;
# 4. writes the report beside the paper's numbers (all four suites, so a rigid-twin variant is
#    paired with its soft one; the Spatial side-swap runs paired with their ID runs), the old-physics
#    rows kept apart.
# A policy exported in an earlier session, whose run this machine lacks, is scored as committed (step 3 on).
# NAME defaults to <variant>-cpu, or <variant>-cpu-<recipe> for a recipe other than base. The
# Object-Soft runs keep the unprefixed paths they were made with.
set -euo pipefail
cd "$(dirname "$0")/../.."
# This checkout's campaign first: a worktree run with another checkout's venv (its editable install of
# softvt_campaign points there) must train, export and study with the code of the commit it runs.
export PYTHONPATH="$PWD/campaign${PYTHONPATH:+:$PYTHONPATH}"
VARIANT=${1:-vo-c}; RECIPE=${2:-base}; WORKERS=${3:-1}; BUDGET=${4:-150}
NAME=${5:-$VARIANT-cpu$([ "$RECIPE" = base ] || echo "-$RECIPE")}
SUITE=${SUITE:-object_soft}
export SOFTVT_DEMOS_DIR=${SOFTVT_DEMOS_DIR:-/root/softvt-demos}
export SOFTVT_RUNS_DIR=${SOFTVT_RUNS_DIR:-/root/softvt-runs}
PY=${PY:-.venv/bin/python}
sub=$([ "$SUITE" = object_soft ] || echo "$SUITE/")
run=$SOFTVT_RUNS_DIR/final/$sub$NAME
policy=campaign-data/policies/$sub$NAME.pt
read -r -a sets <<< "${SET:-}"
if [ -f "$policy" ] && [ ! -f "$run/policy.pt" ]; then
  # Exported in an earlier session whose run is gone (a new machine keeps no runs): training again
  # would make another policy, so the committed one is scored as it is.
  echo "$policy was exported before and $run holds no finished run: scoring the committed policy"
else
"$PY" -m softvt_campaign.baselines.train --variant "$VARIANT" --recipe "$RECIPE" --set threads=1 "suite=$SUITE" \
  "${sets[@]}" --demos "$SOFTVT_DEMOS_DIR" --out "$run" --cache "$SOFTVT_RUNS_DIR/data_cache" --budget-min "$BUDGET" \
  --snapshot-every 3000
if [ ! -f "$run/policy.pt" ]; then
  echo "training stopped at its time budget; run the same command again to continue"; exit 0
fi
mkdir -p "$(dirname "$policy")"
"$PY" -m softvt_campaign.baselines.export "$run/policy.pt" "$policy" --if-changed
fi
"$PY" -m mani_skill_softvt.evaluate --policy "$policy" --suite "$SUITE" --tasks all --episodes-per-task "${PER_TASK:-50}" \
  --workers "$WORKERS" --out campaign-data/results
shopt -s nullglob
"$PY" -m softvt_campaign.studies.results campaign-data/results/{object,spatial}_{soft,rigid}_id_*.jsonl \
  campaign-data/results/side_swap/spatial_*_side_swap_*.jsonl --legacy campaign-data/results/old_physics/*.jsonl --out campaign-data/results
