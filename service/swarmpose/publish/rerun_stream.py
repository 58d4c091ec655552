"""Where a rerun recording goes: an ``.rrd`` file, a spawned viewer, a served or a remote one.

:func:`open_stream` makes the :class:`rerun.RecordingStream` the viewer sink
(:mod:`swarmpose.publish.rerun_view`) logs into, with any of these sinks at once:

* ``rrd``: the recording is written to this ``.rrd`` file (open it later with ``rerun FILE``);
* ``view`` with ``url``: streamed to a rerun viewer (or ``rerun`` server) already listening at
  ``url``, e.g. ``rerun+http://laptop:9876/proxy``;
* ``view`` where there is a display: a native rerun viewer is spawned, listening on ``port``;
* ``view`` where there is none (a headless server, a container): a gRPC server on
  ``0.0.0.0:port`` keeps the newest ~1 GiB of the recording for viewers that connect later:
  ``rerun rerun+http://HOST:port/proxy`` on any machine that reaches ``HOST``.

rerun-sdk needs Python >= 3.11; without it, asking for a view or an ``.rrd`` is a
:class:`~swarmpose.core.errors.ConfigError` that says how to install it.
"""

from __future__ import annotations

import logging
import os
import socket
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from swarmpose.core.errors import ConfigError, OutputError

log = logging.getLogger(__name__)

APPLICATION_ID = "swarmpose"
SERVER_MEMORY = "1GiB"
"""How much of the recording a served view keeps for late viewers (the oldest is dropped first)."""
FLUSH_TIMEOUT_S = 5.0
"""At most this long is spent handing the last data to a viewer or file on close."""


def require_rerun() -> Any:
    """The ``rerun`` module, or a ConfigError saying how to get it."""
    try:
        import rerun
    except (ImportError, RuntimeError) as exc:  # RuntimeError: rerun refuses Python < 3.11
        raise ConfigError(f"the viewer (--view, --rrd, swarmpose view) needs rerun-sdk, which cannot be imported "
                          f"({exc}); install it with `pip install 'swarmpose[view]'` (or rerun-sdk; Python >= 3.11)"
                          ) from exc
    return rerun


def has_display() -> bool:
    """Whether a spawned viewer window can open here: macOS and Windows always; elsewhere
    when ``DISPLAY`` or ``WAYLAND_DISPLAY`` is set."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def check_rrd_path(rrd: str | Path) -> Path:
    """``rrd`` as a Path, its folder created and the file created empty (so that a path that
    cannot be written fails here, naming it, rather than in rerun's writer thread)."""
    path = Path(rrd)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "wb"):
            pass
    except OSError as exc:
        raise OutputError(f"cannot write the rerun recording {path}: {exc.strerror or exc}; "
                          "choose a writable .rrd path (--rrd)") from exc
    return path


def check_port_free(port: int) -> None:
    """ConfigError unless TCP ``port`` can be listened on at 0.0.0.0 (rerun's server only logs
    the failure and serves nothing)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind(("0.0.0.0", port))
        except OSError as exc:
            raise ConfigError(f"cannot serve the rerun view on port {port}: {exc.strerror or exc}; choose another "
                              "--view-port (SWARMPOSE_VIEW_PORT)") from exc


@dataclass
class Stream:
    """An open recording: ``recording`` (:class:`rerun.RecordingStream`), where it goes
    (``targets``: human-readable lines such as the file or the URL to open) and its ``.rrd``
    file (None: none is written)."""

    recording: Any
    targets: list[str]
    rrd: Path | None = None

    def close(self) -> None:
        """Hand the last data to every sink (at most :data:`FLUSH_TIMEOUT_S`), then close them."""
        try:
            self.recording.flush(timeout_sec=FLUSH_TIMEOUT_S)
        except Exception as exc:  # a viewer that went away: the file still gets what it had
            log.warning("rerun: could not hand the last data over (%s)", exc)
        self.recording.disconnect()


def open_stream(name: str, *, rrd: str = "", view: bool = False, url: str = "", port: int = 9876,
                live: bool = False) -> Stream:
    """A recording named ``name`` (the camera id) going where the module docstring says.

    live: a long-running source (no ``.rrd`` footer, which would keep growing in memory).
    Raises ConfigError without rerun-sdk or without any target, OutputError for an ``rrd``
    that cannot be written.
    """
    if not (rrd or view):
        raise ConfigError("a rerun recording needs --view or --rrd FILE")
    rr = require_rerun()
    serving = view and not url and not has_display()
    if serving:
        check_port_free(port)
    recording = rr.RecordingStream(APPLICATION_ID, recording_id=None)
    recording.send_recording_name(name)
    sinks, targets, path = [], [], None
    if rrd:
        path = check_rrd_path(rrd)
        sinks.append(rr.FileSink(str(path), write_footer=not live))
        targets.append(f"rerun recording {path} (open it with `rerun {path}`)")
    if view and url:
        sinks.append(rr.GrpcSink(url))
        targets.append(f"rerun viewer at {url}")
    elif view and has_display():
        rr.spawn(port=port, connect=False, recording=recording)
        sinks.append(rr.GrpcSink(f"rerun+http://127.0.0.1:{port}/proxy"))
        targets.append(f"a rerun viewer window (port {port})")
    elif serving:
        sinks.append(rr.GrpcServerSink("0.0.0.0", port, server_memory_limit=SERVER_MEMORY))
        targets.append(f"no display here: serving the view on rerun+http://{socket.gethostname()}:{port}/proxy "
                       f"while this process runs; open it elsewhere with `rerun rerun+http://HOST:{port}/proxy` "
                       "(`swarmpose view` serves a finished run's)")
    try:
        recording.set_sinks(*sinks)
    except Exception as exc:  # a port in use, a bad URL
        raise ConfigError(f"cannot open the rerun view ({', '.join(targets)}): {exc}; choose another --view-port "
                          "or --view-url") from exc
    for target in targets:  # the served URL even with --quiet: without it the view cannot be found
        log.log(logging.WARNING if serving and target.startswith("no display") else logging.INFO, "viewer: %s", target)
    return Stream(recording, targets, path)
