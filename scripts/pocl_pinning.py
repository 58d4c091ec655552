"""Does pinning PoCL's worker threads (``POCL_AFFINITY=1``) steady the scorer's speed?

Runs ``--processes`` fresh processes per setting (POCL_AFFINITY 0 and 1, alternating); each
builds the ``bench score`` scene's scorer and times ``--windows`` windows of ``--launches``
launches (median kernel time per window, OpenCL event times). A window is "slow" when its
median exceeds 1.5x the median of every window of both settings. Prints the windows and the
count of slow ones per setting.

    .venv/bin/python scripts/pocl_pinning.py [--processes 8] [--windows 8] [--launches 40]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

import numpy as np

CHILD = """
import json, sys
import numpy as np
from swarmpose.bench.score import _scene
from swarmpose.body.loader import load_body
from swarmpose.core.camera import Intrinsics
from swarmpose.gpu.scorer import ParticleScorer
from swarmpose.gpu.tile import box_around
windows, launches = int(sys.argv[1]), int(sys.argv[2])
intr = Intrinsics.kinect_v1()
model = load_body("builtin", None).tracking_lod(1500)
h_true, h, depth = _scene(model, np.random.default_rng(0), 64, intr)
scorer = ParticleScorer(model, intr, (64, 64))
scorer.set_observation(depth, box_around(intr.project(model.pose(h_true[None])[0]), margin=0.15))
out = []
for _ in range(windows):
    times = []
    for _ in range(launches):
        scorer.evaluate(h, points=False)
        times.append(scorer.last_timings["kernel_s"])
    out.append(1e3 * float(np.median(times)))
print(json.dumps(out))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--processes", type=int, default=8)
    ap.add_argument("--windows", type=int, default=8)
    ap.add_argument("--launches", type=int, default=40)
    args = ap.parse_args()
    runs: dict[str, list[list[float]]] = {"0": [], "1": []}
    for _ in range(args.processes):
        for pin in runs:
            env = {**os.environ, "POCL_AFFINITY": pin}
            done = subprocess.run([sys.executable, "-c", CHILD, str(args.windows), str(args.launches)], env=env,
                                  capture_output=True, text=True, check=True)
            runs[pin].append(json.loads(done.stdout.strip().splitlines()[-1]))
    typical = float(np.median([w for windows in runs.values() for run in windows for w in run]))
    for pin, windows in runs.items():
        slow = sum(w > 1.5 * typical for run in windows for w in run)
        print(f"POCL_AFFINITY={pin}: {slow} of {sum(len(r) for r in windows)} windows slow "
              f"(> {1.5 * typical:.2f} ms; typical {typical:.2f} ms)")
        for run in windows:
            print("   " + " ".join(f"{w:.2f}" for w in run))


if __name__ == "__main__":
    main()
