"""`folder:` sources: swarmpose/Open3D sequence folders and TUM RGB-D folders, read back against the
pixels the tests wrote (and another library's reading of the same files)."""

from __future__ import annotations

import json
from decimal import Decimal
from pathlib import Path

import cv2
import numpy as np
import pytest
from skimage import io as skio

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError, SourceError
from swarmpose.sources.base import Frame, SkippedFrame
from swarmpose.sources.folder import FolderSource
from swarmpose.sources.registry import open_source

W, H = 64, 48
INTR = Intrinsics(W, H, 60.0, 61.0, 31.5, 23.5)


def _depth_mm(i: int) -> np.ndarray:
    """A distinct uint16 millimetre image per frame: 1000 + 10 i + column, with a hole."""
    d = (1000 + 10 * i + np.arange(W)[None, :] + np.zeros((H, 1))).astype(np.uint16)
    d[5:9, 7:11] = 0
    return d


def _rgb(i: int) -> np.ndarray:
    rgb = np.zeros((H, W, 3), np.uint8)
    rgb[..., 0] = 200  # red
    rgb[..., 1] = (np.arange(W) * 3)[None, :]
    rgb[..., 2] = i
    return rgb


def _write_sequence(folder: Path, n: int, fps: float = 15.0, frames: int | None = None) -> Path:
    (folder / "color").mkdir(parents=True)
    (folder / "depth").mkdir()
    for i in range(n):
        cv2.imwrite(str(folder / "color" / f"{i:06d}.png"), cv2.cvtColor(_rgb(i), cv2.COLOR_RGB2BGR))
        cv2.imwrite(str(folder / "depth" / f"{i:06d}.png"), _depth_mm(i))
    INTR.save(folder / "intrinsic.json")
    (folder / "sequence.json").write_text(json.dumps({"fps": fps, "frames": frames if frames is not None else n}))
    return folder


def test_sequence_folder_round_trip(tmp_path):
    """Depth comes back as the written millimetres / 1000, colour as RGB (skimage's reading of the
    PNG), stamped i / fps, with the intrinsics of intrinsic.json."""
    seq = _write_sequence(tmp_path / "seq", 4, fps=15.0)
    with open_source(f"folder:{seq}") as src:
        assert isinstance(src, FolderSource) and src.length == 4 and src.fps == 15.0
        assert src.ground_truth is None and src.folder == seq
        items = list(src)
        assert src.status == "ended"
    assert [type(f) for f in items] == [Frame] * 4
    for i, f in enumerate(items):
        assert f.index == i and f.timestamp_ns == round(i * 1e9 / 15.0)
        assert f.depth.dtype == np.float32 and f.depth.shape == (H, W)
        np.testing.assert_array_equal(f.depth, _depth_mm(i).astype(np.float32) / np.float32(1000))
        assert f.depth[6, 8] == 0.0 and f.depth[0, 0] == pytest.approx(1.0 + 0.01 * i)
        np.testing.assert_array_equal(f.color, skio.imread(seq / "color" / f"{i:06d}.png"))
        assert tuple(f.color[0, 0]) == (200, 0, i)
        assert f.intrinsics == INTR and f.size == (W, H)


def test_bare_directory_is_a_folder_source(tmp_path):
    seq = _write_sequence(tmp_path / "seq", 2)
    with open_source(str(seq)) as src:
        assert isinstance(src, FolderSource) and len(list(src)) == 2


def test_missing_and_corrupt_files_are_skipped_and_iteration_goes_on(tmp_path):
    """0 ok, 1 lacks depth, 2 lacks colour, 3 has a corrupt depth PNG, 4 is a gap in the numbering up
    to sequence.json's frames = 6, 5 ok: four SkippedFrames naming the files, then frame 5."""
    seq = _write_sequence(tmp_path / "seq", 6, fps=30.0)
    (seq / "depth" / "000001.png").unlink()
    (seq / "color" / "000002.png").unlink()
    (seq / "depth" / "000003.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"garbage" * 20)
    (seq / "color" / "000004.png").unlink()
    (seq / "depth" / "000004.png").unlink()
    with open_source(f"folder:{seq}") as src:
        items = list(src)
        assert src.status == "ended" and src.length == 6
    assert [type(f).__name__ for f in items] == ["Frame", "SkippedFrame", "SkippedFrame", "SkippedFrame",
                                                 "SkippedFrame", "Frame"]
    assert [f.index for f in items] == list(range(6))
    assert "depth/000001.png" in items[1].reason and "missing" in items[1].reason
    assert "color/000002" in items[2].reason
    assert "000003.png" in items[3].reason and "cannot be decoded" in items[3].reason
    assert "000004" in items[4].reason and "6 frames" in items[4].reason
    assert items[4].timestamp_ns == round(4e9 / 30)
    np.testing.assert_array_equal(items[5].depth, _depth_mm(5) / np.float32(1000))


def test_size_mismatch_first_frame_raises_later_frame_is_skipped(tmp_path):
    seq = _write_sequence(tmp_path / "a", 3)
    cv2.imwrite(str(seq / "color" / "000002.png"), np.zeros((H // 2, W // 2, 3), np.uint8))
    items = list(open_source(f"folder:{seq}"))
    assert isinstance(items[2], SkippedFrame) and "differ in size" in items[2].reason
    assert "depth 64x48 and colour 32x24" in items[2].reason

    seq = _write_sequence(tmp_path / "b", 2)
    cv2.imwrite(str(seq / "color" / "000000.png"), np.zeros((H * 2, W * 2, 3), np.uint8))
    with pytest.raises(SourceError, match="differ in size.*register the depth"):
        open_source(f"folder:{seq}")


def test_bad_folders_raise_clear_errors(tmp_path):
    with pytest.raises(SourceError, match="does not exist"):
        open_source(f"folder:{tmp_path / 'nope'}")
    with pytest.raises(SourceError, match="not an RGBD sequence"):
        open_source(f"folder:{tmp_path}")
    seq = _write_sequence(tmp_path / "seq", 1)
    (seq / "intrinsic.json").unlink()
    with pytest.raises(SourceError, match="no intrinsic.json"):
        open_source(f"folder:{seq}")
    with pytest.raises(ConfigError, match="unknown source scheme 'fodler'.*folder:DIR"):
        open_source(f"fodler:{seq}")
    with pytest.raises(SourceError, match="neither an existing folder"):
        open_source(str(tmp_path / "nope"))


def _write_tum(folder: Path) -> tuple[list[float], list[float]]:
    """A TUM RGB-D folder: depth at 30 Hz, colour 5 ms later except the third depth image, which has
    no colour within 20 ms, and one extra colour image with no depth near it."""
    (folder / "rgb").mkdir(parents=True)
    (folder / "depth").mkdir()
    t0 = 1305031102.160407
    depth_t = [t0 + k / 30 for k in range(4)]
    rgb_t = [t + 0.005 for k, t in enumerate(depth_t) if k != 2] + [t0 + 10.0]
    for k, t in enumerate(depth_t):
        cv2.imwrite(str(folder / "depth" / f"{t:.6f}.png"), (np.full((480, 640), 5000 + 500 * k)).astype(np.uint16))
    for k, t in enumerate(rgb_t):
        cv2.imwrite(str(folder / "rgb" / f"{t:.6f}.png"), np.full((480, 640, 3), k, np.uint8))
    header = "# timestamp filename\n# written by the test\n"
    (folder / "depth.txt").write_text(header + "".join(f"{t:.6f} depth/{t:.6f}.png\n" for t in depth_t))
    (folder / "rgb.txt").write_text(header + "".join(f"{t:.6f} rgb/{t:.6f}.png\n" for t in rgb_t))
    return depth_t, rgb_t


def test_tum_folder_association_scale_and_default_intrinsics(tmp_path):
    depth_t, rgb_t = _write_tum(tmp_path / "tum")
    with open_source(f"folder:{tmp_path / 'tum'}") as src:
        assert src.layout == "tum" and src.fps == pytest.approx(30.0, rel=1e-3)
        assert src.intrinsics == Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)
        items = list(src)
    assert [type(f).__name__ for f in items] == ["Frame", "Frame", "SkippedFrame", "Frame", "SkippedFrame"]
    frames = [f for f in items if isinstance(f, Frame)]
    for f, k in zip(frames, (0, 1, 3)):
        assert f.timestamp_ns == int(Decimal(f"{depth_t[k]:.6f}") * 10**9)  # exact, as written in depth.txt
        assert np.all(f.depth == pytest.approx((5000 + 500 * k) / 5000.0))  # 5000 units per metre
    assert [int(f.color[0, 0, 0]) for f in frames] == [0, 1, 2]  # the colour image 5 ms later
    assert "no colour image within 20 ms" in items[2].reason and f"{depth_t[2]:.6f}" in items[2].reason
    assert "no depth image within 20 ms" in items[4].reason


def test_tum_folder_uses_intrinsic_json_when_present(tmp_path):
    _write_tum(tmp_path / "tum")
    (tmp_path / "tum" / "intrinsic.json").write_text(json.dumps(
        {"width": 640, "height": 480, "fx": 517.3, "fy": 516.5, "cx": 318.6, "cy": 255.3}))
    with open_source(f"folder:{tmp_path / 'tum'}") as src:
        assert src.intrinsics == Intrinsics(640, 480, 517.3, 516.5, 318.6, 255.3)


@pytest.fixture(scope="module")
def synth_seq(tmp_path_factory) -> Path:
    from swarmpose.body.loader import load_body
    from swarmpose.motion.builtin import builtin_motion
    from swarmpose.sim.synth import SynthConfig, synthesize

    out = tmp_path_factory.mktemp("synth")
    synthesize(load_body("builtin").tracking_lod(1500), builtin_motion("wave", 3, 30.0), out,
               SynthConfig(frames=3), progress=False)
    return out


def test_synth_folder_frames_match_open3d_reading_and_ground_truth(synth_seq):
    """The frames of `swarmpose synth` output equal Open3D's own reading of the PNGs, and the ground
    truth comes with the source."""
    import open3d as o3d

    with open_source(f"folder:{synth_seq}") as src:
        assert src.fps == 30.0 and src.length == 3
        assert src.ground_truth is not None and src.ground_truth.frames == (0, 1, 2)
        frames = list(src)
    intr = o3d.io.read_pinhole_camera_intrinsic(str(synth_seq / "intrinsic.json"))
    for f in frames:
        depth = np.asarray(o3d.io.read_image(str(synth_seq / "depth" / f"{f.index:06d}.png")), np.float32) / 1000
        np.testing.assert_allclose(f.depth, depth, rtol=0, atol=1e-6)
        np.testing.assert_array_equal(f.color, np.asarray(o3d.io.read_image(str(synth_seq / "color" /
                                                                              f"{f.index:06d}.png"))))
        np.testing.assert_allclose(f.intrinsics.matrix, intr.intrinsic_matrix)
        assert f.timestamp_ns == round(f.index * 1e9 / 30)
