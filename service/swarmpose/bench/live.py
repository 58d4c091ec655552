"""``swarmpose bench live``: what a client of the service sees when a recording is served at its
recorded rate, looped, through the real worker (``serve``'s threads, hand-overs and dropping).

Reported (see :func:`bench_live`):

* ``poses_per_s``: frame messages with a tracked body per second, from the first pose to the end;
  ``poses_per_s_per_person``: the true people's estimates per second per person (without ground
  truth: tracked bodies per second);
* ``latency_ms``: capture-to-publish latency (p50, p95) of the published frames;
  ``latency_steady_ms``: the same over the frames taken :data:`SETTLE_S` or more after the last
  frame with a track's start (a start and its first re-checks hold up the frames behind them; a
  looped recording whose person jumps back restarts the track at every pass), and ``starts``;
* ``startup_s``: in this process, from opening the parts to the first pose; ``startup_cold_s`` and
  ``startup_warm_s``: a ``swarmpose serve`` process from its start to its first written pose, with
  an empty kernel and body cache, then with the cache that run left;
* ``live_mm``: Δ of each published pose against the truth of its own frame; ``offline_mm``: Δ of
  the same sequence with every frame tracked (``track``), and their ratio;
* ``client_mm``: at every camera frame, the newest pose published by then against the truth of
  that frame, as a client that shows the newest pose sees it; ``client_floor_mm``: the same with
  the truth of the published frame in place of its pose (what the rate and latency alone cost);
  ``client_extrapolated_mm``: the newest pose moved on by its joints' velocities to that frame's
  moment (:func:`swarmpose.publish.pose_at.extrapolate`); camera frames of a pass over the looped
  recording whose newest pose is still the last pass's (the person jumped back to the start) are left
  out and counted (``client_frames_left_out``);
* ``stage_ms``: the mean time per published frame of each stage (:data:`STAGES`).

Without ground truth every figure but the Δs is reported, and ``accuracy`` says why they are not.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from contextlib import ExitStack
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.core.errors import ConfigError
from swarmpose.pipeline.config import ServiceConfig
from swarmpose.pipeline.service import build_worker
from swarmpose.pipeline.status import latency_summary
from swarmpose.publish.pose_at import extrapolate
from swarmpose.sources.base import DeferredFrame, Frame, SkippedFrame

STAGES = {
    "detect": ("detect",),
    "segment": ("segment",),
    "search": ("pso",),
    "rechecks": ("recheck", "init"),
    "flips and proposals": ("scene", "hidden", "arms", "flips", "hypotheses", "lifted"),
    "polish": ("polish",),
    "verdict": ("verdict",),
    "smoothing": ("smoothing",),
}
"""Stages of a frame's time: name -> the keys of a frame message's ``timings_ms`` it sums
(``publish``, the time the sinks took, is measured by the bench itself)."""
SETTLE_S = 1.0
"""A frame taken this long after a track's start is a steady frame (``latency_steady_ms``)."""
MATCH_M = 0.5
"""A body is a true person's estimate when their mean joint distance is within this (several people)."""
STARTUP_LIMIT_S = 180.0
"""A start-up measured in a subprocess gives up after this long."""


@dataclass
class Published:
    """One frame message as the bench keeps it: the camera frame it came from (loop pass, index),
    the wall times it was taken from the source and published (ns), its latency, the tracked
    bodies' joints (id -> (14, 3) m) and velocities (id -> (14, 3) m/s), its timings and the
    time the sinks before the bench took (ms)."""

    pass_index: int
    frame: int
    received_ns: int
    publish_ns: int
    latency_ms: float
    joints: dict[int, np.ndarray]
    velocities: dict[int, np.ndarray]
    timings_ms: dict[str, float]
    publish_ms: float


@dataclass
class LiveLog:
    """The bench's sink and the worker's acquisition observer: every camera frame taken from the
    source (loop pass, index, wall ns) and every frame message published."""

    acquired: list[tuple[int, int, int]] = field(default_factory=list)
    published: list[Published] = field(default_factory=list)
    first_pose_ns: int = 0
    _pass: int = 0
    _last_index: int = -1
    _pass_of: dict[int, tuple[int, int]] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def on_acquired(self, item: Frame | SkippedFrame | DeferredFrame, received_ns: int) -> None:
        """Called by the acquisition thread for every item it takes (a new pass when the index goes back)."""
        with self._lock:
            if item.index <= self._last_index:
                self._pass += 1
            self._last_index = item.index
            self.acquired.append((self._pass, item.index, received_ns))
            self._pass_of[received_ns] = (self._pass, item.index)

    def frame(self, message: dict, frame: Frame | None) -> None:
        now = time.time_ns()
        with self._lock:
            pass_index, index = self._pass_of.get(message["received_ns"], (self._pass, message["frame"]))
        joints, velocities = {}, {}
        for k, body in enumerate(message["bodies"]):
            if body.get("state") == "lost":
                continue
            named = body.get("joints") or {}
            key = int(body.get("id", k))
            joints[key] = np.array([(named.get(n) or {}).get("position_m") or [np.nan] * 3 for n in EVAL_JOINTS],
                                   float)
            velocities[key] = np.array([(named.get(n) or {}).get("velocity_m_s") or [0.0] * 3 for n in EVAL_JOINTS],
                                       float)
        if joints and not self.first_pose_ns:
            self.first_pose_ns = now
        self.published.append(Published(pass_index, index, message["received_ns"], message["publish_ns"],
                                         float(message["latency_ms"]), joints, velocities,
                                         dict(message.get("timings_ms") or {}), (now - message["publish_ns"]) / 1e6))

    def status(self, message: dict) -> None:
        """Statuses are not part of the bench."""

    def close(self) -> None:
        """Nothing to release."""


def steady_latencies(log: LiveLog, settle_s: float = SETTLE_S) -> tuple[list[float], int]:
    """The latencies (ms) of the published frames taken ``settle_s`` or more after the last frame
    with a track's start (its timings hold ``init``), and how many frames started a track."""
    last_start_ns, steady, starts = None, [], 0
    for p in sorted(log.published, key=lambda p: p.received_ns):
        if p.timings_ms.get("init"):
            last_start_ns, starts = p.received_ns, starts + 1
        elif last_start_ns is None or p.received_ns - last_start_ns >= settle_s * 1e9:
            steady.append(p.latency_ms)
    return steady, starts


def truth_people(ground_truth, index: int) -> list[np.ndarray]:
    """The true people's joints ((14, 3) m each) at frame ``index``, person 1 first; [] without truth."""
    try:
        row = ground_truth.row(index)
    except KeyError:
        return []
    people = ground_truth.people_at(row)
    if people:
        return [np.asarray(p.joints3d, float) for p in people]
    return [np.asarray(ground_truth.joints3d[row], float)]


def mean_distance_mm(a: np.ndarray, b: np.ndarray) -> float:
    """Mean distance (mm) over the joints finite in both of (J, 3) m arrays; NaN when none is."""
    d = np.linalg.norm(a - b, axis=1)
    d = d[np.isfinite(d)]
    return float(1000 * d.mean()) if d.size else float("nan")


def estimate_of(truth: np.ndarray, bodies: dict[int, np.ndarray], single: bool) -> int | None:
    """The id of ``truth``'s estimate among ``bodies``: the only body when ``single``, else the
    nearest within :data:`MATCH_M`; None when there is none."""
    if not bodies:
        return None
    if single:
        return next(iter(bodies))
    distances = {k: mean_distance_mm(truth, j) for k, j in bodies.items()}
    best = min(distances, key=lambda k: np.inf if np.isnan(distances[k]) else distances[k])
    return best if distances[best] <= 1000 * MATCH_M else None


def _mean(values: list[float]) -> float | None:
    values = [v for v in values if np.isfinite(v)]
    return round(float(np.mean(values)), 2) if values else None


def accuracy_figures(log: LiveLog, ground_truth) -> dict:
    """Live Δ, the client's Δ (newest pose, extrapolated, floor) and the published frames each
    true person was missing from (see the module doc)."""
    live, missed = [], 0
    single = all(len(truth_people(ground_truth, p.frame)) <= 1 for p in log.published[:50])
    for p in log.published:
        for truth in truth_people(ground_truth, p.frame):
            key = estimate_of(truth, p.joints, single)
            if key is None:
                missed += 1
            else:
                live.append(mean_distance_mm(p.joints[key], truth))
    client, extrapolated, floor, restarting = [], [], [], 0
    order = sorted(log.published, key=lambda p: p.publish_ns)
    publish_times = np.array([p.publish_ns for p in order], np.int64)
    for pass_index, index, at_ns in log.acquired:
        k = int(np.searchsorted(publish_times, at_ns, side="right")) - 1
        if k < 0:
            continue
        newest = order[k]
        if newest.pass_index != pass_index:  # the loop started over: the person jumped back to the start
            restarting += 1
            continue
        for truth in truth_people(ground_truth, index):
            shown = truth_people(ground_truth, newest.frame)
            if shown:
                floor.append(min(mean_distance_mm(t, truth) for t in shown))
            key = estimate_of(truth, newest.joints, single)
            if key is None:
                continue
            client.append(mean_distance_mm(newest.joints[key], truth))
            moved = extrapolate(newest.joints[key], newest.velocities[key], (at_ns - newest.received_ns) * 1e-9)
            extrapolated.append(mean_distance_mm(moved, truth))
    return {"live_mm": _mean(live), "missed": missed, "client_mm": _mean(client),
            "client_extrapolated_mm": _mean(extrapolated), "client_floor_mm": _mean(floor),
            "client_frames_left_out": restarting}


def stage_split(log: LiveLog) -> dict[str, float]:
    """Mean ms per published frame of each of :data:`STAGES` and ``publish``."""
    rows = [p for p in log.published if p.timings_ms]
    if not rows:
        return {}
    split = {name: round(float(np.mean([sum(p.timings_ms.get(k, 0.0) for k in keys) for p in rows])), 2)
             for name, keys in STAGES.items()}
    split["publish"] = round(float(np.mean([p.publish_ms for p in rows])), 2)
    split["total"] = round(float(np.mean([p.timings_ms.get("total", 0.0) for p in rows])), 2)
    return split


def serve_startup_s(config: ServiceConfig, cache: Path, timeout_s: float = STARTUP_LIMIT_S) -> float | None:
    """Seconds from starting a ``swarmpose serve`` process on ``config``'s source to its first
    written pose, with ``cache`` as its cache folder (kernels, bodies); None when none came."""
    with tempfile.TemporaryDirectory(prefix="swarmpose-bench-live-") as tmp:
        record = Path(tmp) / "record"
        t = config.tracker
        budget = "auto" if config.frame_budget_ms is None else str(config.frame_budget_ms)
        argv = [sys.executable, "-m", "swarmpose", "serve", config.source, "--zenoh-mode", "off", "--record",
                str(record), "--no-overlay", "--no-ros-bag", "--body", config.body, "--detector", config.detector,
                "--quiet",
                "--particles", str(t.particles), "--generations", str(t.generations), "--max-people",
                str(t.max_people), "--frame-budget-ms", budget, "--rate", str(config.rate)]
        argv += ["--shape", config.shape] if config.shape else []
        argv += ["--models", config.models] if config.models else []
        env = {**os.environ, "XDG_CACHE_HOME": str(cache), "POCL_CACHE_DIR": str(cache / "pocl"),
               "SWARMPOSE_CACHE_DIR": str(cache / "swarmpose")}
        started = time.monotonic()
        proc = subprocess.Popen(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        poses = record / "poses.jsonl"
        try:
            while time.monotonic() - started < timeout_s:
                if poses.is_file() and _has_pose(poses):
                    return round(time.monotonic() - started, 2)
                if proc.poll() is not None and not (poses.is_file() and _has_pose(poses)):
                    return None
                time.sleep(0.02)
            return None
        finally:
            proc.kill()
            proc.wait()


def _has_pose(poses: Path) -> bool:
    """Whether a poses.jsonl holds a line with a tracked body."""
    for line in poses.read_text(encoding="utf-8").splitlines():
        try:
            bodies = json.loads(line).get("bodies", [])
        except ValueError:  # a line being written
            continue
        if any(b.get("state") != "lost" for b in bodies):
            return True
    return False


def run_live(config: ServiceConfig, seconds: float) -> tuple[LiveLog, float | None, object]:
    """Serve ``config``'s source (looped, paced at its rate, zenoh off) for ``seconds`` after its
    first pose (or after :data:`STARTUP_LIMIT_S` without one); returns the log, the in-process
    start-up (s, None: no pose) and the source's ground truth (None: none)."""
    config = replace(config, loop=True, frames=0, zenoh=replace(config.zenoh, zenoh_mode="off"))
    log = LiveLog()
    started_ns = time.time_ns()
    with ExitStack() as stack:
        worker, parts, _ = build_worker(config, stack, replay=False, sinks=[log], on_acquired=log.on_acquired)
        ground_truth = getattr(parts.source, "ground_truth", None)

        def stop_later() -> None:
            deadline = time.monotonic() + STARTUP_LIMIT_S
            while not log.first_pose_ns and time.monotonic() < deadline:
                time.sleep(0.05)
            time.sleep(seconds)
            worker.stop()

        threading.Thread(target=stop_later, name="bench live timer", daemon=True).start()
        worker.run()
    startup = (log.first_pose_ns - started_ns) / 1e9 if log.first_pose_ns else None
    return log, startup, ground_truth


def offline_mm(config: ServiceConfig) -> float | None:
    """Δ (mm) of ``config``'s source with every frame tracked (as ``track`` does), each frame's bodies
    matched to its true people as the live run's are (:func:`accuracy_figures`)."""
    from swarmpose.pipeline.run import results
    from swarmpose.pipeline.service import open_parts

    log = LiveLog()
    with ExitStack() as stack:
        parts = open_parts(config, stack, score=False)
        for result in results(parts.source, parts.pipeline):
            log.frame(result.to_message(config.camera_id, received_ns=0, publish_ns=0), None)
        figures = accuracy_figures(log, parts.source.ground_truth)
    return figures["live_mm"]


def bench_live(config: ServiceConfig, seconds: float = 20.0, offline: bool = True, startup: bool = True) -> dict:
    """The figures of the module doc for ``config``'s recording (``config.source``) served at its
    recorded rate (or ``config.rate``). offline: also track every frame for the offline Δ;
    startup: also time two ``swarmpose serve`` processes (cold and warm cache)."""
    if seconds <= 0:
        raise ConfigError(f"--seconds {seconds}: the live run needs a positive length")
    log, startup_s, ground_truth = run_live(config, seconds)
    poses = [p for p in log.published if p.joints]
    steady, starts = steady_latencies(log)
    span_s = ((log.published[-1].publish_ns - log.first_pose_ns) / 1e9) if poses else 0.0
    people = max((len(truth_people(ground_truth, p.frame)) for p in log.published[:50]), default=1) \
        if ground_truth is not None else 1
    bodies = sum(len(p.joints) for p in poses)  # without truth: every tracked body; with it, its people's
    if ground_truth is not None:
        single = people <= 1
        bodies = sum(estimate_of(truth, p.joints, single) is not None for p in poses
                     for truth in truth_people(ground_truth, p.frame))
    result = {
        "source": config.source, "seconds": round(span_s, 2), "camera_frames": len(log.acquired),
        "published": len(log.published), "poses": len(poses),
        "poses_per_s": round(len(poses) / span_s, 2) if span_s > 0 else 0.0,
        "poses_per_s_per_person": round(bodies / span_s / max(people, 1), 2) if span_s > 0 else 0.0,
        "people": people,
        "latency_ms": latency_summary([p.latency_ms for p in log.published]),
        "latency_steady_ms": latency_summary(steady), "starts": starts,
        "startup_s": None if startup_s is None else round(startup_s, 2),
        "stage_ms": stage_split(log),
        "particles": config.tracker.particles, "generations": config.tracker.generations,
    }
    if ground_truth is None:
        result["accuracy"] = f"{config.source} has no ground truth: no Δ (a `swarmpose synth` folder has one)"
    else:
        result.update(accuracy_figures(log, ground_truth))
        if offline:
            result["offline_mm"] = offline_mm(config)
            if result["live_mm"] is not None and result["offline_mm"]:
                result["live_over_offline"] = round(result["live_mm"] / result["offline_mm"], 3)
    if startup:
        with tempfile.TemporaryDirectory(prefix="swarmpose-bench-cache-") as cache:
            result["startup_cold_s"] = serve_startup_s(config, Path(cache))
            result["startup_warm_s"] = serve_startup_s(config, Path(cache))
    return result


def format_live_bench(result: dict) -> str:
    """A few human-readable lines for a :func:`bench_live` result."""
    def mm(key: str) -> str:
        value = result.get(key)
        return "–" if value is None else f"{value:.1f} mm"

    lat, steady = result["latency_ms"], result["latency_steady_ms"]
    lines = [f"{result['source']}: {result['published']} frames published of {result['camera_frames']} served in "
             f"{result['seconds']:.1f} s (p = {result['particles']}, g = {result['generations']})",
             f"poses/s {result['poses_per_s']:.2f} ({result['poses_per_s_per_person']:.2f} per person, "
             f"{result['people']} in view); latency p50 {lat['median']} ms, p95 {lat['p95']} ms; "
             f"{result['starts']} track starts, {SETTLE_S:g} s after them p50 {steady['median']} ms, "
             f"p95 {steady['p95']} ms",
             f"start-up to the first pose: {result['startup_s']} s in this process"
             + (f", a serve process {result['startup_cold_s']} s cold, {result['startup_warm_s']} s warm"
                if "startup_cold_s" in result else "")]
    if "accuracy" in result:
        lines.append(result["accuracy"])
    else:
        ratio = f" (x{result['live_over_offline']:.2f})" if "live_over_offline" in result else ""
        lines.append(f"live delta {mm('live_mm')}, offline {mm('offline_mm')}{ratio}; {result['missed']} poses "
                     "missing a person")
        lines.append(f"client delta {mm('client_mm')}, extrapolated {mm('client_extrapolated_mm')}, floor "
                     f"{mm('client_floor_mm')}")
    if result["stage_ms"]:
        lines.append("per frame (ms): " + ", ".join(f"{k} {v:.1f}" for k, v in result["stage_ms"].items()))
    return "\n".join(lines)
