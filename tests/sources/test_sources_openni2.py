"""`openni2:` through the real OpenNI2 library (Debian's libopenni2) and its DummyDevice driver.

A child process records the Dummy device's depth and colour streams with openni2.Recorder; the
.oni file is then played back by the source and every frame compared with the image the Dummy
driver draws for that frame number, computed here by hand from the driver's source (OpenNI2's
Source/Drivers/DummyDevice/DummyDevice.cpp: a disc of radius sqrt(70) px bouncing across a
320x240 image, depth 1000 + 3 (x - y) mm inside it, the top row 2000 mm). Two defects of
Debian's OpenNI2 2.2.0.33 shape this (see swarmpose.sources.openni2): a process that opened Dummy
segfaults when it exits, so Dummy is only opened in child processes; and the OniFile player drops
every frame of a Dummy recording because Dummy's streams lack the cropping property, so the test
adds that one property record (cropping off) to the recording before playing it. Real OpenNI2
devices cannot be tested here.
"""

from __future__ import annotations

import json
import signal
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from swarmpose.core.errors import SourceError
from swarmpose.sources.base import Frame
from swarmpose.sources.openni2 import APT_PACKAGES, OpenNI2Source, locate_openni2
from swarmpose.sources.registry import open_source

try:
    LIBDIR = locate_openni2()
except SourceError as exc:  # a machine without libopenni2: nothing of this module can run
    pytest.skip(f"OpenNI2 is not installed ({exc})", allow_module_level=True)

RECORD = r"""
import os, sys, time
from openni import openni2
openni2.initialize(sys.argv[2])
dev = openni2.Device(b"Dummy")
depth, color = dev.create_depth_stream(), dev.create_color_stream()
depth.start(); color.start()
rec = openni2.Recorder(sys.argv[1].encode())
rec.attach(depth); rec.attach(color)
rec.start()
time.sleep(0.25)  # about 7 frames at Dummy's 30 Hz
rec.stop()
rec.close()  # writes the seek tables and closes the file
os._exit(0)  # skip OpenNI2's shutdown and Dummy's teardown: Debian's Dummy crashes there
"""


def _disc_centre(frame_id: int, start: tuple[int, int], step: tuple[int, int]) -> tuple[int, int]:
    """Where DummyDevice's bouncing disc is in frame ``frame_id`` (1-based), as its Mainloop moves it."""
    (x, y), (dx, dy) = start, step
    for _ in range(frame_id - 1):
        x, y = x + dx, y + dy
        if x < abs(dx) or x > 320 - 1 - abs(dx):
            dx = -dx
        if y < abs(dy) or y > 240 - 1 - abs(dy):
            dy = -dy
    return x, y


def _disc(centre: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    cx, cy = centre
    y, x = np.mgrid[max(cy - 10, 0):min(cy + 10, 240), max(cx - 10, 0):min(cx + 10, 320)]
    inside = (x - cx) ** 2 + (y - cy) ** 2 < 70
    return y[inside], x[inside]


def dummy_depth_mm(frame_id: int) -> np.ndarray:
    """DummyDevice's depth frame: the disc (start (0, 0), step (1, 1)) at 1000 + 3 (x - y) mm, row 0 at 2000 mm."""
    depth = np.zeros((240, 320), np.uint16)
    y, x = _disc(_disc_centre(frame_id, (0, 0), (1, 1)))
    depth[y, x] = 1000 + 3 * (x - y)
    depth[0, :] = 2000
    return depth


def dummy_rgb(frame_id: int) -> np.ndarray:
    """DummyDevice's colour frame: the disc (start (160, 120), step (-3, 1)) coloured by position, pixel 0 blue."""
    rgb = np.zeros((240, 320, 3), np.uint8)
    y, x = _disc(_disc_centre(frame_id, (160, 120), (-3, 1)))
    rgb[y, x] = np.column_stack([(255 * x) // 320, (255 * y) // 240, (255 * (320 - x)) // 320])
    rgb[0, 0, 2] = 255
    return rgb

HEADER = struct.Struct("<4sIIIIQ")  # ONI record header: magic, type, node, fields size, payload size, undo pos
SEEK_ENTRY = struct.Struct("<QIQ")  # seek table entry: timestamp, configuration id, file position
NODE_ADDED, GENERAL_PROPERTY, SEEK_TABLE, END = 0x0D, 0x06, 0x0E, 0x0B


def add_cropping_property(src: Path, dst: Path) -> None:
    """Copy an .oni recording, adding after each node's NODE_ADDED record a general property
    ``xnCropping`` = {enabled 0, 0, 0, 0, 0} (12 bytes) and shifting every file position that
    points past an insertion (undo positions, the NODE_ADDED seek-table position, seek tables)."""
    buf = src.read_bytes()
    records, pos = [], 24  # after the file header
    while pos + HEADER.size <= len(buf):
        magic, kind, node, fields, payload, _ = HEADER.unpack_from(buf, pos)
        assert magic == b"NIR\0", f"not an ONI record at {pos}"
        records.append((pos, kind, node, fields, payload))
        pos += fields + payload
        if kind == END:
            break
    inserts = {}
    for pos, kind, node, fields, payload in records:
        if kind == NODE_ADDED:
            name = b"xnCropping\0"
            body = struct.pack("<I", len(name)) + name + struct.pack("<I", 12) + struct.pack("<IHHHH", 0, 0, 0, 0, 0)
            inserts[pos + fields + payload] = HEADER.pack(b"NIR\0", GENERAL_PROPERTY, node, HEADER.size + len(body),
                                                          0, 0) + body

    def moved(p: int) -> int:
        return p + sum(len(b) for at, b in inserts.items() if p >= at) if p else 0

    out = bytearray(buf[:24])
    for pos, kind, _, fields, payload in records:
        rec = bytearray(buf[pos:pos + fields + payload])
        struct.pack_into("<Q", rec, 20, moved(struct.unpack_from("<Q", rec, 20)[0]))
        if kind == NODE_ADDED:
            struct.pack_into("<Q", rec, fields - 8, moved(struct.unpack_from("<Q", rec, fields - 8)[0]))
        elif kind == SEEK_TABLE:
            for off in range(fields, fields + payload, SEEK_ENTRY.size):
                ts, cfg, at = SEEK_ENTRY.unpack_from(rec, off)
                SEEK_ENTRY.pack_into(rec, off, ts, cfg, moved(at))
        out += rec
        out += inserts.get(pos + fields + payload, b"")
    dst.write_bytes(bytes(out))


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp("oni")
    raw = folder / "dummy.oni"
    subprocess.run([sys.executable, "-c", RECORD, str(raw), str(LIBDIR)], check=True, timeout=60)
    fixed = folder / "dummy_cropping.oni"
    add_cropping_property(raw, fixed)
    return raw, fixed


def test_recording_plays_back_frame_for_frame(recording):
    """Every played-back frame is exactly the Dummy driver's drawing of one frame number, depth in
    metres (the disc's 1000 + 3 (x - y) mm as 1.000 + 0.003 (x - y) m, the top row at 2.0 m), the
    frame numbers consecutive (the last frame may lack colour when the recorder stopped between
    the two streams); 320x240, the recording's 33 ms clock from 0, not registered (Dummy
    cannot), nominal intrinsics (f = 525 px at 640 px wide)."""
    _, fixed = recording
    with open_source(f"openni2:{fixed}") as src:
        assert isinstance(src, OpenNI2Source) and src.length >= 3
        assert src.registered is False and src.intrinsics_nominal is True
        assert (src.intrinsics.fx, src.intrinsics.cx, src.intrinsics.cy) == (262.5, 159.5, 119.5)
        frames = list(src)
        assert src.status == "ended"
    assert len(frames) == src.length and all(isinstance(f, Frame) for f in frames)
    depth_ids, color_ids = [], []
    for k, f in enumerate(frames):
        assert f.index == k and f.size == (320, 240) and f.depth.dtype == np.float32
        assert f.timestamp_ns == 33_000_000 * k
        ids = [i for i in range(1, 80) if np.array_equal(f.depth, dummy_depth_mm(i) / np.float32(1000))]
        assert len(ids) == 1, f"frame {k}: depth matches Dummy frames {ids}"
        depth_ids.append(ids[0])
        if f.color is None:  # the recorder stopped between a depth frame and its colour frame
            assert k == len(frames) - 1, f"frame {k} lacks colour"
            continue
        ids = [i for i in range(1, 80) if np.array_equal(f.color, dummy_rgb(i))]
        assert len(ids) == 1, f"frame {k}: colour matches Dummy frames {ids}"
        color_ids.append(ids[0])
        assert f.depth[0].max() == 2.0 and f.depth[1:].max() < 1.1
    assert np.all(np.diff(depth_ids) == 1) and np.all(np.diff(color_ids) == 1)


@pytest.mark.slow
def test_player_defect_without_the_cropping_property(recording):
    """The untouched Dummy recording opens but Debian's player delivers no frame: a clear error."""
    raw, _ = recording
    src = open_source(f"openni2:{raw}")
    src.read_timeout_s = 0.5
    with pytest.raises(SourceError, match="delivers no frames"):
        list(src)
    src.close()


def test_live_dummy_device_through_probe():
    """`openni2:Dummy` live, in a child process: three 320x240 frames with metric depth. The child's
    exit status is 0 or, from Debian's Dummy shutdown defect, SIGSEGV after its output."""
    proc = subprocess.run([sys.executable, "-m", "swarmpose", "probe", "--source", "openni2:Dummy",
                           "--frames", "3", "--json"], capture_output=True, text=True, timeout=120)
    assert proc.returncode in (0, -signal.SIGSEGV), proc.stderr
    lines = [json.loads(line) for line in proc.stdout.splitlines()]
    frames, summary = lines[:-1], lines[-1]["summary"]
    assert len(frames) == 3 and all(f["width"] == 320 and f["height"] == 240 for f in frames)
    assert all(f["depth_max_m"] == 2.0 and f["valid_fraction"] > 0 for f in frames)
    assert summary["frames_read"] == 3 and summary["status"] == "open" and summary["nominal_fps"] == 30.0


def test_missing_file_and_no_device(tmp_path):
    with pytest.raises(SourceError, match=r"openni2: file .*none\.oni does not exist"):
        open_source(f"openni2:{tmp_path / 'none.oni'}")
    from swarmpose.sources.openni2 import openni2_module

    if [u for u in openni2_module().Device.enumerate_uris() if not u.lower().endswith(b".oni")]:
        pytest.skip("an OpenNI2 device is connected")
    with pytest.raises(SourceError, match="no OpenNI2 device is connected"):
        open_source("openni2:")


def test_missing_library_names_the_apt_packages(tmp_path):
    with pytest.raises(SourceError, match=" ".join(APT_PACKAGES)):
        locate_openni2([tmp_path])
    (tmp_path / "libOpenNI2.so.0").write_bytes(b"")
    with pytest.raises(SourceError, match="libOpenNI2.so.0 exists but not libOpenNI2.so.*libopenni2-dev"):
        locate_openni2([tmp_path])
    assert (LIBDIR / "libOpenNI2.so").is_file() and (LIBDIR / "OpenNI2" / "Drivers").is_dir()
