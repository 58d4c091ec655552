"""The same recording, seed and settings give byte-identical poses on the same machine (issue 53).

Oracle: the first run. Two runs in this process, each with its own tracker (nothing of the first
carries into the second but what a process shares: compiled kernels, caches); the only fields
allowed to differ are the wall-clock ones the protocol defines as such.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import swarmpose
from swarmpose.cli.main import main

WALL_CLOCK = ("received_ns", "publish_ns", "latency_ms", "timings_ms")
"""Frame-message fields that say when and how fast, not what: they differ from run to run."""


def _poses(wave_sequence) -> list[list[tuple]]:
    """Per frame, per body: id, state and the raw bytes of the float64 pose (36,) and joints (J, 3)."""
    return [[(b.id, b.state, np.asarray(b.pose, dtype=np.float64).tobytes(),
              np.asarray(b.joints3d, dtype=np.float64).tobytes()) for b in result.bodies]
            for result in swarmpose.track(f"folder:{wave_sequence}", frames=3, particles=16, generations=12)]


def test_two_runs_of_the_api_give_byte_identical_poses(wave_sequence):
    first = _poses(wave_sequence)
    assert len(first) == 3 and all(frame for frame in first)
    assert _poses(wave_sequence) == first


@pytest.mark.slow
def test_two_runs_of_track_with_default_settings_write_the_same_files(wave_sequence, tmp_path):
    """`swarmpose track` twice with every default (the search, the starts' facings, the polish):
    poses.bvh byte for byte, poses.jsonl and poses.csv but for the wall-clock fields."""
    runs = [tmp_path / "first", tmp_path / "second"]
    for out in runs:
        assert main(["track", str(wave_sequence), "--out", str(out), "--no-overlay", "-q"]) == 0
    assert (runs[0] / "poses.bvh").read_bytes() == (runs[1] / "poses.bvh").read_bytes()

    def what(out) -> list[dict]:
        messages = [json.loads(line) for line in (out / "poses.jsonl").read_text().splitlines()]
        return [{k: v for k, v in m.items() if k not in WALL_CLOCK} for m in messages]

    assert what(runs[0]) == what(runs[1]) and len(what(runs[0])) == 6

    def rows(out) -> list[list[str]]:
        lines = [line.split(",") for line in (out / "poses.csv").read_text().splitlines()]
        keep = [k for k, name in enumerate(lines[0]) if name not in WALL_CLOCK]
        return [[row[k] for k in keep] for row in lines]

    assert rows(runs[0]) == rows(runs[1])
