"""Helpers of the daemon reliability scripts (``soak.py``, ``router_restart.py``): a synthetic
sequence folder, a ``swarmpose serve`` subprocess, a plain zenoh session that counts the
daemon's frames and keeps its status messages, the resident memory of a process.

Not a part of the package: the scripts run the daemon as users do (the ``swarmpose`` entry
point of the virtual environment) and watch it from outside, over zenoh, as a subscriber would.
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import zenoh

REPO = Path(__file__).resolve().parents[1]
SWARMPOSE = str(Path(sys.executable).parent / "swarmpose")


def synth_folder(out: Path, frames: int = 90, motion: str = "builtin:wave") -> Path:
    """A synthetic sequence folder (``swarmpose synth``) in ``out``, made once."""
    if not (out / "sequence.json").exists():
        subprocess.run([SWARMPOSE, "synth", "--motion", motion, "--frames", str(frames), "--out", str(out),
                        "--quiet"], check=True)
    return out


def session(mode: str = "peer", connect: str = "", listen: str = "") -> zenoh.Session:
    """A zenoh session on loopback endpoints, multicast scouting off."""
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps(mode))
    config.insert_json5("scouting/multicast/enabled", "false")
    if connect:
        config.insert_json5("connect/endpoints", json.dumps([connect]))
    if listen:
        config.insert_json5("listen/endpoints", json.dumps([listen]))
    return zenoh.open(config)


@dataclass
class Watcher:
    """Counts the frame messages of ``camera`` and keeps its status messages, each with the
    ``time.monotonic()`` it arrived (s)."""

    camera: str
    frames: int = 0
    frame_times: list[float] = field(default_factory=list)
    statuses: list[tuple[float, dict]] = field(default_factory=list)
    bad: int = 0
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def attach(self, zsession: zenoh.Session, keep_times: bool = False) -> list:
        """Declare the subscribers on ``zsession``; returns them (keep them referenced)."""
        def on_frame(sample) -> None:
            try:
                message = json.loads(sample.payload.to_bytes())
                ok = message.get("schema") == "swarmpose.frame"
            except ValueError:
                ok = False
            with self._lock:
                self.frames += ok
                self.bad += not ok
                if keep_times:
                    self.frame_times.append(time.monotonic())

        def on_status(sample) -> None:
            message = json.loads(sample.payload.to_bytes())
            with self._lock:
                self.statuses.append((time.monotonic(), message))

        return [zsession.declare_subscriber(f"swarmpose/{self.camera}/frame", on_frame),
                zsession.declare_subscriber(f"swarmpose/{self.camera}/status", on_status)]

    @property
    def last_status(self) -> dict | None:
        with self._lock:
            return self.statuses[-1][1] if self.statuses else None


def serve(seq: Path, camera: str, log: Path, *flags: str) -> subprocess.Popen:
    """``swarmpose serve SEQ --loop --camera-id CAMERA FLAGS...``, its stderr into ``log``."""
    with open(log, "w", encoding="utf-8") as stream:  # the child keeps its own descriptor
        return subprocess.Popen([SWARMPOSE, "serve", str(seq), "--loop", "--camera-id", camera, *flags],
                                stdout=stream, stderr=subprocess.STDOUT)


def stop(proc: subprocess.Popen, timeout: float = 60.0) -> int:
    """SIGTERM, then the exit status (SIGKILL after ``timeout`` s: status -9)."""
    if proc.poll() is None:
        proc.terminate()
        try:
            return proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
    return proc.wait()


def rss_bytes(pid: int) -> int:
    """Resident set size of process ``pid`` (bytes): psutil where installed, else /proc."""
    try:
        import psutil
    except ImportError:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
        raise RuntimeError(f"no VmRSS in /proc/{pid}/status") from None
    return int(psutil.Process(pid).memory_info().rss)


def log_problems(log: Path) -> list[str]:
    """The lines of a daemon log that report an error or a traceback."""
    words = ("ERROR", "Traceback", "CRITICAL", "Exception")
    return [line for line in log.read_text(encoding="utf-8", errors="replace").splitlines()
            if any(w in line for w in words)]
