#!/usr/bin/env bash
# Personalisation benchmark (issue 15): synthesise a walk for every MakeHuman preset and four
# slider mixes, personalise each from its first frames, and print one JSON line per subject with
# the true and recovered height, volume and mean vertex distance. Resumable: a subject whose
# OUT/<subject>.json exists is skipped.
#   usage: scripts/bench-personalise.sh OUT [FRAMES] [PARTICLES] [SEED] [ENSEMBLE]
# (PARTICLES: particles and generations of the tracking and pose refits; the shape PSO is 16 x 16;
# SEED: the fit's --seed, 0 by default; ENSEMBLE: personalize's --ensemble, the tracks whose
# joints are averaged over the frames the fit reads, 1 by default)
set -euo pipefail
OUT=${1:?usage: scripts/bench-personalise.sh OUT [FRAMES] [PARTICLES] [SEED] [ENSEMBLE]}
FRAMES=${2:-30}
P=${3:-32}
SEED=${4:-0}
ENSEMBLE=${5:-1}
S=${SWARMPOSE:-.venv/bin/swarmpose}
PY=${PYTHON:-.venv/bin/python}
MH=${MH:-../shared/assets/bodies/makehuman}
CLIP=${CLIP:-../shared/assets/mocap/bvh11_131_01.bvh}
mkdir -p "$OUT"
SUBJECTS=(male female male-heavy female-heavy male-slim female-slim male-muscular female-muscular
          male-tall female-tall male-short female-short neutral
          "gender=0.5,weight=0.75" "gender=0.25,muscle=0.8,height=0.6"
          "gender=0.8,weight=0.3,height=0.35" "gender=0.6,caucasian=0.5,weight=0.65,muscle=0.3")
for subject in "${SUBJECTS[@]}"; do
  name=$(echo "$subject" | tr '=,' '-_')
  [ -s "$OUT/$name.json" ] && continue
  "$S" -q synth --body "makehuman:$MH" --shape "$subject" --motion "$CLIP" --frames "$FRAMES" --out "$OUT/seq-$name" >/dev/null
  "$S" -q personalize "$OUT/seq-$name" --body "makehuman:$MH" --frames "$FRAMES" --particles "$P" --generations "$P" --seed "$SEED" --ensemble "$ENSEMBLE" \
      --out "$OUT/$name.glb" --json > "$OUT/$name.fit.json"
  "$PY" - "$MH" "$subject" "$OUT/$name.fit.json" "$OUT/$name.glb" > "$OUT/$name.json" <<'PYEOF'
import json, sys
import numpy as np
from swarmpose.body.loader import load_body
from swarmpose.tracking.personalise import body_measures
mh, subject, fit_file, glb = sys.argv[1:5]
truth, fitted = load_body(f"makehuman:{mh}", subject), load_body(glb)
fit, true = json.load(open(fit_file)), body_measures(truth)
print(json.dumps({"subject": subject, "true_height_m": true["height_m"], "height_m": fit["height_m"],
                  "height_error_cm": round(100 * (fit["height_m"] - true["height_m"]), 2),
                  "true_volume_l": true["volume_l"], "volume_l": fit["volume_l"],
                  "volume_error_pct": round(100 * (fit["volume_l"] / true["volume_l"] - 1), 2),
                  "vertex_mm": round(1000 * float(np.linalg.norm(fitted.vertices - truth.vertices, axis=1).mean()), 1),
                  "parameters": fit["parameters"], "seconds": fit["seconds"]}))
PYEOF
  cat "$OUT/$name.json"
done
