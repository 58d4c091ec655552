"""Bad-input sweep (issue 16): every command of the real CLI on broken inputs, as a Markdown table.

usage: .venv/bin/python scripts/bad_input_sweep.py [--out docs/bad-input.md] [--only WORD ...] [--jobs N]
       [--work DIR] [--timeout S]

Each case is built in a temporary folder from a small valid synthetic sequence (``swarmpose synth``,
a few frames) and every command it concerns runs in a subprocess (``python -m swarmpose``) with a
small search (16 particles, 8 generations) so each run takes seconds. A row records the case, the
command, the exit status, the first line of the message, whether a traceback was printed and the
verdict:

* ``error`` — the run refused the input with exit status != 0 and a message naming it;
* ``skipped, named`` — the run went on past a damaged frame and its output names the file;
* ``warned`` — the run went on and a warning says what is wrong with the input;
* ``ok`` — a valid or harmless input ran (a control);
* ``TRACEBACK`` / ``SILENT SUCCESS`` (exit 0 having done nothing useful without saying so) /
  ``UNNAMED`` (refused, but the message does not name the input) / ``HANG`` (no exit within the
  timeout) — a failure of the sweep, to be fixed.

Mid-run cases (``track``, ``replay`` and ``serve --record`` stopped by SIGTERM or SIGKILL after a
few frames) add what stayed readable: poses.jsonl lines that parse, poses.csv rows, BVH frames
read back with :func:`swarmpose.motion.bvh.read_bvh`, and overlay.mp4 frames decoded with PyAV.

The exit status is 1 when any row failed, so the sweep can gate a change.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

FRAMES = 4
"""Frames of the base sequence of the per-file cases."""
KILL_FRAMES = 40
"""Frames of the sequence the mid-run cases stop after a few frames of."""
FAST = ("--particles", "16", "--generations", "8", "--start-budget", "16")
"""A small search: each run takes seconds."""
SOURCE_COMMANDS = ("track", "eval", "replay", "serve", "probe", "personalize")
FAIL = ("TRACEBACK", "SILENT SUCCESS", "UNNAMED", "HANG", "UNREADABLE")


# -- building cases ---------------------------------------------------------------------------------


def write_png(path: Path, image: np.ndarray) -> None:
    """Write ``image`` (uint8 or uint16, (H, W) or (H, W, 3)) as a PNG."""
    if not cv2.imwrite(str(path), image):
        raise OSError(f"cannot write {path}")


def garbage(path: Path, size: int = 4096, seed: int = 0) -> None:
    """``size`` random bytes into ``path`` (0: an empty file)."""
    path.write_bytes(np.random.default_rng(seed).integers(0, 256, size, dtype=np.uint8).tobytes())


def depth_files(seq: Path) -> list[Path]:
    return sorted((seq / "depth").glob("*.png"))


def set_intrinsics(seq: Path, text: str) -> None:
    (seq / "intrinsic.json").write_text(text)


def intrinsics_with(seq: Path, **changes) -> None:
    data = json.loads((seq / "intrinsic.json").read_text())
    matrix = data["intrinsic_matrix"]
    for key, value in changes.items():
        if key == "fx":
            matrix[0] = value
        elif key == "drop":
            data.pop(value)
        else:
            data[key] = value
    set_intrinsics(seq, json.dumps(data, allow_nan=True))


def every_depth(seq: Path, make: Callable[[np.ndarray], np.ndarray]) -> None:
    for path in depth_files(seq):
        write_png(path, make(cv2.imread(str(path), cv2.IMREAD_UNCHANGED)))


def break_groundtruth_line(seq: Path, line: int, text: str | None) -> None:
    """Replace line ``line`` (1-based) of groundtruth.jsonl by ``text``; None truncates that line
    halfway and drops the rest (a synth killed while writing)."""
    path = seq / "groundtruth.jsonl"
    lines = path.read_text().splitlines()
    if text is None:
        path.write_text("\n".join(lines[:line - 1] + [lines[line - 1][: len(lines[line - 1]) // 2]]))
    else:
        lines[line - 1] = text
        path.write_text("\n".join(lines) + "\n")


@dataclass(frozen=True)
class Case:
    """One bad input. ``build(base, dir)`` makes it in ``dir`` from the valid ``base`` sequence
    (a copy of it lies in ``dir / "seq"``) and returns the source argument (or None for cases
    that do not take one). ``runs``: (command, argv after ``swarmpose``) pairs, with ``{src}``,
    ``{out}`` and ``{dir}`` substituted. ``expect``: "error" (refuse), "skip" (go on past the
    damaged frame, naming it), "warn" (go on, saying what is wrong), "ok" (a control that must
    run). ``names``: a text the output must contain (``a|b``: one of them; the table shows the
    first line of the message)."""

    name: str
    what: str
    build: Callable[[Path], str | None]
    expect: str
    names: str
    runs: tuple[tuple[str, tuple[str, ...]], ...] = ()
    env: dict[str, str] = field(default_factory=dict)


def source_runs(*commands: str) -> tuple[tuple[str, tuple[str, ...]], ...]:
    """The argv of each source command on ``{src}``."""
    argv = {
        "track": ("track", "{src}", "--out", "{out}", *FAST),
        "eval": ("eval", "{src}", *FAST),
        "replay": ("replay", "{src}", "--out", "{out}", *FAST),
        "serve": ("serve", "{src}", "--zenoh-mode", "off", *FAST),
        "probe": ("probe", "--source", "{src}"),
        "personalize": ("personalize", "{src}", "--out", "{dir}/me.glb", "--frames", str(FRAMES), "--keyframes",
                        "2", "--rounds", "1", *FAST),
    }
    return tuple((c, argv[c]) for c in (commands or SOURCE_COMMANDS))


def seq_case(name: str, what: str, change: Callable[[Path], None], expect: str, names: str,
             commands: tuple[str, ...] = (), src: Callable[[Path], str] | None = None) -> Case:
    """A case that damages the copied sequence ``dir/seq`` and runs the source commands on it."""
    def build(d: Path) -> str:
        change(d / "seq")
        return src(d) if src else str(d / "seq")
    return Case(name, what, build, expect, names, source_runs(*commands))


def file_case(name: str, what: str, suffix: str, size: int, names: str, scheme: str = "") -> Case:
    """A recording file of ``size`` random bytes (0: empty) read as ``suffix``."""
    def build(d: Path) -> str:
        path = d / f"recording{suffix}"
        garbage(path, size)
        return f"{scheme}{path}"
    return Case(name, what, build, "error", names, source_runs())


def no_source(d: Path) -> None:
    return None


def flag_case(name: str, what: str, command: str, argv: tuple[str, ...], names: str, expect: str = "error",
              env: dict | None = None, prepare: Callable[[Path], None] | None = None) -> Case:
    """A nonsense flag value, TOML file or environment variable on the valid sequence."""
    def build(d: Path) -> str:
        if prepare:
            prepare(d)
        return str(d / "seq")
    return Case(name, what, build, expect, names, ((command, argv),), env or {})


def toml(text: str) -> Callable[[Path], None]:
    def prepare(d: Path) -> None:
        (d / "settings.toml").write_text(text)
    return prepare


def status_file(text: str) -> Callable[[Path], None]:
    def prepare(d: Path) -> None:
        (d / "status.json").write_text(text)
    return prepare


def cases() -> list[Case]:
    """Every case of the sweep."""
    def one_depth(index: int, make: Callable[[Path], None]) -> Callable[[Path], None]:
        return lambda seq: make(depth_files(seq)[index])

    out = [
        seq_case("valid", "the valid synthetic sequence (control)", lambda seq: None, "ok", ""),
        seq_case("corrupt-depth-png", "depth/000002.png is 4 KiB of random bytes", one_depth(2, garbage),
                 "skip", "000002.png"),
        seq_case("corrupt-first-depth", "depth/000000.png (the first frame) is random bytes", one_depth(0, garbage),
                 "skip", "000000.png"),
        seq_case("empty-depth-png", "depth/000002.png is empty (0 bytes)", one_depth(2, lambda p: garbage(p, 0)),
                 "skip", "000002.png"),
        seq_case("empty-color-png", "color/000001.png is empty (0 bytes)",
                 lambda seq: garbage(seq / "color" / "000001.png", 0), "skip", "000001.png"),
        seq_case("missing-depth-png", "depth/000002.png deleted", one_depth(2, Path.unlink), "skip", "000002.png"),
        seq_case("wrong-size-depth", "depth/000002.png is 320x240 (the others and the intrinsics 640x480)",
                 one_depth(2, lambda p: write_png(p, np.full((240, 320), 3000, np.uint16))), "skip", "000002.png"),
        seq_case("wrong-size-all", "every depth and colour image 320x240, intrinsics 640x480",
                 lambda seq: [write_png(p, cv2.resize(cv2.imread(str(p), cv2.IMREAD_UNCHANGED), (320, 240),
                                                      interpolation=cv2.INTER_NEAREST))
                              for p in (*depth_files(seq), *sorted((seq / "color").glob("*.png")))],
                 "error", "intrinsic"),
        seq_case("8bit-depth-one", "depth/000001.png 8-bit (depth / 20)",
                 one_depth(1, lambda p: write_png(p, (cv2.imread(str(p), cv2.IMREAD_UNCHANGED) // 20)
                                                  .astype(np.uint8))), "skip", "000001.png"),
        seq_case("8bit-depth-all", "every depth PNG 8-bit (an 8-bit export of the depth)",
                 lambda seq: every_depth(seq, lambda d: (d // 20).astype(np.uint8)), "error", "depth"),
        seq_case("rgb-depth", "every depth PNG 3-channel 16-bit", lambda seq: every_depth(
                 seq, lambda d: np.repeat(d[:, :, None], 3, axis=2)), "error", "depth"),
        seq_case("depth-all-zero", "every depth pixel 0 (no measurement)",
                 lambda seq: every_depth(seq, np.zeros_like), "warn", "no valid"),
        seq_case("depth-all-max", "every depth pixel 65535 (65.5 m: a sensor's saturated value)",
                 lambda seq: every_depth(seq, lambda d: np.full_like(d, 65535)), "warn",
                 "nobody|no person|tracker none|65.535"),
        seq_case("intrinsics-fx0", "intrinsic.json fx = 0", lambda seq: intrinsics_with(seq, fx=0.0),
                 "error", "intrinsic.json"),
        seq_case("intrinsics-nan", "intrinsic.json fx = NaN", lambda seq: intrinsics_with(seq, fx=float("nan")),
                 "error", "intrinsic.json"),
        seq_case("intrinsics-inf-cx", "intrinsic.json cx = Infinity",
                 lambda seq: set_intrinsics(seq, '{"width": 640, "height": 480, "fx": 525, "fy": 525, '
                                                 '"cx": Infinity, "cy": 239.5}'), "error", "intrinsic.json"),
        seq_case("intrinsics-missing-key", "intrinsic.json without height",
                 lambda seq: intrinsics_with(seq, drop="height"), "error", "intrinsic.json"),
        seq_case("intrinsics-string-width", "intrinsic.json width \"wide\"",
                 lambda seq: intrinsics_with(seq, width="wide"), "error", "intrinsic.json"),
        seq_case("intrinsics-not-json", "intrinsic.json is not JSON",
                 lambda seq: set_intrinsics(seq, "fx: 525\n"), "error", "intrinsic.json"),
        seq_case("intrinsics-list", "intrinsic.json holds a JSON list", lambda seq: set_intrinsics(seq, "[1, 2]"),
                 "error", "intrinsic.json"),
        seq_case("intrinsics-missing", "intrinsic.json deleted", lambda seq: (seq / "intrinsic.json").unlink(),
                 "error", "intrinsic.json"),
        seq_case("groundtruth-garbage-line", "groundtruth.jsonl line 3 is 'garbage'",
                 lambda seq: break_groundtruth_line(seq, 3, "garbage"), "error", "groundtruth.jsonl:3"),
        seq_case("groundtruth-truncated", "groundtruth.jsonl cut halfway through line 2 (a killed synth)",
                 lambda seq: break_groundtruth_line(seq, 2, None), "error", "groundtruth.jsonl:2"),
        seq_case("groundtruth-short-pose", "groundtruth.jsonl line 1 has a pose of 3 numbers",
                 lambda seq: break_groundtruth_line(seq, 1, '{"frame": 0, "pose": [0, 0, 3]}'), "error",
                 "groundtruth.jsonl:1"),
        seq_case("groundtruth-empty", "groundtruth.jsonl is empty (0 bytes)",
                 lambda seq: (seq / "groundtruth.jsonl").write_text(""), "error", "ground truth", ("eval",)),
        seq_case("sequence-json-broken", "sequence.json is not JSON",
                 lambda seq: (seq / "sequence.json").write_text("{"), "error", "sequence.json"),
        seq_case("sequence-fps-0", "sequence.json fps = 0", lambda seq: (seq / "sequence.json").write_text(
                 json.dumps({**json.loads((seq / "sequence.json").read_text()), "fps": 0})), "error", "fps"),
        seq_case("empty-folder", "an empty folder", lambda seq: [shutil.rmtree(seq), seq.mkdir()], "error", "seq"),
        seq_case("no-images", "color/ and depth/ exist but hold no images",
                 lambda seq: [p.unlink() for p in (*depth_files(seq), *(seq / "color").glob("*.png"))],
                 "error", "no images"),
        seq_case("missing-folder", "a folder that does not exist", lambda seq: shutil.rmtree(seq), "error", "seq"),
        seq_case("still-corrupt", "rgbd:C,D,K with a corrupt depth PNG",
                 one_depth(0, garbage), "error", "000000.png", ("track", "replay", "probe"),
                 src=lambda d: f"rgbd:{d}/seq/color/000000.png,{d}/seq/depth/000000.png,{d}/seq/intrinsic.json"),
        file_case("garbage-mkv", "recording.mkv of 4 KiB random bytes", ".mkv", 4096, "recording.mkv"),
        file_case("empty-mkv", "recording.mkv empty (0 bytes)", ".mkv", 0, "recording.mkv"),
        file_case("garbage-bag", "recording.bag of 4 KiB random bytes", ".bag", 4096, "recording.bag"),
        file_case("empty-bag", "recording.bag empty (0 bytes)", ".bag", 0, "recording.bag"),
        file_case("garbage-oni", "recording.oni of 4 KiB random bytes", ".oni", 4096, "recording.oni"),
        file_case("empty-oni", "recording.oni empty (0 bytes)", ".oni", 0, "recording.oni"),
        file_case("garbage-mat", "a UTD-MHAD a1_s1_t1_depth.mat of random bytes", "_depth.mat", 4096, "depth.mat"),
        Case("missing-mkv", "mkv:missing.mkv", lambda d: f"mkv:{d}/missing.mkv", "error", "missing.mkv",
             source_runs("track", "probe")),
        Case("unknown-scheme", "--source nonsense:foo", lambda d: "nonsense:foo", "error", "nonsense",
             source_runs("track", "probe")),
    ]
    replay = ("replay", "{src}", "--out", "{out}", *FAST)
    track = ("track", "{src}", "--out", "{out}", *FAST)
    out += [
        flag_case("toml-syntax", "--config: a TOML syntax error", "replay",
                  (*replay, "--config", "{dir}/settings.toml"), "settings.toml", prepare=toml("particles = = 3\n")),
        flag_case("toml-unknown-key", "--config: an unknown key", "replay",
                  (*replay, "--config", "{dir}/settings.toml"), "particels", prepare=toml("particels = 3\n")),
        flag_case("toml-wrong-type", "--config: particles = \"many\"", "track",
                  (*track, "--config", "{dir}/settings.toml"), "particles", prepare=toml('particles = "many"\n')),
        flag_case("toml-out-of-range", "--config: [tracker] generations = 0", "serve",
                  ("serve", "{src}", "--zenoh-mode", "off", "--config", "{dir}/settings.toml"), "generations",
                  prepare=toml("[tracker]\ngenerations = 0\n")),
        flag_case("toml-missing", "--config a file that does not exist", "replay",
                  (*replay, "--config", "{dir}/none.toml"), "none.toml"),
        flag_case("toml-binary", "--config a file of random bytes", "replay", (*replay, "--config", "{dir}/bin.toml"),
                  "bin.toml", prepare=lambda d: garbage(d / "bin.toml")),
        flag_case("env-bad-int", "SWARMPOSE_PARTICLES=abc", "track", track, "SWARMPOSE_PARTICLES",
                  env={"SWARMPOSE_PARTICLES": "abc"}),
        flag_case("env-config-missing", "SWARMPOSE_CONFIG names a missing file", "replay", replay, "gone.toml",
                  env={"SWARMPOSE_CONFIG": "/nonexistent/gone.toml"}),
        flag_case("particles-negative", "--particles -5", "replay", (*replay, "--particles", "-5"), "particles"),
        flag_case("particles-zero", "--particles 0", "track", (*track, "--particles", "0"), "particles"),
        flag_case("generations-text", "--generations many", "replay", (*replay, "--generations", "many"),
                  "generations"),
        flag_case("tile-0x0", "--tile 0x0", "replay", (*replay, "--tile", "0x0"), "tile"),
        flag_case("tile-text", "--tile big", "track", (*track, "--tile", "big"), "tile"),
        flag_case("threshold-nan", "--threshold-m nan", "replay", (*replay, "--threshold-m", "nan"), "threshold"),
        flag_case("alpha-2", "--alpha 2", "replay", (*replay, "--alpha", "2"), "alpha"),
        flag_case("smoothing-cutoff-negative", "--smoothing one-euro --smoothing-cutoff-hz -1", "replay",
                  (*replay, "--smoothing", "one-euro", "--smoothing-cutoff-hz", "-1"), "cutoff"),
        flag_case("mode-unknown", "--mode fast", "track", (*track, "--mode", "fast"), "mode"),
        flag_case("detector-unknown", "--detector nonsense", "replay", (*replay, "--detector", "nonsense"),
                  "nonsense"),
        flag_case("detector-missing-onnx", "--detector onnx:missing.onnx", "track",
                  (*track, "--detector", "onnx:{dir}/missing.onnx"), "missing.onnx"),
        flag_case("detector-garbage-onnx", "--detector onnx:garbage.onnx (random bytes)", "track",
                  (*track, "--detector", "onnx:{dir}/garbage.onnx"), "garbage.onnx",
                  prepare=lambda d: garbage(d / "garbage.onnx")),
        flag_case("body-unknown", "--body nonsense", "replay", (*replay, "--body", "nonsense"), "nonsense"),
        flag_case("body-missing-glb", "--body missing.glb", "track", (*track, "--body", "{dir}/missing.glb"),
                  "missing.glb"),
        flag_case("body-garbage-glb", "--body garbage.glb (random bytes)", "track",
                  (*track, "--body", "{dir}/garbage.glb"), "garbage.glb", prepare=lambda d: garbage(d / "garbage.glb")),
        flag_case("shape-unknown", "--shape nonsense", "replay", (*replay, "--shape", "nonsense"), "nonsense"),
        flag_case("shape-negative", "--shape height=-1", "track", (*track, "--shape", "height=-1"), "height"),
        flag_case("frames-negative", "--frames -1", "replay", (*replay, "--frames", "-1"), "frames"),
        flag_case("rate-negative", "--rate -1", "serve", ("serve", "{src}", "--zenoh-mode", "off", "--rate", "-1"),
                  "rate"),
        flag_case("camera-id-slash", "--camera-id a/b", "replay", (*replay, "--camera-id", "a/b"), "a/b"),
        flag_case("device-unknown", "--device nonsense", "track", (*track, "--device", "nonsense"), "nonsense"),
        flag_case("max-people-zero", "--max-people 0", "track", (*track, "--max-people", "0"), "max"),
        flag_case("personalize-2", "--personalize 2 (below 3)", "replay", (*replay, "--personalize", "2"),
                  "personalize"),
        flag_case("two-sources", "SEQ and a different --source", "track", (*track, "--source", "{dir}/other"),
                  "two sources"),
        flag_case("no-source", "serve without a source", "serve", ("serve", "--zenoh-mode", "off"), "source"),
        flag_case("out-is-file", "--out names an existing file", "replay",
                  ("replay", "{src}", "--out", "{dir}/afile", *FAST), "afile",
                  prepare=lambda d: (d / "afile").write_text("x")),
        flag_case("out-unwritable", "--out under /proc (not writable)", "track",
                  ("track", "{src}", "--out", "/proc/swarmpose-out", *FAST), "/proc/swarmpose-out"),
        flag_case("zenoh-bad-endpoint", "--zenoh-mode client --connect garbage", "serve",
                  ("serve", "{src}", "--zenoh-mode", "client", "--connect", "garbage", *FAST), "garbage"),
        flag_case("zenoh-config-missing", "--zenoh-config missing.json5", "serve",
                  ("serve", "{src}", "--zenoh-mode", "peer", "--zenoh-config", "{dir}/missing.json5", *FAST),
                  "missing.json5"),
        flag_case("zenoh-config-garbage", "--zenoh-config garbage.json5 (random bytes)", "serve",
                  ("serve", "{src}", "--zenoh-mode", "peer", "--zenoh-config", "{dir}/garbage.json5", *FAST),
                  "garbage.json5", prepare=lambda d: garbage(d / "garbage.json5")),
        flag_case("health-file-zero-status", "--status-period-s 0", "serve",
                  ("serve", "{src}", "--zenoh-mode", "off", "--status-period-s", "0"), "status"),
        flag_case("probe-frames-negative", "probe --frames -3", "probe",
                  ("probe", "--source", "{src}", "--frames", "-3"), "frames"),
        flag_case("probe-detector-unknown", "probe --detector nonsense", "probe",
                  ("probe", "--source", "{src}", "--detector", "nonsense"), "nonsense"),
        flag_case("personalize-out-txt", "personalize --out me.txt", "personalize",
                  ("personalize", "{src}", "--out", "{dir}/me.txt"), "me.txt"),
        flag_case("personalize-out-nodir", "personalize --out into a missing folder", "personalize",
                  ("personalize", "{src}", "--out", "{dir}/nodir/me.glb"), "nodir"),
        flag_case("personalize-frames-0", "personalize --frames 0", "personalize",
                  ("personalize", "{src}", "--out", "{dir}/me.glb", "--frames", "0"), "frames"),
        flag_case("health-no-file", "health --file missing.json", "health", ("health", "--file", "{dir}/missing.json"),
                  "missing.json"),
        flag_case("health-garbage", "health --file of random bytes", "health",
                  ("health", "--file", "{dir}/status.json"), "status.json",
                  prepare=lambda d: garbage(d / "status.json")),
        flag_case("health-stale", "health: a status 1 hour old", "health", ("health", "--file", "{dir}/status.json"),
                  "old", prepare=status_file(json.dumps({"time_ns": time.time_ns() - 3600 * 10**9,
                                                        "state": "running", "source": {"state": "running"},
                                                        "fps": 1.0}))),
        flag_case("health-wrong-types", "health: a status with time_ns \"x\"", "health",
                  ("health", "--file", "{dir}/status.json"), "status.json",
                  prepare=status_file('{"time_ns": "x", "state": 3}')),
        flag_case("health-max-age-negative", "health --max-age -1", "health",
                  ("health", "--file", "{dir}/status.json", "--max-age", "-1"), "max-age",
                  prepare=status_file("{}")),
        flag_case("subscribe-count-negative", "subscribe --count -1", "subscribe",
                  ("subscribe", "--count", "-1", "--timeout", "1"), "count"),
        flag_case("subscribe-timeout-negative", "subscribe --timeout -1", "subscribe",
                  ("subscribe", "--timeout", "-1", "--count", "1"), "timeout"),
        flag_case("subscribe-bad-endpoint", "subscribe --mode client --connect garbage", "subscribe",
                  ("subscribe", "--mode", "client", "--connect", "garbage", "--timeout", "1"), "garbage"),
        flag_case("subscribe-config-missing", "subscribe --zenoh-config missing.json5", "subscribe",
                  ("subscribe", "--zenoh-config", "{dir}/missing.json5", "--timeout", "1"), "missing.json5"),
        flag_case("synth-frames-0", "synth --frames 0", "synth",
                  ("synth", "--motion", "builtin:wave", "--frames", "0", "--out", "{dir}/s"), "frames"),
        flag_case("synth-frames-negative", "synth --frames -1", "synth",
                  ("synth", "--motion", "builtin:wave", "--frames", "-1", "--out", "{dir}/s"), "frames"),
        flag_case("synth-motion-missing", "synth --motion missing.bvh", "synth",
                  ("synth", "--motion", "{dir}/missing.bvh", "--frames", "2", "--out", "{dir}/s"), "missing.bvh"),
        flag_case("synth-motion-garbage", "synth --motion garbage.bvh (random bytes)", "synth",
                  ("synth", "--motion", "{dir}/garbage.bvh", "--frames", "2", "--out", "{dir}/s"), "garbage.bvh",
                  prepare=lambda d: garbage(d / "garbage.bvh")),
        flag_case("synth-motion-unknown", "synth --motion builtin:fly", "synth",
                  ("synth", "--motion", "builtin:fly", "--frames", "2", "--out", "{dir}/s"), "fly"),
        flag_case("synth-distance-0", "synth --camera-distance 0", "synth",
                  ("synth", "--motion", "builtin:wave", "--frames", "2", "--camera-distance", "0", "--out",
                   "{dir}/s"), "distance"),
        flag_case("synth-fps-0", "synth --fps 0", "synth",
                  ("synth", "--motion", "builtin:wave", "--frames", "2", "--fps", "0", "--out", "{dir}/s"), "fps"),
        flag_case("synth-out-file", "synth --out names an existing file", "synth",
                  ("synth", "--motion", "builtin:wave", "--frames", "2", "--out", "{dir}/afile"), "afile",
                  prepare=lambda d: (d / "afile").write_text("x")),
        flag_case("synth-scene-garbage", "synth --scene of random bytes", "synth",
                  ("synth", "--scene", "{dir}/scene.json", "--frames", "2", "--out", "{dir}/s"), "scene.json",
                  prepare=lambda d: garbage(d / "scene.json")),
        flag_case("synth-person-bad", "synth --person nonsense", "synth",
                  ("synth", "--person", "nonsense", "--frames", "2", "--out", "{dir}/s"), "nonsense"),
        flag_case("body-lod-negative", "body --lod -5", "body", ("body", "--lod", "-5"), "-5"),
        flag_case("body-glb-garbage", "body --body garbage.glb", "body", ("body", "--body", "{dir}/garbage.glb"),
                  "garbage.glb", prepare=lambda d: garbage(d / "garbage.glb")),
        flag_case("body-export-nodir", "body --export into a missing folder (it is created)", "body",
                  ("body", "--export", "{dir}/nodir/b.glb"), "", expect="ok"),
        flag_case("demo-frames-negative", "demo --frames -1", "demo", ("demo", "--frames", "-1", "--out", "{dir}/d"),
                  "frames"),
        flag_case("demo-particles-0", "demo --particles 0", "demo", ("demo", "--particles", "0", "--out", "{dir}/d"),
                  "particles"),
    ]
    return out


# -- running and judging ----------------------------------------------------------------------------


@dataclass
class Row:
    case: str
    what: str
    command: str
    status: int | None
    message: str
    traceback: bool
    verdict: str


_PROGRESS = re.compile(r"^.*?\d+%\|[^\]]*\]")
"""A progress bar (``track:  50%|#####     | 2/4 [00:01<00:01, 2.0frame/s]``) at the start of a line."""


def first_message(stdout: str, stderr: str, status: int | None) -> str:
    """The line a user reads first: the error line, else the first warning, else stdout's first line."""
    lines = [ln.strip() for text in (stderr,) for part in text.splitlines() for ln in part.split("\r")]
    lines = [_PROGRESS.sub("", ln).strip() for ln in lines]  # a warning may follow a progress bar on its line
    lines = [ln for ln in lines if ln]
    for pattern in (r"^swarmpose( \w+)?: error:", r"^Traceback", r"^unhealthy:", r"frame \d+ skipped:",
                    r"nobody was tracked|no valid pixels|ended with an error", r"(?i)warning|skipped|error|cannot"):
        hit = next((ln for ln in lines if re.search(pattern, ln)), None)
        if hit:
            if hit.startswith("Traceback"):
                return next((ln for ln in reversed(lines) if re.match(r"^\w+(\.\w+)*(Error|Exception)", ln)), hit)
            return hit
    out = [ln.strip() for ln in stdout.splitlines() if ln.strip()]
    return (out or lines or [""])[0]


def judge(case: Case, status: int | None, message: str, stdout: str, stderr: str) -> str:
    """The verdict of one run (see the module docstring)."""
    if status is None:
        return "HANG"
    if "Traceback (most recent call last)" in stderr:
        return "TRACEBACK"
    named = any(name.lower() in (stdout + stderr).lower() for name in case.names.split("|"))
    if case.expect == "ok":
        return "ok" if status == 0 else "FAILED CONTROL"
    if case.expect == "warn":
        return "warned" if named else ("SILENT SUCCESS" if status == 0 else "UNNAMED")
    if case.expect == "skip":
        if named:
            return "skipped, named"
        return "SILENT SUCCESS" if status == 0 else ("error" if named else "UNNAMED")
    if status == 0:
        return "SILENT SUCCESS"
    return "error" if named else "UNNAMED"


def swarmpose(argv: list[str], env: dict[str, str], timeout: float, cwd: Path) -> tuple[int | None, str, str]:
    """Run ``python -m swarmpose argv``; (exit status or None on timeout, stdout, stderr)."""
    try:
        done = subprocess.run([sys.executable, "-m", "swarmpose", *argv], capture_output=True, text=True,
                              env=env, timeout=timeout, cwd=cwd, errors="replace")
    except subprocess.TimeoutExpired as exc:
        text = (exc.stderr or b"").decode(errors="replace") if isinstance(exc.stderr, bytes) else (exc.stderr or "")
        return None, "", text
    return done.returncode, done.stdout, done.stderr


def base_env() -> dict[str, str]:
    """The environment of every run: no SWARMPOSE_* from the caller, no colour, no rerun viewer."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("SWARMPOSE_")}
    env.update({"PYTHONUNBUFFERED": "1", "NO_COLOR": "1", "TQDM_DISABLE": "1"})
    return env


def run_case(case: Case, base: Path, work: Path, timeout: float) -> list[Row]:
    """Build ``case`` in its own folder under ``work`` and run each of its commands."""
    d = work / case.name
    shutil.rmtree(d, ignore_errors=True)
    d.mkdir(parents=True)
    shutil.copytree(base, d / "seq")
    src = case.build(d)
    rows = []
    for command, template in case.runs:
        out = d / f"out-{command}"
        argv = [a.format(src=src or "", out=out, dir=d) for a in template]
        status, stdout, stderr = swarmpose(argv, {**base_env(), **case.env}, timeout, d)
        message = first_message(stdout, stderr, status).replace(str(d), "$CASE")
        rows.append(Row(case.name, case.what, command, status, message,
                        "Traceback (most recent call last)" in stderr,
                        judge(case, status, message, stdout, stderr)))
        log = d / f"{command}.log"
        log.write_text(f"$ swarmpose {' '.join(argv)}\nexit {status}\n--- stdout\n{stdout}\n--- stderr\n{stderr}")
    return rows


# -- stopping a run halfway -------------------------------------------------------------------------


@dataclass
class KillRow:
    command: str
    signal: str
    status: int | None
    frames_before: int
    jsonl: str
    csv: str
    bvh: str
    overlay: str
    verdict: str


def jsonl_state(path: Path) -> tuple[str, bool]:
    """'N lines parse' (+ a torn last line); ok when every complete line parses."""
    if not path.is_file():
        return "missing", False
    data = path.read_bytes()
    lines = data.split(b"\n")
    torn = lines.pop() if lines else b""
    parsed = bad = 0
    for line in lines:
        try:
            json.loads(line)
            parsed += 1
        except ValueError:
            bad += 1
    text = f"{parsed} lines parse" + (f", {bad} do not" if bad else "") + (", last line torn" if torn else "")
    return text, bad == 0 and parsed > 0


def csv_state(path: Path) -> tuple[str, bool]:
    if not path.is_file():
        return "missing", False
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        return "empty", False
    width = len(rows[0])
    bad = sum(len(r) != width for r in rows[1:])
    return f"{len(rows) - 1} rows" + (f", {bad} short" if bad else ""), bad == 0 and len(rows) > 1


def bvh_state(path: Path) -> tuple[str, bool]:
    if not path.is_file():
        return "missing", False
    from swarmpose.core.errors import SwarmposeError
    from swarmpose.motion.bvh import read_bvh

    try:
        clip = read_bvh(path)
    except SwarmposeError as exc:
        return f"unreadable ({str(exc).split(':')[-1].strip()[:60]})", False
    return f"{len(clip)} frames read", True


def overlay_state(path: Path) -> tuple[str, bool]:
    if not path.is_file():
        return "missing", False
    import av

    frames = 0
    try:
        with av.open(str(path)) as container:
            for _ in container.decode(video=0):
                frames += 1
    except Exception as exc:  # PyAV raises its own FFmpeg errors
        return f"{frames} frames decode, then {type(exc).__name__}", frames > 0
    return f"{frames} frames decode", frames > 0


def kill_run(command: str, sig: signal.Signals, seq: Path, work: Path, timeout: float) -> KillRow:
    """Start ``command`` on ``seq``, wait for a few frames in poses.jsonl, send ``sig``, read what is left."""
    out = work / f"kill-{command}-{sig.name}"
    shutil.rmtree(out, ignore_errors=True)
    argv = {"track": ["track", str(seq), "--out", str(out), *FAST],
            "replay": ["replay", str(seq), "--out", str(out), "--rate", "4", *FAST],
            "serve": ["serve", str(seq), "--zenoh-mode", "off", "--record", str(out), "--rate", "4", *FAST]}[command]
    proc = subprocess.Popen([sys.executable, "-m", "swarmpose", *argv], env=base_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, errors="replace")
    jsonl = out / "poses.jsonl"
    deadline = time.monotonic() + timeout
    before = 0
    while time.monotonic() < deadline and proc.poll() is None:
        before = jsonl.read_bytes().count(b"\n") if jsonl.is_file() else 0
        if before >= 3:
            break
        time.sleep(0.2)
    proc.send_signal(sig)
    try:
        _, stderr = proc.communicate(timeout=60)
        status: int | None = proc.returncode
    except subprocess.TimeoutExpired:
        proc.kill()
        _, stderr = proc.communicate()
        status = None
    states = [jsonl_state(jsonl), csv_state(out / "poses.csv"), bvh_state(out / "poses.bvh"),
              overlay_state(out / "overlay.mp4")]
    (work / f"kill-{command}-{sig.name}.log").write_text(f"$ swarmpose {' '.join(argv)}\nexit {status}\n{stderr}")
    if "Traceback (most recent call last)" in stderr:
        verdict = "TRACEBACK"
    elif status is None:
        verdict = "HANG"
    elif sig == signal.SIGTERM:  # serve ends on SIGTERM as on any stop (0); the others report it (130)
        verdict = ("all readable" if all(ok for _, ok in states) and status == (0 if command == "serve" else 130)
                   else "UNREADABLE")
    else:  # SIGKILL: nothing runs; what was flushed per frame must read back
        verdict = "flushed frames readable" if states[0][1] and states[1][1] else "UNREADABLE"
    return KillRow(command, sig.name, status, before, *(text for text, _ in states), verdict)


# -- the report ----------------------------------------------------------------------------------------


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def markdown(rows: list[Row], kills: list[KillRow], command_line: str) -> str:
    """The report: the table of cases, the table of stopped runs and the counts."""
    counts: dict[str, int] = {}
    for verdict in [r.verdict for r in rows] + [k.verdict for k in kills]:
        counts[verdict] = counts.get(verdict, 0) + 1
    lines = ["| case | input | command | exit | traceback | first line of the message | verdict |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        message = r.message if len(r.message) <= 220 else r.message[:217] + "..."
        lines.append(f"| {r.case} | {_cell(r.what)} | {r.command} | {'timeout' if r.status is None else r.status} "
                     f"| {'yes' if r.traceback else 'no'} | {_cell(message)} | {r.verdict} |")
    table = "\n".join(lines)
    klines = ["| command | signal | exit | frames in poses.jsonl when sent | poses.jsonl | poses.csv | poses.bvh | "
              "overlay.mp4 | verdict |", "|---|---|---|---|---|---|---|---|---|"]
    for k in kills:
        klines.append(f"| {k.command} | {k.signal} | {'timeout' if k.status is None else k.status} | "
                      f"{k.frames_before} | {k.jsonl} | {k.csv} | {k.bvh} | {k.overlay} | {k.verdict} |")
    summary = ", ".join(f"{v}: {n}" for v, n in sorted(counts.items()))
    return (f"Generated by `{command_line}`.\n\n{len(rows)} runs of {len({r.case for r in rows})} cases and "
            f"{len(kills)} stopped runs; verdicts: {summary}.\n\n{table}\n\n"
            f"### Stopped halfway (SIGTERM / SIGKILL)\n\n{chr(10).join(klines)}\n")


def synth(folder: Path, frames: int) -> None:
    status, stdout, stderr = swarmpose(["synth", "--motion", "builtin:wave", "--frames", str(frames), "--out",
                                        str(folder), "-q"], base_env(), 300, folder.parent)
    if status != 0:
        raise SystemExit(f"cannot synthesise the base sequence: {stderr or stdout}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=None, help="write the Markdown table here (default: print it)")
    parser.add_argument("--only", nargs="*", default=None, help="run only the cases whose name contains a WORD")
    parser.add_argument("--no-kill", action="store_true", help="skip the SIGTERM / SIGKILL runs")
    parser.add_argument("--jobs", type=int, default=1, help="cases run at once")
    parser.add_argument("--timeout", type=float, default=180.0, help="seconds a run may take before it counts as hung")
    parser.add_argument("--work", default=None, help="keep the cases and each run's log in this folder")
    args = parser.parse_args(argv)
    work = Path(args.work) if args.work else Path(tempfile.mkdtemp(prefix="swarmpose-sweep-"))
    work.mkdir(parents=True, exist_ok=True)
    base = work / "base"
    if not (base / "sequence.json").is_file():
        shutil.rmtree(base, ignore_errors=True)
        synth(base, FRAMES)
    chosen = [c for c in cases() if not args.only or any(w in c.name for w in args.only)]
    with ThreadPoolExecutor(max(1, args.jobs)) as pool:
        rows = [r for batch in pool.map(lambda c: run_case(c, base, work, args.timeout), chosen) for r in batch]
    kills: list[KillRow] = []
    if not args.no_kill:
        long = work / "long"
        if not (long / "sequence.json").is_file():
            shutil.rmtree(long, ignore_errors=True)
            synth(long, KILL_FRAMES)
        for command in ("replay", "track", "serve"):
            for sig in (signal.SIGTERM, signal.SIGKILL):
                kills.append(kill_run(command, sig, long, work, args.timeout))
    shown = ["python scripts/bad_input_sweep.py"] + (["--out", args.out] if args.out else [])
    report = markdown(rows, kills, " ".join(shown))
    if args.out:
        Path(args.out).write_text(report)
    else:
        sys.stdout.write(report)
    failed = [r for r in rows if r.verdict in FAIL or r.verdict == "FAILED CONTROL"] + [
        k for k in kills if k.verdict in FAIL]
    print(f"{len(rows)} runs, {len(kills)} stopped runs, {len(failed)} failed; logs in {work}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
