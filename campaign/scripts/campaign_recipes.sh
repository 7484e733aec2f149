#!/usr/bin/env bash
# Baselines campaign, step 2 (docs/baselines.md): the recipe search, resumable across sessions.
#   bash campaign/scripts/campaign_recipes.sh [VARIANT=vo-c] [BUDGET_MIN=150] [RECIPE ...]
# Trains the named recipes (campaign/softvt_campaign/baselines/config.py: RECIPES, run by studies/recipe_search.py; default: all, in
# order) on the step-1 demos (SOFTVT_DEMOS_DIR, default /root/softvt-demos, rendered at 84x84),
# each with 90 demos a task trained on and the next 10 held out, until BUDGET_MIN minutes are
# spent; run again to continue. Runs (checkpoints, prepared data) stay beside the demos
# (SOFTVT_RUNS_DIR, default /root/softvt-runs); every snapshot's open-loop error is logged to
# campaign-data/search/<variant>.jsonl, which is committed. SET="key=value ..." adds overrides to
# every recipe (runs named <variant>-<recipe>+key=value).
set -euo pipefail
cd "$(dirname "$0")/../.."
# This checkout's campaign first: a worktree run with another checkout's venv (its editable install of
# softvt_campaign points there) must train, export and study with the code of the commit it runs.
export PYTHONPATH="$PWD/campaign${PYTHONPATH:+:$PYTHONPATH}"
VARIANT=${1:-vo-c}; BUDGET=${2:-150}; shift $(( $# < 2 ? $# : 2 ))
export SOFTVT_DEMOS_DIR=${SOFTVT_DEMOS_DIR:-/root/softvt-demos}
export SOFTVT_RUNS_DIR=${SOFTVT_RUNS_DIR:-/root/softvt-runs}
PY=${PY:-.venv/bin/python}
recipes=("$@")
if (( ${#recipes[@]} == 0 )); then
  mapfile -t recipes < <("$PY" -c "from softvt_campaign.studies.recipe_search import RECIPES; print(*RECIPES, sep='\n')")
fi
read -r -a sets <<< "${SET:-}"
"$PY" -m softvt_campaign.studies.recipe_search --variant "$VARIANT" --recipes "${recipes[@]}" --budget-min "$BUDGET" \
  --demos "$SOFTVT_DEMOS_DIR" --runs "$SOFTVT_RUNS_DIR" --demos-per-task 90 --heldout 10 --set "${sets[@]}"
