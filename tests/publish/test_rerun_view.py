"""The rerun viewer: ``--rrd`` on a real run and ``swarmpose view``, read back with rerun's own reader.

The oracle is the run's ``poses.jsonl`` (the frame messages), the sequence's depth PNGs and
intrinsics read here with OpenCV and json, and rerun's :class:`rerun.chunk.RrdReader`.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
from collections import defaultdict
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
from conftest import free_port
from scipy.spatial.transform import Rotation

from swarmpose.body.joint_set import SKELETON_LINKS, SKELETON_NAMES
from swarmpose.cli.main import main
from swarmpose.core.polling import wait_until

rerun = pytest.importorskip("rerun", reason="rerun-sdk is not installed (pip install rerun-sdk; Python >= 3.11)")

STEP = 3  # the sink's default depth step
FAST = ["--particles", "16", "--generations", "3", "--no-overlay", "--quiet"]


def read_rrd(path: Path) -> dict[str, list[dict]]:
    """Every row of the recording in ``path``: entity path -> rows (column name -> value), via rerun's reader."""
    from rerun.chunk import RrdReader

    rows: dict[str, list[dict]] = defaultdict(list)
    for chunk in RrdReader(path).stream():
        rows[chunk.entity_path].extend(chunk.to_record_batch().to_pylist())
    return rows


def by_frame(rows: list[dict], column: str) -> dict[int, object]:
    """The value of ``column`` per ``frame`` of temporal rows that have it."""
    return {row["frame"]: row[column] for row in rows if row.get("frame") is not None and row.get(column) is not None}


def messages_of(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / "poses.jsonl").read_text().splitlines()]


@pytest.fixture(scope="module")
def tracked(wave_sequence, tmp_path_factory) -> tuple[Path, Path, Path]:
    """(sequence, track --out folder, the .rrd that track --rrd wrote) of a short real run."""
    out = tmp_path_factory.mktemp("track")
    rrd = out / "view.rrd"
    assert main(["track", str(wave_sequence), "--out", str(out), "--rrd", str(rrd), *FAST]) == 0
    return wave_sequence, out, rrd


def check_bodies(rows: dict[str, list[dict]], messages: list[dict]) -> None:
    """The 3D and 2D joints, bones and confidence logged per frame are the messages' values."""
    joints = by_frame(rows["/world/bodies/0/joints"], "Points3D:positions")
    keypoints = by_frame(rows["/world/bodies/0/joints"], "Points3D:keypoint_ids")
    pixels = by_frame(rows["/world/camera/image/bodies/0/joints"], "Points2D:positions")
    bones = by_frame(rows["/world/bodies/0/bones"], "LineStrips3D:strips")
    confidence = by_frame(rows["/stats/confidence/0"], "Scalars:scalars")
    labels = by_frame(rows["/world/bodies/0/label"], "Points3D:labels")
    arrows = by_frame(rows["/world/bodies/0/axes"], "Arrows3D:vectors")
    origins = by_frame(rows["/world/bodies/0/axes"], "Arrows3D:origins")
    assert sorted(joints) == [m["frame"] for m in messages]
    for message in messages:
        body = message["bodies"][0]
        f = message["frame"]
        expected = np.array([body["joints"][name]["position_m"] for name in SKELETON_NAMES], dtype=np.float32)
        np.testing.assert_array_equal(np.asarray(joints[f], dtype=np.float32), expected)
        assert keypoints[f] == list(range(len(SKELETON_NAMES)))
        np.testing.assert_array_equal(np.asarray(pixels[f], dtype=np.float32),
                                      np.array([body["joints"][n]["pixel"] for n in SKELETON_NAMES], np.float32))
        strips = np.asarray(bones[f], dtype=np.float32)
        link_ends = np.array([[body["joints"][a]["position_m"], body["joints"][b]["position_m"]]
                              for a, b in SKELETON_LINKS], dtype=np.float32)
        # each joint's axes: 8 cm along the columns of its quaternion's matrix (scipy's reading of x, y, z, w)
        axes = Rotation.from_quat([body["joints"][n]["orientation_xyzw"] for n in SKELETON_NAMES]).as_matrix()
        np.testing.assert_allclose(np.asarray(arrows[f]), 0.08 * np.swapaxes(axes, 1, 2).reshape(-1, 3), atol=1e-6)
        np.testing.assert_allclose(np.asarray(origins[f]), np.repeat(expected, 3, axis=0), atol=1e-6)
        np.testing.assert_array_equal(strips, link_ends)
        mean = np.mean([j["confidence"] for j in body["joints"].values()])
        assert confidence[f] == pytest.approx([mean], abs=1e-12)
        assert labels[f] == [f"0 {body['state']} {mean:.2f}"]


def check_depth(rows: dict[str, list[dict]], sequence: Path, frames: list[int]) -> None:
    """The point cloud per frame: the valid pixels of the depth PNG's grid [::STEP, ::STEP],
    back-projected with intrinsic.json, coloured from the colour PNG."""
    import cv2

    k = np.asarray(json.loads((sequence / "intrinsic.json").read_text())["intrinsic_matrix"]).reshape(3, 3).T
    points = by_frame(rows["/world/camera/depth"], "Points3D:positions")
    colors = by_frame(rows["/world/camera/depth"], "Points3D:colors")
    assert sorted(points) == frames
    for f in frames:
        depth_mm = cv2.imread(str(sequence / "depth" / f"{f:06d}.png"), cv2.IMREAD_UNCHANGED)[::STEP, ::STEP]
        color = cv2.imread(str(sequence / "color" / f"{f:06d}.png"), cv2.IMREAD_COLOR)[::STEP, ::STEP, ::-1]
        v, u = np.nonzero(depth_mm > 0)
        z = depth_mm[v, u] / 1000.0
        expected = np.stack([(u * STEP - k[0, 2]) / k[0, 0] * z, (v * STEP - k[1, 2]) / k[1, 1] * z, z], axis=-1)
        got = np.asarray(points[f], dtype=np.float64)
        assert got.shape == expected.shape and len(got) > 1000
        np.testing.assert_allclose(got, expected, atol=1e-5)
        rgb = color[v, u].astype(np.uint32)
        packed = (rgb[:, 0] << 24) | (rgb[:, 1] << 16) | (rgb[:, 2] << 8) | 0xFF
        np.testing.assert_array_equal(np.asarray(colors[f], dtype=np.uint32), packed)


@pytest.mark.slow
def test_track_rrd_holds_every_frame_the_depth_and_the_message_values(tracked):
    sequence, out, rrd = tracked
    rows = read_rrd(rrd)
    messages = messages_of(out)
    frames = [m["frame"] for m in messages]
    assert frames == list(range(6))
    for entity in ("/world/camera/image", "/world/camera/depth", "/world/camera", "/world/bodies/0/joints",
                   "/world/bodies/0/bones", "/world/bodies/0/label", "/world/camera/image/bodies/0/joints",
                   "/world/camera/image/bodies/0/bones", "/stats/confidence/0", "/stats/latency_ms", "/log"):
        assert entity in rows, entity
    # every temporal row is on the "frame" timeline; one image per processed frame
    assert sorted(by_frame(rows["/world/camera/image"], "EncodedImage:blob")) == frames
    assert {r["frame"] for e in rows.values() for r in e if "frame" in r and r["frame"] is not None} == set(frames)
    pinhole = [r for r in rows["/world/camera/image"] if r.get("Pinhole:image_from_camera") is not None]
    assert len(pinhole) == 1 and pinhole[0].get("frame") is None  # static, logged once
    k = np.asarray(json.loads((sequence / "intrinsic.json").read_text())["intrinsic_matrix"], dtype=np.float32)
    np.testing.assert_array_equal(np.ravel(pinhole[0]["Pinhole:image_from_camera"]).astype(np.float32), k)
    np.testing.assert_array_equal(np.ravel(pinhole[0]["Pinhole:resolution"]), [640.0, 480.0])
    check_bodies(rows, messages)
    check_depth(rows, sequence, frames)
    states = [r["TextLog:text"][0] for r in sorted(rows["/log"], key=lambda r: r["frame"])]
    assert states[0] == "person 0: init" and "person 0: tracking" in states


@pytest.mark.slow
def test_replay_writes_the_rrd_named_by_the_environment(wave_sequence, tmp_path, monkeypatch):
    """replay runs the sinks on the worker's thread; SWARMPOSE_RRD is the setting's variable."""
    rrd = tmp_path / "replay.rrd"
    monkeypatch.setenv("SWARMPOSE_RRD", str(rrd))
    out = tmp_path / "replay"
    assert main(["replay", str(wave_sequence), "--out", str(out), *FAST]) == 0
    rows = read_rrd(rrd)
    check_bodies(rows, messages_of(out))
    check_depth(rows, wave_sequence, list(range(6)))
    assert any("worker" in r["TextLog:text"][0] for r in rows["/log"])


@pytest.mark.slow
def test_view_of_a_track_folder_writes_the_same_recording(tracked, tmp_path):
    sequence, out, _ = tracked
    rrd = tmp_path / "view.rrd"
    run = subprocess.run([sys.executable, "-m", "swarmpose", "view", str(out), "--source", str(sequence),
                          "--rrd", str(rrd)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "6 frames" in run.stdout
    rows = read_rrd(rrd)
    messages = messages_of(out)
    check_bodies(rows, messages)
    check_depth(rows, sequence, list(range(6)))


def test_view_without_a_source_shows_the_skeletons_only(tracked, tmp_path):
    _, out, _ = tracked
    rrd = tmp_path / "bodies.rrd"
    assert main(["view", str(out / "poses.jsonl"), "--rrd", str(rrd), "--quiet"]) == 0
    rows = read_rrd(rrd)
    check_bodies(rows, messages_of(out))
    assert "/world/camera/depth" not in rows and "/world/camera/image" not in rows


def test_view_of_a_sequence_folder_shows_its_depth_and_colour(wave_sequence, tmp_path):
    rrd = tmp_path / "seq.rrd"
    assert main(["view", str(wave_sequence), "--rrd", str(rrd), "--quiet"]) == 0
    rows = read_rrd(rrd)
    check_depth(rows, wave_sequence, list(range(6)))
    assert sorted(by_frame(rows["/world/camera/image"], "EncodedImage:blob")) == list(range(6))
    assert not any(entity.startswith("/world/bodies") for entity in rows)


def test_a_body_that_leaves_is_cleared(tmp_path):
    from swarmpose.publish.rerun_view import open_view_sink

    def message(frame: int, ids: list[int]) -> dict:
        joint = {"position_m": [0.1, 0.2, 3.0], "pixel": [300.0, 200.0], "confidence": 0.5}
        return {"frame": frame, "capture_ns": frame * 33_000_000, "latency_ms": 1.0, "reason": "",
                "bodies": [{"id": i, "state": "tracking", "reason": "", "joints": {"head": joint}} for i in ids]}

    sink = open_view_sink("camera0", rrd=str(tmp_path / "ids.rrd"))
    for frame, ids in enumerate([[0, 3], [0, 3], [0]]):
        sink.frame(message(frame, ids), None)
    sink.close()
    rows = read_rrd(tmp_path / "ids.rrd")
    assert sorted(by_frame(rows["/world/bodies/3/joints"], "Points3D:positions")) == [0, 1]
    cleared = [r["frame"] for r in rows["/world/bodies/3"] if r.get("Clear:is_recursive") == [True]]
    assert cleared == [2]
    assert sorted(by_frame(rows["/world/bodies/0/joints"], "Points3D:positions")) == [0, 1, 2]
    # the camera's capture clock (not a UNIX time) becomes a duration timeline
    capture = {r["frame"]: r["capture"] for r in rows["/world/bodies/0/joints"]}
    assert [capture[f] for f in range(3)] == [timedelta(milliseconds=33 * f) for f in range(3)]


def test_world_coordinates_place_the_camera_by_the_message_transform(tmp_path):
    """A message in world coordinates: ``world`` turns y up (RUB) and ``world/camera`` (the depth
    and image under it) gets the message's camera_to_world; the joints stay the message's values."""
    from swarmpose.publish.rerun_view import open_view_sink

    angle = np.radians(10.0)
    pose = np.array([[1.0, 0.0, 0.0, 0.2], [0.0, -np.cos(angle), np.sin(angle), 1.3],
                     [0.0, -np.sin(angle), -np.cos(angle), 3.0], [0.0, 0.0, 0.0, 1.0]])
    joint = {"position_m": [0.1, 1.6, 0.05], "pixel": [300.0, 200.0], "confidence": 1.0}
    camera_message = {"frame": 0, "capture_ns": 0, "latency_ms": 1.0, "reason": "", "coordinates": "camera",
                      "camera_to_world": None, "bodies": []}
    world_message = {"frame": 1, "capture_ns": 33_000_000, "latency_ms": 1.0, "reason": "", "coordinates": "world",
                     "camera_to_world": pose.tolist(),
                     "bodies": [{"id": 0, "state": "tracking", "reason": "", "joints": {"head": joint}}]}
    sink = open_view_sink("camera0", rrd=str(tmp_path / "w.rrd"))
    sink.frame(camera_message, None)
    sink.frame(world_message, None)
    sink.close()
    rows = read_rrd(tmp_path / "w.rrd")
    axes = by_frame(rows["/world"], "ViewCoordinates:xyz")
    assert axes == {0: [rerun.components.ViewCoordinates.RDF.as_arrow_array().to_pylist()[0]],
                    1: [rerun.components.ViewCoordinates.RUB.as_arrow_array().to_pylist()[0]]}
    rotation = by_frame(rows["/world/camera"], "Transform3D:mat3x3")
    translation = by_frame(rows["/world/camera"], "Transform3D:translation")
    np.testing.assert_allclose(np.ravel(rotation[0]), np.eye(3).ravel(order="F"))
    np.testing.assert_allclose(np.ravel(rotation[1]), pose[:3, :3].ravel(order="F"), atol=1e-7)  # column-major
    np.testing.assert_allclose(np.ravel(translation[1]), pose[:3, 3], atol=1e-7)
    np.testing.assert_array_equal(by_frame(rows["/world/bodies/0/joints"], "Points3D:positions")[1],
                                  np.float32([joint["position_m"]]))


@pytest.mark.parametrize("case", ["missing", "bad line", "unwritable rrd", "port in use"])
def test_view_of_bad_input_is_a_clear_error(case, tracked, tmp_path, capsys, monkeypatch):
    _, out, _ = tracked
    rrd = tmp_path / "x.rrd"
    taken = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    taken.bind(("0.0.0.0", 0))
    taken.listen()
    if case == "port in use":  # no display: the view would be served on that port
        monkeypatch.delenv("DISPLAY", raising=False)
        monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
        args, words = [str(out), "--view-port", str(taken.getsockname()[1])], "choose another --view-port"
    elif case == "missing":
        args, words = [str(tmp_path / "nothing"), "--rrd", str(rrd)], "no such file or folder"
    elif case == "bad line":
        bad = tmp_path / "poses.jsonl"
        bad.write_text((out / "poses.jsonl").read_text().splitlines()[0] + "\n{\"frame\": 1, \"bod\n")
        args, words = [str(bad), "--rrd", str(rrd)], "line 2 is not a swarmpose.frame message"
    else:
        (tmp_path / "file").write_text("")
        args, words = [str(out), "--rrd", str(tmp_path / "file" / "x.rrd")], "cannot write the rerun recording"
    with taken:
        assert main(["view", *args, "--quiet"]) == 2
    assert words in capsys.readouterr().err


def received_all(path: Path, frames: int = 6) -> bool:
    """Whether the .rrd being written at ``path`` already holds ``frames`` frames of depth and joints."""
    try:
        rows = read_rrd(path)
    except Exception:  # not there yet, or its last message still half written
        return False
    return all(len(by_frame(rows.get(e, []), "Points3D:positions")) == frames
               for e in ("/world/camera/depth", "/world/bodies/0/joints"))


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore:RRD file has no footer")
def test_a_headless_view_is_served_to_a_remote_viewer(tracked, tmp_path):
    """Without a display, `swarmpose view` serves the recording over gRPC; rerun's own client
    (`rerun --save FILE URL`) receives all of it and stops when the view does (SIGTERM: exit 0)."""
    rerun_exe = shutil.which("rerun", path=str(Path(sys.executable).parent)) or shutil.which("rerun")
    if rerun_exe is None:
        pytest.skip("the rerun executable (from rerun-sdk) is not on PATH")
    sequence, out, _ = tracked
    port = free_port()
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    view = subprocess.Popen([sys.executable, "-m", "swarmpose", "view", str(out), "--source", str(sequence),
                             "--view-port", str(port)], env=env, stderr=subprocess.PIPE, text=True)
    saved = tmp_path / "served.rrd"
    saver = None
    try:
        for line in view.stderr:
            if "serving until" in line:
                break
        else:
            pytest.fail(f"view ended without serving (exit {view.wait()})")
        saver = subprocess.Popen([rerun_exe, "--port", str(free_port()), "--save", str(saved),
                                  f"rerun+http://127.0.0.1:{port}/proxy"], stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL, env=env)
        wait_until(lambda: received_all(saved), 60, 0.2)  # synchronisation, not a speed requirement
        view.send_signal(signal.SIGTERM)
        assert view.wait(timeout=60) == 0
        assert saver.wait(timeout=60) == 0
    finally:
        for process in (view, saver):
            if process is not None and process.poll() is None:
                process.kill()
    rows = read_rrd(saved)
    check_bodies(rows, messages_of(out))
    check_depth(rows, sequence, list(range(6)))


def test_a_served_view_names_its_url_even_when_quiet(caplog, monkeypatch):
    """Without a display the URL is the only way to the view: it is said at warning level, which
    --quiet keeps, and says the view lasts as long as the process."""
    import logging

    from swarmpose.publish import rerun_stream

    monkeypatch.setattr(rerun_stream, "has_display", lambda: False)
    caplog.set_level(logging.WARNING, logger="swarmpose")
    stream = rerun_stream.open_stream("cam", view=True, port=free_port())
    try:
        said = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
        assert any("serving the view on rerun+http://" in m and "while this process runs" in m for m in said), said
    finally:
        stream.close()
