#!/usr/bin/env bash
# The tracker experiments of BENCHMARKS.md (paper §3.3): synthesise the sequences, then one
# `swarmpose eval --json` per cell into OUT/results/NAME.json (existing results are kept, so
# an interrupted run resumes). Usage: scripts/run-experiments.sh OUT   (needs ../shared/assets)
set -uo pipefail
OUT=${1:?usage: scripts/run-experiments.sh OUT}
SP=${SWARMPOSE:-.venv/bin/swarmpose}
MH=makehuman:../shared/assets/bodies/makehuman
M=../shared/assets/mocap
MOVENET=onnx:../shared/assets/pose2d/movenet_singlepose_lightning.onnx
R=$OUT/results
mkdir -p "$R"
declare -A SHAPE=([walk-male]=male [jj-female]=female [jump-male]=male [walk-female]=female [walk-male-heavy]=male-heavy)
declare -A CLIP=([walk-male]=bvh11_131_01 [jj-female]=animdrawings_cmu1_jumping_jacks [jump-male]=fairmotion_01_01
                 [walk-female]=bvh11_131_01 [walk-male-heavy]=bvh11_131_01)
for seq in "${!SHAPE[@]}"; do
  [ -s "$OUT/$seq/groundtruth.jsonl" ] || $SP synth --body $MH --shape "${SHAPE[$seq]}" --motion "$M/${CLIP[$seq]}.bvh" \
      --frames 100 --out "$OUT/$seq" --quiet
done
ev() {
  local name=$1; shift
  [ -s "$R/$name.json" ] && return
  $SP eval "$@" --json --quiet > "$R/$name.json.tmp" 2> "$R/$name.err" && mv "$R/$name.json.tmp" "$R/$name.json"
}
for det in simulated movenet; do  # Table 2
  J=simulated; [ $det = movenet ] && J=$MOVENET
  for seq in walk-male jj-female jump-male; do
    for mode in lift hybrid joints depth; do
      ev "t2-$seq-$det-$mode" "$OUT/$seq" --body $MH --shape "${SHAPE[$seq]}" --detector "$J" --mode $mode
    done
  done
done
for wd in 3 0.5 18 1.5 6; do for pso in perturbed canonical; do  # Table 3
  ev "t3-$pso-$wd" "$OUT/walk-male" --body $MH --shape male --pso $pso --depth-weight $wd --frames 50
done; done
for seq in walk-male walk-female walk-male-heavy; do  # Table 4
  for model in male female male-heavy; do
    ev "t4-$seq-$model" "$OUT/$seq" --body $MH --shape $model --frames 50
  done
  height=$($SP body --body $MH --shape "${SHAPE[$seq]}" --json | python3 -c 'import json,sys;print(round(json.load(sys.stdin)["height_m"],3))')
  ev "t4-$seq-builtin" "$OUT/$seq" --body builtin --shape "height=$height" --frames 50
done
for p in 16 32 64; do for g in 16 32 64; do  # Fig. 3
  ev "f3-p$p-g$g" "$OUT/walk-male" --body $MH --shape male --particles $p --generations $g --frames 30
done; done
