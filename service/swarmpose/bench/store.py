"""The per-run records of the resumable benchmarks (``bench accuracy``, ``bench utdmhad``, ``bench
still``): one JSON file per run, written whole or not at all, and read back only when it was made
with the same settings; and their sequences, rendered whole or not at all (:func:`render_whole`)."""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Callable
from pathlib import Path

from swarmpose.tracking.config import TrackerConfig

BENCH_SETTINGS = ("particles", "generations", "search", "turning_swarm", "arm_prior", "limb_flips", "limb_exchanges",
                  "hidden_lifts", "arm_proposals", "hypotheses", "backward", "polish", "smoothing", "ensemble",
                  "box_hold")
"""The tracker settings the resumable benchmarks take as flags (their defaults: :class:`TrackerConfig`'s)."""
TRACKER_DEFAULTS = {**{name: getattr(TrackerConfig(), name) for name in BENCH_SETTINGS}, "max_people": 1}
"""The tracker settings every record stores, so that a resume compares them even when the
caller left them at their defaults (``bench utdmhad`` adds ``auto_height``, which the matrix's
given shapes never use). The matrix's cells hold one person each, so its ``max_people`` is 1."""
BEFORE_THE_SETTING = {**TRACKER_DEFAULTS, "limb_flips": False, "limb_exchanges": False, "hidden_lifts": False,
                      "arm_proposals": False, "hypotheses": 0, "polish": 0, "auto_height": False, "lag_frames": 0.0,
                      "box_hold": 0.0, "search": "swarm", "turning_swarm": 0.0}
"""What a record that lacks a setting was made with: the tracker's behaviour before the setting
existed (its default then, or, for a new behaviour that is on by default now, off); UTD-MHAD
records without ``lag_frames`` were scored against the files' own pairing of skeleton and depth;
records without ``search`` were made by the whole-pose swarm, those without ``turning_swarm`` searched
a turning track's frames as any other."""
OFFLINE_SEARCH = {"auto": "swarm"}
"""The search a ``search`` setting runs in these benchmarks, which have no frame budget: auto is the swarm."""


def tracker_settings(tracker: dict | None) -> dict:
    """``tracker`` with :data:`TRACKER_DEFAULTS` filled in."""
    return {**TRACKER_DEFAULTS, **(tracker or {})}


def mode_settings(tracker: dict, mode: str) -> dict:
    """The settings a ``mode``'s record is made and resumed with: ``arm_proposals`` off where it does
    nothing (the joints and lift modes have no depth term to judge them), ``hypotheses`` and
    ``backward`` 0, ``ensemble`` 1 and ``smoothing`` off in the lift mode (no search, no body, no pose), so that
    their records made before the setting existed still match; ``polish`` only in the hybrid mode:
    the joints-only, depth-only and lift modes are the benchmarks' baselines (the paper's Table 3),
    run as every earlier figure ran them (the polish would take a joints-only baseline further too:
    the walk from behind with MoveNet 53.8 mm at p = g = 32, the ratio to hybrid 0.67 instead of
    0.55)."""
    searched = {k: 0 if mode == "lift" else int(tracker.get(k, TRACKER_DEFAULTS[k]))
                for k in ("hypotheses", "backward")}
    searched["ensemble"] = 1 if mode == "lift" else int(tracker.get("ensemble", TRACKER_DEFAULTS["ensemble"]))
    polish = int(tracker.get("polish", TRACKER_DEFAULTS["polish"])) if mode == "hybrid" else 0
    smoothing = "off" if mode == "lift" else tracker.get("smoothing", TRACKER_DEFAULTS["smoothing"])
    return {**tracker, "arm_proposals": bool(tracker.get("arm_proposals", True)) and mode not in ("joints", "lift"),
            **searched, "polish": polish, "smoothing": smoothing}


def seeded(settings: dict, seed: int) -> tuple[dict, str]:
    """A run's settings and file-name suffix for PSO seed ``seed``: seed 0 is the records made before
    seeds (no ``seed`` setting, no suffix), seed s adds ``seed`` to the settings and ``-seed{s}``."""
    return ({**settings, "seed": seed}, f"-seed{seed}") if seed else (settings, "")


def read_record(path: Path, expected: dict) -> dict | None:
    """The JSON record at ``path`` if each key of ``expected`` holds the same value in it (a
    tracker setting it lacks: :data:`BEFORE_THE_SETTING`'s value); None when it is absent,
    unreadable or was made with other settings."""
    try:
        record = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    return record if all(_ran(k, record.get(k, BEFORE_THE_SETTING.get(k))) == _ran(k, v)
                         for k, v in expected.items()) else None


def _ran(key: str, value):
    """A setting's ``value`` as what it ran offline (``search``: :data:`OFFLINE_SEARCH`)."""
    return OFFLINE_SEARCH.get(value, value) if key == "search" else value


def write_record(path: Path, record: dict) -> None:
    """Write ``record`` as JSON at ``path`` through a temporary file, so an interrupted run leaves
    the old file or the new one, never half of one."""
    tmp = Path(path).with_suffix(".tmp")
    tmp.write_text(json.dumps(record))
    os.replace(tmp, path)


def render_whole(folder: Path, render: Callable[[Path], None]) -> Path:
    """``folder`` as ``render`` (called with an empty folder to fill) makes it: rendered beside it as
    ``FOLDER.partial`` (one an interrupted run left is thrown away), then put in its place, so that an
    interrupted run never leaves a half-rendered sequence where a complete one is looked for."""
    tmp = folder.with_name(folder.name + ".partial")
    shutil.rmtree(tmp, ignore_errors=True)
    render(tmp)
    shutil.rmtree(folder, ignore_errors=True)  # one made for other settings (too short, another plan)
    tmp.rename(folder)
    return folder
