#!/bin/sh
# Peers at equal check density (docs/peers.md, "Equal check density: how this was measured"):
# every setting's compare run once per run seed, then the analysis over seeds and problems.
#
#   sh docs/peers-equal.sh                      # the measurement: 4 settings x 3 seeds, 100 problems
#   OUT=/tmp/pe SEEDS=0 DATASET="recycle-v3.1:quick:family=window,kind=transit" sh docs/peers-equal.sh
#                                               # a small trial of the same pipeline elsewhere
#
# Each setting's planner settings, dataset, budget and jobs are its committed
# results/peers-equal/<setting>/config.yaml; DATASET, when given, overrides the dataset. A run that
# exists already is resumed (its recorded trials are kept). Run from the repository's root, in the
# environment with the `peers` extra, on a quiet machine, from a clean commit.
set -eu
CONFIGS=results/peers-equal
OUT=${OUT:-$CONFIGS}
SEEDS=${SEEDS:-"0 1 2"}
SETTINGS=${SETTINGS:-"step-0.01-range-1 step-0.01-range-2 step-0.05-range-1 step-0.05-range-2"}
PYTHON=${PYTHON:-python}

dirs=""
for setting in $SETTINGS; do
    for seed in $SEEDS; do
        run="$OUT/$setting/seed-$seed"
        set -- --config "$CONFIGS/$setting/config.yaml" --seed "$seed" --out "$run" --no-progress --no-plots
        if [ -n "${DATASET:-}" ]; then set -- "$@" --dataset "$DATASET"; fi
        if [ -f "$run/trials.jsonl" ]; then set -- "$@" --resume; fi
        echo "== $setting, run seed $seed -> $run"
        "$PYTHON" -m suite compare "$@"
    done
    dirs="$dirs $OUT/$setting"
done
# shellcheck disable=SC2086
"$PYTHON" -m suite.report.peers_equal $dirs --json "$OUT/analysis.json"
