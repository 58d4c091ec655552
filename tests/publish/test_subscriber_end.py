"""`swarmpose subscribe` ends by itself when the worker it listens to ends (both real processes on loopback)."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import free_port

BIN = Path(sys.executable).parent


@pytest.mark.slow
def test_the_subscriber_exits_when_the_worker_ends_and_keeps_waiting_with_forever(wave_sequence, tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    env = {"PATH": str(BIN), "HOME": str(tmp_path)}
    later = f"tcp/127.0.0.1:{free_port()}"
    subscriber = subprocess.Popen([str(BIN / "swarmpose"), "subscribe", "--no-multicast", "--listen", endpoint],
                                  env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    forever = subprocess.Popen([str(BIN / "swarmpose"), "subscribe", "--forever", "--no-multicast", "--listen",
                                later, "--connect", endpoint], env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    try:
        time.sleep(1.0)  # the subscribers' sessions are up before the worker's first frame
        worker = subprocess.run([str(BIN / "swarmpose"), "serve", "--source", str(wave_sequence),
                                 "--connect", endpoint, "--connect", later, "--no-multicast", "--mode", "lift",
                                 "--rate", "4", "--camera-id", "cam7", "--quiet"],
                                env=env, capture_output=True, text=True, timeout=120)
        assert worker.returncode == 0, worker.stderr
        out, err = subscriber.communicate(timeout=30)
        assert subscriber.returncode == 0, err
        lines = out.splitlines()
        assert sum(line.startswith("cam7 frame") for line in lines) >= 1, out
        assert lines[-1].startswith("worker cam7 ended;"), out
        time.sleep(2.0)
        assert forever.poll() is None, "--forever must keep waiting for workers"
        forever.kill()
        assert "cam7 frame" in forever.communicate(timeout=10)[0]
    finally:
        for proc in (subscriber, forever):
            if proc.poll() is None:
                proc.kill()
                proc.wait()
