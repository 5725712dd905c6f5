#!/usr/bin/env bash
# The robustness target on many contours at once (docs/robustness.md, "Many contours"): for each contour,
# es on four gain matrices alone over randomised sheets (warpcut optimize), then the force and noise studies
# of it against none and fixed (warpcut robustness, 30 trials), then the target check
# (scripts/robustness_tables.py). With --studies CONTOUR it instead trains the same gains on the nominal
# sheet too and runs all three studies for both policies on CONTOUR (one figure for both).
#
#   bash scripts/robustness_scan.sh [--out DIR] [CONTOUR ...]     (default: the suite's closed contours)
#   bash scripts/robustness_scan.sh [--out DIR] --studies CONTOUR   (after the scan: reuses DIR/CONTOUR-gains4)
#
# --sag schedules the gains on the sheet's sag (--set grad.es_feedback_sag=true), for both modes;
# --episodes N: episodes per perturbed policy (--set grad.es_trials=N, default 4);
# --iterations N: es steps per optimisation (warpcut optimize --iterations; default: es's own).
# --trials N: trials per value of each study (default 30); --range NAME=LOW,HIGH: a randomised parameter's
# range while optimising (grad.es_randomize_ranges; repeatable).
# --gains-from DIR: reuse the gains a scan wrote to DIR (DIR/CONTOUR-gains4) instead of optimising them again,
# and only run the studies (e.g. to score them again at more trials).
# WARPCUT and PYTHON name the commands (default: .venv's, else those on PATH).
set -euo pipefail
cd "$(dirname "$0")/.."
WARPCUT=${WARPCUT:-$([ -x .venv/bin/warpcut ] && echo .venv/bin/warpcut || echo warpcut)}
PYTHON=${PYTHON:-$([ -x .venv/bin/python ] && echo .venv/bin/python || echo python)}
out=logs/robustness-scan
studies=""
sag=()
episodes=4
iterations=()
gains_from=""
trials=30
ranges=""
while [ $# -gt 0 ]; do
  case "$1" in
    --out) out=$2; shift 2 ;;
    --studies) studies=$2; shift 2 ;;
    --sag) sag=(--set grad.es_feedback_sag=true); shift ;;
    --episodes) episodes=$2; shift 2 ;;
    --iterations) iterations=(--iterations "$2"); shift 2 ;;
    --gains-from) gains_from=$2; shift 2 ;;
    --trials) trials=$2; shift 2 ;;
    --range) ranges="${ranges:+$ranges, }${2%%=*}: [${2#*=}]"; shift 2 ;;
    -h|--help) sed -n 2,18p "$0"; exit 0 ;;
    -*) echo "error: unknown option $1 (see --help)" >&2; exit 2 ;;
    *) break ;;
  esac
done
mkdir -p "$out"
gains=(--estimator es --set grad.es_feedback_phases=4 --set grad.es_feedback_only=true "${sag[@]}" "${iterations[@]}")
# every range in one mapping: grad.es_randomize_ranges={NAME: [LOW, HIGH], ...}
range_set=()
[ -z "$ranges" ] || range_set=(--set "grad.es_randomize_ranges={$ranges}")
randomised() {  # CONTOUR: the randomised gains into $out/CONTOUR-gains4 (with --gains-from: copied from there)
  if [ -n "$gains_from" ]; then
    [ -f "$gains_from/$1-gains4/$1.json" ] || { echo "error: --gains-from: no $gains_from/$1-gains4/$1.json" >&2; exit 2; }
    mkdir -p "$out/$1-gains4" && cp "$gains_from/$1-gains4/$1.json" "$out/$1-gains4/"
    return
  fi
  $WARPCUT optimize --contour "$1" "${gains[@]}" --set grad.es_randomize=gravity,noise \
    --set grad.es_trials="$episodes" "${range_set[@]}" --out "$out/$1-gains4" --overwrite > "$out/$1-opt.log" 2>&1
}
if [ -n "$studies" ]; then
  c=$studies
  [ -f "$out/$c-gains4/$c.json" ] || randomised "$c"
  $WARPCUT optimize --contour "$c" "${gains[@]}" --out "$out/$c-gains4-nominal" --overwrite > "$out/$c-nominal-opt.log" 2>&1
  $WARPCUT robustness --contour "$c" --study all --methods none,fixed,analytic \
    --set plans.gains4="$out/$c-gains4-nominal/$c.json" --set plans.gains4-rand="$out/$c-gains4/$c.json" \
    --trials "$trials" --out "$out/$c-all" --json "$out/$c-all.json" --overwrite > "$out/$c-all.log" 2>&1
  "$PYTHON" scripts/robustness_tables.py "$out/$c-all.json" --policy gains4 --policy gains4-rand
  exit 0
fi
contours=("$@")
[ ${#contours[@]} -gt 0 ] || mapfile -t contours < <("$PYTHON" -c "from warpcut.contours import builtin_contours
print('\n'.join(name for name, c in builtin_contours().items() if c.closed))")
for c in "${contours[@]}"; do
  randomised "$c"
  $WARPCUT robustness --contour "$c" --study force,noise --methods none,fixed \
    --set plans.gains4="$out/$c-gains4/$c.json" --trials "$trials" --set plots=false \
    --out "$out/$c-studies" --json "$out/$c.json" --overwrite > "$out/$c-rob.log" 2>&1
  echo "== $c"
  "$PYTHON" scripts/robustness_tables.py "$out/$c.json" --policy gains4 --policy fixed | tail -8
done
