#!/usr/bin/env bash
# Findings campaign, step 1 (docs/baselines.md, "The findings campaign"): the committed VO-C and
# VT-C on a soft suite's OOD protocol, then their ID twins on this machine, then the report.
#   [SUITE=object_soft] bash campaign/scripts/campaign_ood.sh [WORKERS=1] [POLICIES="vo-c-cpu vt-c-cpu"]
# SUITE=spatial_soft runs the Spatial-Soft policies (campaign-data/policies/spatial_soft/); name the
# ones committed (POLICIES="vo-c-cpu" until VT-C is trained there): a missing policy stops the run.
# Every stage resumes where it stopped (records are appended as episodes finish): run the same
# command again in the next session, from a checkout that holds the records so far.
# 1. OOD: 9 held-out conditions x 10 tasks x 10 episodes a policy, into campaign-data/results/;
# 2. ID twins: the first 10 ID seeds of each task again, on the OOD episodes' machine, into
#    campaign-data/results/twins/ (paired with the OOD episodes by the report);
# 3. the report: campaign-data/results/ood.md, ood.json, ood_curves.png.
set -euo pipefail
cd "$(dirname "$0")/../.."
# This checkout's campaign first: a worktree run with another checkout's venv (its editable install of
# softvt_campaign points there) must train, export and study with the code of the commit it runs.
export PYTHONPATH="$PWD/campaign${PYTHONPATH:+:$PYTHONPATH}"
WORKERS=${1:-1}
read -r -a policies <<< "${2:-vo-c-cpu vt-c-cpu}"
PY=${PY:-.venv/bin/python}
SUITE=${SUITE:-object_soft}
case "$SUITE" in
  object_soft) policy_dir=campaign-data/policies ;;  # the Object policies predate the per-suite folders
  spatial_soft) policy_dir=campaign-data/policies/spatial_soft ;;
  *) echo "SUITE=$SUITE: the OOD protocol is defined on the soft suites only (object_soft, spatial_soft)" >&2; exit 2 ;;
esac
for p in "${policies[@]}"; do
  "$PY" -m mani_skill_softvt.evaluate --policy "$policy_dir/$p.pt" --suite "$SUITE" --protocol ood --tasks all \
    --episodes-per-task 10 --workers "$WORKERS" --out campaign-data/results
done
for p in "${policies[@]}"; do
  "$PY" -m mani_skill_softvt.evaluate --policy "$policy_dir/$p.pt" --suite "$SUITE" --tasks all --episodes-per-task 10 \
    --workers "$WORKERS" --out campaign-data/results/twins
done
# One report (ood.md) over every soft suite's committed OOD run whose ID twins have run (the report
# pairs each run with them): a Spatial run must not replace the Object page, nor a run still under
# way stop the report.
shopt -s nullglob
ood=()
for f in campaign-data/results/{object,spatial}_soft_ood_*-cpu.jsonl; do
  name=$(basename "$f")
  [ -f "campaign-data/results/twins/${name/_ood_/_id_}" ] && ood+=("$f")
done
"$PY" -m softvt_campaign.studies.ood_results "${ood[@]}" --twins campaign-data/results/twins --out campaign-data/results
