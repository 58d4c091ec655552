"""How many frames UTD-MHAD's depth trails its Kinect skeleton, measured on the data alone.

Usage: .venv/bin/python scripts/utdmhad_lag.py [ASSETS]   (default: $SWARMPOSE_ASSETS or ../shared/assets)

For every depth file of subjects s1-s3 and trial lags from -1 to 4 frames (quarter steps), the
mean disagreement between the skeleton at ``t - lag`` and the depth under its moving joints
(:func:`swarmpose.sources.utdmhad_sync.depth_agreement_mm`), per subject and over all; prints
each curve and its best lag. BENCHMARKS.md and :mod:`swarmpose.sources.utdmhad_sync` quote it.
"""

from __future__ import annotations

import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

from swarmpose.bench.detect import find_assets
from swarmpose.bench.utdmhad import sequences
from swarmpose.sources.utdmhad import KINECT_JOINTS, UtdMhadSource
from swarmpose.sources.utdmhad_sync import AGREEMENT_JOINTS, depth_agreement_mm

LAGS = np.arange(-1.0, 4.01, 0.25)


def main(assets: Path) -> None:
    files = sequences(assets)  # subjects s1-s3, every action; ConfigError when there are none
    joints = [KINECT_JOINTS.index(j) for j in AGREEMENT_JOINTS]
    curves = defaultdict(list)
    for path in files:
        source = UtdMhadSource(path)
        curve = depth_agreement_mm(source.depth, source.skeleton, joints, source.intrinsics, LAGS)
        subject = path.name.split("_")[1]
        curves[subject].append(curve)
        curves["all"].append(curve)
    for name in sorted(curves):
        mean = np.mean(curves[name], axis=0)  # mean of the sequences' means
        print(f"{name}: best lag {LAGS[int(np.argmin(mean))]:.2f} frames; "
              + " ".join(f"{lag:g}:{value:.1f}" for lag, value in zip(LAGS, mean)))


if __name__ == "__main__":
    main(find_assets(sys.argv[1] if len(sys.argv) > 1 else None))
