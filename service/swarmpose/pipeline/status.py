"""The worker's health as ``swarmpose.status`` messages, and the sinks that only report it.

:class:`WorkerStats` holds the counters (``frames`` in ``protocol/status.schema.json``),
updated through its one locked method; :func:`status_message` builds the message. Two
sinks report statuses: :class:`HealthFileSink` (the file ``swarmpose health`` reads, the
docker HEALTHCHECK) and :class:`LogSink` (the ``swarmpose`` logger).
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from swarmpose.messages.describe import format_status
from swarmpose.messages.schema import MESSAGE_VERSIONS
from swarmpose.sources.base import Frame

log = logging.getLogger("swarmpose.status")
LOG_EVERY_S = 10.0
"""Seconds between status lines in the log while a worker runs."""
NO_ZENOH = {"mode": "off", "connect": [], "listen": [], "peers": 0, "routers": 0, "warning": ""}


@dataclass
class WorkerStats:
    """Counters since the start, the tracker's last state and errors, and the latencies (ms)
    of the current status period (and of the whole run when ``keep_all``). Threads change
    them only through :meth:`update`."""

    received: int = 0
    published: int = 0
    dropped: int = 0
    skipped: int = 0
    failed: int = 0
    detector_errors: int = 0
    tracker_failures: int = 0
    period_published: int = 0
    period_latencies: list[float] = field(default_factory=list)
    all_latencies: list[float] = field(default_factory=list)
    last_latency: float | None = None
    tracker_state: str = "none"
    detector_error: str = ""
    tracker_error: str = ""
    people: dict = field(default_factory=dict)
    personalisation: dict = field(default_factory=dict)
    keep_all: bool = False
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def update(self, latency_ms: float | None = None, **changes: int | str) -> None:
        """Add the integer ``changes`` to their counters, set the string and dict ones, and
        record a published frame's latency; all under one lock."""
        with self._lock:
            for name, value in changes.items():
                if isinstance(value, (str, dict)):
                    setattr(self, name, value)
                else:
                    setattr(self, name, getattr(self, name) + value)
            if latency_ms is not None:
                self.last_latency = latency_ms
                self.period_latencies.append(latency_ms)
                if self.keep_all:  # replay reports them all at the end; serve runs for days
                    self.all_latencies.append(latency_ms)

    def take_period(self) -> tuple[int, list[float], dict]:
        """(frames published, latencies) of the period that ends now, and a copy of the counters."""
        with self._lock:
            published, latencies = self.period_published, self.period_latencies
            self.period_published, self.period_latencies = 0, []
            counters = {k: getattr(self, k) for k in ("received", "published", "dropped", "skipped", "failed",
                                                      "detector_errors", "tracker_failures", "last_latency",
                                                      "tracker_state", "detector_error", "tracker_error")}
            counters["people"] = dict(self.people)
            counters["personalisation"] = dict(self.personalisation)
        return published, latencies, counters


def latency_summary(latencies_ms) -> dict:
    """``{"median", "p95"}`` of latencies (ms), None for an empty list."""
    lat = np.asarray(latencies_ms, float)
    if not lat.size:
        return {"median": None, "p95": None}
    return {"median": round(float(np.median(lat)), 3), "p95": round(float(np.percentile(lat, 95)), 3)}


def status_message(camera: str, state: str, stats: WorkerStats, period_s: float, uptime_s: float, *,
                   source_uri: str, source_state: str, detector_spec: str, zenoh: dict | None,
                   opencl_device: str, errors: list[str]) -> dict:
    """A ``swarmpose.status`` message; ends the stats' status period (``period_s`` long)."""
    published, latencies, s = stats.take_period()
    return {
        "schema": "swarmpose.status", "version": MESSAGE_VERSIONS["status"], "camera": camera,
        "time_ns": time.time_ns(), "uptime_s": round(uptime_s, 3), "state": state,
        "fps": round(published / period_s, 3),
        "latency_ms": {**latency_summary(latencies), "last": s["last_latency"]},
        "frames": {k: s[k] for k in ("received", "published", "dropped", "skipped", "failed")},
        "source": {"uri": source_uri, "state": source_state},
        "detector": {"spec": detector_spec, "errors": s["detector_errors"], "last_error": s["detector_error"]},
        "tracker": {"state": s["tracker_state"], "failures": s["tracker_failures"], "last_error": s["tracker_error"],
                    **({"people": s["people"]} if s["people"] else {}),
                    **({"personalisation": s["personalisation"]} if s["personalisation"] else {})},
        "zenoh": zenoh or dict(NO_ZENOH), "opencl_device": opencl_device, "errors": errors,
    }


def write_health_file(path: str | Path, message: dict) -> None:
    """Write the status message atomically (temporary file + rename) for ``swarmpose health``."""
    target = Path(path)
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(json.dumps(message), encoding="utf-8")
        os.replace(tmp, target)
    except OSError as exc:  # health reporting must never stop the worker; `swarmpose health` then sees a stale file
        log.warning("cannot write the health file %s: %s", target, exc)


class _StatusOnly:
    """A sink that ignores frames."""

    def frame(self, message: dict, frame: Frame | None) -> None:
        """Frames carry nothing to report."""

    def close(self) -> None:
        """Nothing to release."""


class HealthFileSink(_StatusOnly):
    """Writes every status message to ``path`` (atomically) for ``swarmpose health``."""

    def __init__(self, path: str | Path):
        self.path = Path(path)

    def status(self, message: dict) -> None:
        write_health_file(self.path, message)


class LogSink(_StatusOnly):
    """Logs status messages as one line each (logger ``swarmpose.status``, level INFO): while
    running at most every ``every_s`` seconds, and every one once the worker is ending."""

    def __init__(self, every_s: float = LOG_EVERY_S):
        self.every_s, self._last = every_s, -float("inf")

    def status(self, message: dict) -> None:
        now = time.monotonic()
        if message["state"] not in ("starting", "running") or now - self._last >= self.every_s:
            self._last = now
            log.info("%s", format_status(message))
