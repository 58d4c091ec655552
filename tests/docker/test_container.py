"""The daemon's image, really built with podman and run, talking zenoh to this host.

scripts/build-image.sh builds docker/Dockerfile (its layers are cached: a rebuild after a code
change reinstalls only the package); the container then runs the image's entrypoint
(`swarmpose serve`) on a small synthetic sequence folder mounted read-only, as the non-root user of
the image, with the host's network. A plain zenoh session on the host (zenoh's own API) listens on
a loopback port the daemon connects to; it receives frames, which the JSON schemas in protocol/
validate, and sees the daemon's liveliness token. The image's own HEALTHCHECK, run by hand (podman
has no healthcheck timer without systemd), turns the container healthy; `podman stop` sends the
image's stop signal, SIGTERM, and the daemon exits 0 and withdraws its token.

Skipped where podman is not installed, without root, or where podman cannot run a container at
all; scripts/install-system-deps.sh installs podman when run as root (as CI does).
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
from pathlib import Path

import jsonschema
import pytest
import zenoh
from conftest import REPO, free_port

from swarmpose.cli.main import main
from swarmpose.core.polling import wait_until

PODMAN = shutil.which("podman")
BUILD = REPO / "scripts" / "build-image.sh"
TAG = "localhost/swarmpose:test"
CAMERA = "podcam"
SCHEMAS = {name: json.loads((REPO / "protocol" / f"{name}.schema.json").read_text())
           for name in ("frame", "status")}
CANNOT_RUN = "podman cannot run a container here"
"""What scripts/build-image.sh says when no container can be started on this machine."""

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(PODMAN is None, reason="podman is not installed (as root, scripts/install-system-deps.sh "
                                              "installs it: apt-get install podman)"),
    pytest.mark.skipif(os.geteuid() != 0, reason="the container test runs podman as root, and this is not root"),
]


def podman(*args: str, timeout: float = 60, check: bool = True) -> subprocess.CompletedProcess:
    """``podman ARGS``; raises with its output when ``check`` and it fails."""
    result = subprocess.run([PODMAN, *args], capture_output=True, text=True, timeout=timeout)
    if check and result.returncode != 0:
        raise AssertionError(f"podman {' '.join(args)}: exit {result.returncode}\n{result.stdout}{result.stderr}")
    return result



@pytest.fixture(scope="module")
def image() -> tuple[str, list[str]]:
    """The image built by scripts/build-image.sh, and the options ``podman run`` needs here (its last line)."""
    result = subprocess.run(["bash", str(BUILD), TAG], capture_output=True, text=True, timeout=1800)
    output = result.stdout + result.stderr
    if result.returncode != 0 and CANNOT_RUN in output:
        pytest.skip(output.strip().splitlines()[-1])
    assert result.returncode == 0, f"scripts/build-image.sh failed:\n{output[-6000:]}"
    last = result.stdout.strip().splitlines()[-1]
    assert last.startswith("podman-run-options:"), f"scripts/build-image.sh ended with {last!r}"
    return TAG, last.split(":", 1)[1].split()


@pytest.fixture
def sequence(tmp_path) -> Path:
    """A 6-frame synthetic sequence, readable by the image's user (uid 10001), not writable by it."""
    out = tmp_path / "sequence"
    assert main(["synth", "--motion", "builtin:wave", "--frames", "6", "--out", str(out), "--quiet"]) == 0
    for path in [out, *out.rglob("*")]:
        path.chmod(0o755 if path.is_dir() else 0o644)
    return out


def host_session(listen: str) -> zenoh.Session:
    """A plain zenoh peer on the host listening on ``listen``, multicast scouting off."""
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps("peer"))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("listen/endpoints", json.dumps([listen]))
    return zenoh.open(config)


def test_the_image_serves_a_folder_over_zenoh_turns_healthy_and_stops_on_sigterm(image, sequence):
    tag, run_options = image
    inspected = json.loads(podman("image", "inspect", tag).stdout)[0]
    assert inspected["Healthcheck"]["Test"] == ["CMD", "swarmpose", "health"], "built without --format docker?"
    config = inspected["Config"]
    assert config["User"] == "10001" and config["Entrypoint"] == ["swarmpose", "serve"]
    assert config["StopSignal"] == "SIGTERM"

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = host_session(endpoint)
    frames, encodings, statuses, alive = [], [], [], []

    def on_frame(sample: zenoh.Sample) -> None:
        frames.append(json.loads(sample.payload.to_bytes()))
        encodings.append(str(sample.encoding))

    session.declare_subscriber(f"swarmpose/{CAMERA}/frame", on_frame)
    session.declare_subscriber(f"swarmpose/{CAMERA}/status",
                               lambda s: statuses.append(json.loads(s.payload.to_bytes())))
    session.liveliness().declare_subscriber("swarmpose/*/alive", lambda s: alive.append((str(s.key_expr), str(s.kind))),
                                            history=True)
    name = f"swarmpose-test-{os.getpid()}"
    environment = {
        "SWARMPOSE_SOURCE": "folder:/data", "SWARMPOSE_LOOP": "true", "SWARMPOSE_RATE": "10",
        "SWARMPOSE_CAMERA_ID": CAMERA, "SWARMPOSE_ZENOH_MODE": "peer", "SWARMPOSE_MULTICAST": "false",
        "SWARMPOSE_CONNECT": endpoint, "SWARMPOSE_PARTICLES": "8", "SWARMPOSE_GENERATIONS": "4",
        "SWARMPOSE_START_BUDGET": "8", "SWARMPOSE_MAX_PEOPLE": "1", "SWARMPOSE_STATUS_PERIOD_S": "0.5",
    }
    env_args = [arg for key, value in environment.items() for arg in ("--env", f"{key}={value}")]
    try:
        podman("run", "--detach", "--name", name, "--network", "host", *run_options,
               "--volume", f"{sequence}:/data:ro", *env_args, tag)

        def logs() -> str:
            return podman("logs", name, check=False).stderr[-4000:]

        assert wait_until(lambda: (f"swarmpose/{CAMERA}/alive", "SampleKind.PUT") in alive, 60), \
            f"no liveliness token from the container:\n{logs()}"
        assert wait_until(lambda: len(frames) >= 3, 120), f"{len(frames)} frames reached the host:\n{logs()}"
        # the daemon runs as uid 10001, with the groups camera udev rules grant (video 44, plugdev 46)
        ids = podman("exec", name, "id", "-u").stdout.split() + podman("exec", name, "id", "-G").stdout.split()
        assert ids[0] == "10001" and {"44", "46"} <= set(ids[1:]), ids
        for message in list(frames):
            jsonschema.validate(message, SCHEMAS["frame"])
            assert message["camera"] == CAMERA
        assert all(enc.startswith("application/json") for enc in encodings)
        assert any(body["state"] in ("init", "tracking") and body["pose"] is not None
                   for message in frames for body in message["bodies"]), "no body was tracked"
        assert wait_until(lambda: statuses and statuses[-1]["state"] == "running", 30), logs()
        jsonschema.validate(statuses[-1], SCHEMAS["status"])
        assert statuses[-1]["zenoh"]["connect"] == [endpoint]

        # The image's HEALTHCHECK (`swarmpose health` in the container), run as podman's timer would.
        def healthy() -> bool:
            return podman("healthcheck", "run", name, check=False).returncode == 0

        assert wait_until(healthy, 30), f"the healthcheck never passed:\n{logs()}"
        state = json.loads(podman("inspect", name).stdout)[0]["State"]
        assert state["Health"]["Status"] == "healthy", state["Health"]

        # podman stop sends the image's stop signal (SIGTERM) and waits for the daemon to end.
        assert json.loads(podman("inspect", name).stdout)[0]["Config"]["StopSignal"] == signal.SIGTERM
        podman("stop", "--time", "60", name, timeout=90)
        state = json.loads(podman("inspect", name).stdout)[0]["State"]
        assert state["Status"] == "exited" and state["ExitCode"] == 0, f"{state}\n{logs()}"
        assert wait_until(lambda: (f"swarmpose/{CAMERA}/alive", "SampleKind.DELETE") in alive, 10)
        assert list(session.liveliness().get("swarmpose/*/alive", timeout=2.0)) == []
        assert "Traceback" not in logs()
    finally:
        podman("rm", "--force", "--time", "0", name, check=False)
        session.close()
