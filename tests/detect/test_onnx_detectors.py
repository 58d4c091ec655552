"""ONNX pose detectors (MoveNet, BlazePose) against real ground truth: a COCO photo and a synth render."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import ASSETS, BLAZEPOSE_COCO_BOUND_PX, MAKEHUMAN, MOVENET_COCO_BOUND_PX, needs_assets

from swarmpose.body.skeleton import COCO17
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import DetectorError
from swarmpose.detect.onnx_pose import OnnxPoseDetector, Square, crop_square, square_around, whole_frame
from swarmpose.sources.base import Frame

MOVENET = ASSETS / "pose2d" / "movenet_singlepose_lightning.onnx"
BLAZEPOSE = ASSETS / "pose2d" / "blazepose_landmark_full.onnx"
PHOTO = ASSETS / "images" / "coco_val2017_000000000785.jpg"
PHOTO_TRUTH = ASSETS / "images" / "coco_val2017_000000000785_keypoints.json"

# Bounds a little above the measured medians (see each test's docstring).
MOVENET_RENDER_BOUND_PX = 12.0


def _frame(rgb: np.ndarray, index: int = 0, timestamp_ns: int = 0) -> Frame:
    h, w = rgb.shape[:2]
    return Frame(index, timestamp_ns, np.zeros((h, w), np.float32), rgb,
                 Intrinsics(w, h, 525.0, 525.0, (w - 1) / 2, (h - 1) / 2))


def _read_rgb(path: Path) -> np.ndarray:
    return cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)


@pytest.fixture(scope="module")
def photo():
    """The COCO photo as a Frame, its annotated keypoints (17, 3) (x, y, visibility) and box [x0, y0, x1, y1]."""
    ann = json.loads(PHOTO_TRUTH.read_text())["annotations"]
    assert len(ann) == 1
    x, y, w, h = ann[0]["bbox"]
    return _frame(_read_rgb(PHOTO)), np.array(ann[0]["keypoints"], float).reshape(17, 3), np.array([x, y, x + w, y + h])


@pytest.fixture(scope="module")
def movenet():
    det = OnnxPoseDetector(MOVENET)
    yield det
    det.close()


@pytest.fixture(scope="module")
def blazepose():
    det = OnnxPoseDetector(BLAZEPOSE)
    yield det
    det.close()


def _coco_errors(joints, truth: np.ndarray) -> np.ndarray:
    """Pixel distances over the labelled COCO keypoints, matching keypoints by name."""
    names = [n for n, (_, _, v) in zip(COCO17.keypoints, truth) if v > 0]
    got = np.array([joints.keypoints[joints.layout.keypoints.index(n), :2] for n in names])
    want = np.array([truth[COCO17.keypoints.index(n), :2] for n in names])
    return np.linalg.norm(got - want, axis=1)


@needs_assets
def test_movenet_on_the_coco_photo(movenet, photo):
    """Whole photo padded to a square: measured median 5.19 px over the 17 labelled keypoints
    (the photo is 640x425, the person about 350 px tall)."""
    frame, truth, _ = photo
    joints = movenet.detect(frame)
    assert movenet.layout.name == "coco17" and joints.keypoints.shape == (17, 3)
    assert (joints.frame_index, joints.timestamp_ns) == (0, 0)
    errors = _coco_errors(joints, truth)
    assert len(errors) == 17
    assert np.median(errors) < MOVENET_COCO_BOUND_PX
    assert np.all((joints.keypoints[:, 2] > 0.2) & (joints.keypoints[:, 2] <= 1.0))


@needs_assets
def test_movenet_with_a_box_crops_around_it(movenet, photo):
    """Crop = the annotated box enlarged 1.25x to a square: measured median 6.46 px."""
    frame, truth, box = photo
    assert np.median(_coco_errors(movenet.detect(frame, box), truth)) < MOVENET_COCO_BOUND_PX + 1.5


@needs_assets
def test_blazepose_on_the_coco_photo_with_the_annotated_box(blazepose, photo):
    """Crop = the annotated box enlarged 1.25x to a square: measured median 7.13 px over the 17 COCO
    keypoints. Scores are sigmoid(visibility): the raw logits run 1.7..12.5, so the scores of
    this clearly visible person are all above 0.8 and at most 1."""
    frame, truth, box = photo
    blazepose.reset()
    joints = blazepose.detect(frame, box)
    assert blazepose.layout.name == "blazepose33" and joints.keypoints.shape == (33, 3)
    assert np.median(_coco_errors(joints, truth)) < BLAZEPOSE_COCO_BOUND_PX
    coco = [joints.layout.keypoints.index(n) for n in COCO17.keypoints]
    assert np.all((joints.keypoints[coco, 2] > 0.8) & (joints.keypoints[coco, 2] <= 1.0))


@needs_assets
def test_blazepose_without_a_box_follows_its_previous_detection(photo):
    """Without the second pass: the first call sees the whole photo (measured 11.4 px), the
    next frame crops the region that detection's alignment points gave (measured 6.1 px)."""
    frame, truth, _ = photo
    single = OnnxPoseDetector(BLAZEPOSE, refine=False)
    first = single.detect(frame)
    second = single.detect(replace(frame, index=1))
    assert np.median(_coco_errors(second, truth)) < BLAZEPOSE_COCO_BOUND_PX
    assert np.median(_coco_errors(first, truth)) > np.median(_coco_errors(second, truth))
    single.reset()
    np.testing.assert_allclose(single.detect(frame).keypoints, first.keypoints, atol=1e-4)


@needs_assets
def test_blazepose_refines_its_first_whole_frame_detection_on_a_crop(blazepose, photo):
    """With the second pass (the default) the first call is as good as the followed one of the
    single-pass detector: measured 6.3 px against 11.4 px for the whole photo alone."""
    frame, truth, _ = photo
    blazepose.reset()
    first = blazepose.detect(frame)
    whole = OnnxPoseDetector(BLAZEPOSE, refine=False).detect(frame)
    assert np.median(_coco_errors(first, truth)) < BLAZEPOSE_COCO_BOUND_PX
    assert np.median(_coco_errors(first, truth)) < np.median(_coco_errors(whole, truth)) - 2


@needs_assets
def test_blazepose_reports_nobody_on_an_empty_frame_and_forgets_the_crop(blazepose, photo):
    frame, _, box = photo
    blazepose.detect(frame, box)
    empty = blazepose.detect(_frame(np.zeros((480, 640, 3), np.uint8), index=1))
    assert np.all(empty.keypoints == 0)
    blazepose.reset()
    whole = blazepose.detect(frame)
    blazepose.detect(_frame(np.zeros((480, 640, 3), np.uint8), index=1))
    np.testing.assert_allclose(blazepose.detect(frame).keypoints, whole.keypoints, atol=1e-4)


@needs_assets
def test_blazepose_remembers_the_region_its_alignment_points_give(photo):
    """After a detection, the region of the next crop is centred on the annotated hips (measured 8.5
    px off, the person 289 px tall) and turned along the hips-to-shoulders axis (measured 8.8 degrees)."""
    frame, truth, box = photo
    det = OnnxPoseDetector(BLAZEPOSE)
    det.detect(frame, box)
    region = det.adapter.found
    det.close()
    hips, shoulders = truth[11:13, :2].mean(axis=0), truth[5:7, :2].mean(axis=0)
    axis = (shoulders - hips) / np.linalg.norm(shoulders - hips)
    assert np.linalg.norm(np.array(region.centre) - hips) < 20.0
    assert np.degrees(np.arccos(np.dot(region.up, axis))) < 20.0
    assert box[3] - box[1] < region.side < 2.5 * (box[3] - box[1])


@needs_assets
def test_blazepose_crops_a_turned_body_turned(photo):
    """The COCO photo turned a quarter (the person lying across the frame): the square around the
    annotated box gives a median error of 90.5 px (measured), a region turned with the body's axis
    (the annotated hips to shoulders) 6.6 px, and the next detections, which crop the regions their
    own alignment points give, stay near it (measured 8.7, 9.6, 7.6 px)."""
    from swarmpose.detect.regions import aligned_square

    frame, truth, _ = photo
    height = frame.color.shape[0]
    turned = _frame(np.ascontiguousarray(cv2.rotate(frame.color, cv2.ROTATE_90_CLOCKWISE)))
    keypoints = truth.copy()
    keypoints[:, 0], keypoints[:, 1] = height - 1 - truth[:, 1], truth[:, 0]  # (x, y) -> (h - 1 - y, x)
    seen = keypoints[:, 2] > 0
    box = np.array([*keypoints[seen, :2].min(axis=0), *keypoints[seen, :2].max(axis=0)])
    det = OnnxPoseDetector(BLAZEPOSE)
    assert np.median(_coco_errors(det.detect(turned, box), keypoints)) > 40.0
    hips, shoulders = keypoints[11:13, :2].mean(axis=0), keypoints[5:7, :2].mean(axis=0)
    axis = (shoulders - hips) / np.linalg.norm(shoulders - hips)
    reach = np.max(np.linalg.norm(keypoints[seen, :2] - hips, axis=1))
    det.reset()
    det.adapter.begin(-1)  # as if a frame before had found the body there
    det.adapter.regions.add(aligned_square(hips, hips + reach * axis))
    errors = [np.median(_coco_errors(det.detect(replace(turned, index=k), box), keypoints)) for k in range(4)]
    det.close()
    assert errors[0] < BLAZEPOSE_COCO_BOUND_PX
    assert max(errors) < BLAZEPOSE_COCO_BOUND_PX + 4.0


@needs_assets
def test_blazepose_follows_the_pass_it_kept_and_not_a_crop_that_found_nobody(photo):
    """A whole-frame detection with its second pass leaves one region, that of the pass it returned
    (the two passes' regions differ); a crop with a box that finds nobody (an empty image) leaves none,
    so the next frame crops the box's square."""
    frame, _, box = photo
    det = OnnxPoseDetector(BLAZEPOSE)
    try:
        det.detect(frame)  # no box, nothing remembered: the whole photo, then the square around what it found
        kept = det.adapter.found
        det.adapter.begin(1)
        assert det.adapter.regions.last == (kept,)
        empty = _frame(np.zeros_like(frame.color), index=1)
        assert not det.detect(empty, box).keypoints.any()
        det.adapter.begin(2)
        assert det.adapter.regions.last == ()
        assert det.adapter.regions.region_for(box, square_around(box).side) is None
    finally:
        det.close()


@pytest.fixture(scope="module")
def far_side_render(tmp_path_factory):
    """One synth frame of the MakeHuman body walking (CMU 131_01), seen from its side at 4 m from
    2.2 m up (the accuracy benchmark's wall-mounted placement): about 150 px tall in 640x480."""
    from swarmpose.body.loader import load_body
    from swarmpose.motion.library import load_motion_spec
    from swarmpose.sim.synth import SynthConfig, synthesize

    out = tmp_path_factory.mktemp("side")
    body = load_body(f"makehuman:{MAKEHUMAN}")
    motion = load_motion_spec(str(ASSETS / "mocap" / "bvh11_131_01.bvh"), body, 1, 30.0)
    synthesize(body, motion, out, SynthConfig(frames=1, camera_yaw_deg=90.0, camera_height=2.2,
                                              camera_distance=4.0), progress=False)
    record = json.loads((out / "groundtruth.jsonl").read_text().splitlines()[0])
    return _frame(_read_rgb(out / "color" / "000000.png"), 0, record["timestamp_ns"]), record


def _limb_errors(joints, record) -> np.ndarray:
    found = joints.by_point(min_score=0.0)
    truth = {k: v for k, v in record["joints2d"].items() if k in COCO17.keypoints}
    return np.array([np.hypot(found[k][0] - x, found[k][1] - y) for k, (x, y) in truth.items() if k in found])


@needs_assets
def test_movenet_refines_a_small_person_on_a_crop(far_side_render):
    """A small person seen from the side: the whole frame alone gives a median error of
    14.7 px over the 12 limb joints, the second pass on the crop around it 6.7 px (measured)."""
    frame, record = far_side_render
    whole = _limb_errors(OnnxPoseDetector(MOVENET, refine=False).detect(frame), record)
    crop = _limb_errors(OnnxPoseDetector(MOVENET).detect(frame), record)
    assert len(crop) == 12
    assert np.median(crop) < np.median(whole)


@pytest.fixture(scope="module")
def makehuman_render(tmp_path_factory):
    """One synth frame of the full MakeHuman body (builtin wave) and its ground-truth record."""
    from swarmpose.body.loader import load_body
    from swarmpose.motion.builtin import builtin_motion
    from swarmpose.sim.synth import SynthConfig, synthesize

    out = tmp_path_factory.mktemp("mh")
    synthesize(load_body(f"makehuman:{MAKEHUMAN}"), builtin_motion("wave", 1, 30.0), out, SynthConfig(frames=1),
               progress=False)
    record = json.loads((out / "groundtruth.jsonl").read_text().splitlines()[0])
    return _frame(_read_rgb(out / "color" / "000000.png"), 0, record["timestamp_ns"]), record


@needs_assets
def test_movenet_finds_the_joints_on_a_makehuman_render(movenet, makehuman_render):
    """Every COCO joint the tracker evaluates (shoulders .. ankles) is found within 25 px of the
    projected ground-truth joint centre, on the right side; measured median 8.6 px (the person is
    about 300 px tall; networks place hips and shoulders on the surface, not at joint centres)."""
    frame, record = makehuman_render
    found = movenet.detect(frame).by_point(min_score=0.2)
    truth = {k: v for k, v in record["joints2d"].items() if k in COCO17.keypoints}
    assert len(truth) == 12
    errors = {k: np.hypot(found[k][0] - x, found[k][1] - y) for k, (x, y) in truth.items() if k in found}
    assert set(errors) == set(truth), f"missing: {set(truth) - set(errors)}"
    assert max(errors.values()) < 25.0, errors
    assert np.median(list(errors.values())) < MOVENET_RENDER_BOUND_PX


def test_crop_square_and_back_to_frame_pixels():
    """A marked pixel lands where the square mapping says, through padding and resizing."""
    image = np.zeros((60, 100, 3), np.uint8)
    image[10, 30] = 255
    square = whole_frame(100, 60)
    assert square == Square(0, -20, 100)
    crop = crop_square(image, square, 100)
    v, u = np.argwhere(crop[..., 0] == 255)[0]
    assert (u, v) == (30, 30)
    np.testing.assert_allclose(square.to_frame(np.array([(u + 0.5) / 100]), np.array([(v + 0.5) / 100])), [[30, 10]])
    big = crop_square(image, square, 200)  # 2x: the pixel covers crop pixels 60..61
    ys, xs = np.nonzero(big[..., 0] > 100)
    np.testing.assert_allclose(square.to_frame(np.array([(xs.mean() + 0.5) / 200]),
                                               np.array([(ys.mean() + 0.5) / 200])), [[30, 10]], atol=0.3)
    assert square_around([10, 20, 30, 60], 1.25) == Square(-5, 15, 50)
    with pytest.raises(DetectorError, match="box"):
        square_around([10, 20, 10, 20])


# -- unexpected or broken models: a tiny ONNX model written with the protobuf wire format ---------------

def _varint(n: int) -> bytes:
    out = bytearray()
    while True:
        b = n & 0x7F
        n >>= 7
        out.append(b | (0x80 if n else 0))
        if not n:
            return bytes(out)


def _msg(field: int, payload: bytes) -> bytes:
    return _varint(field << 3 | 2) + _varint(len(payload)) + payload


def _int(field: int, value: int) -> bytes:
    return _varint(field << 3) + _varint(value)


def _value_info(name: str, elem_type: int, shape: tuple[int, ...]) -> bytes:
    dims = b"".join(_msg(1, _int(1, d)) for d in shape)  # TensorShapeProto.dim{dim_value}
    tensor = _int(1, elem_type) + _msg(2, dims)  # TypeProto.Tensor{elem_type, shape}
    return _msg(1, name.encode()) + _msg(2, _msg(1, tensor))  # ValueInfoProto{name, type{tensor_type}}


def write_identity_model(path: Path, elem_type: int, shape: tuple[int, ...]) -> Path:
    """An ONNX model (IR 8, opset 13) whose one node is Identity x -> y of ``shape``.

    ModelProto{ir_version=1, graph=7, opset_import=8}; GraphProto{node=1, name=2, input=11, output=12};
    NodeProto{input=1, output=2, op_type=4}; elem_type 1 = float, 2 = uint8.
    """
    node = _msg(1, b"x") + _msg(2, b"y") + _msg(4, b"Identity")
    graph = (_msg(1, node) + _msg(2, b"tiny") + _msg(11, _value_info("x", elem_type, shape))
             + _msg(12, _value_info("y", elem_type, shape)))
    path.write_bytes(_int(1, 8) + _msg(7, graph) + _msg(8, _msg(1, b"") + _int(2, 13)))
    return path


def test_the_tiny_model_is_a_real_onnx_model(tmp_path):
    import onnxruntime as ort

    path = write_identity_model(tmp_path / "tiny.onnx", 1, (1, 3, 4, 4))
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    x = np.arange(48, dtype=np.float32).reshape(1, 3, 4, 4)
    np.testing.assert_array_equal(session.run(None, {"x": x})[0], x)


def test_a_model_with_unsupported_shapes_is_refused_naming_file_and_shapes(tmp_path):
    path = write_identity_model(tmp_path / "classifier.onnx", 1, (1, 3, 224, 224))
    with pytest.raises(DetectorError) as err:
        OnnxPoseDetector(path)
    text = str(err.value)
    assert str(path) in text and "(1, 3, 224, 224)" in text and "movenet" in text and "blazepose" in text


def test_a_movenet_input_with_the_wrong_output_is_refused(tmp_path):
    path = write_identity_model(tmp_path / "half.onnx", 2, (1, 192, 192, 3))
    with pytest.raises(DetectorError, match="half.onnx.*outputs \\[\\(1, 192, 192, 3\\)\\]"):
        OnnxPoseDetector(path)
    with pytest.raises(DetectorError, match="not what adapter 'movenet' needs"):
        OnnxPoseDetector(path, adapter="movenet")


def test_missing_and_corrupt_model_files_are_named(tmp_path):
    missing = tmp_path / "nope.onnx"
    with pytest.raises(DetectorError, match="nope.onnx not found"):
        OnnxPoseDetector(missing)
    corrupt = tmp_path / "corrupt.onnx"
    corrupt.write_bytes(b"this is not a protobuf \x00\xff" * 10)
    with pytest.raises(DetectorError, match=f"cannot load ONNX model {corrupt}"):
        OnnxPoseDetector(corrupt)


@needs_assets
def test_a_frame_without_colour_is_refused(movenet):
    frame = Frame(3, 0, np.zeros((48, 64), np.float32), None, Intrinsics(64, 48, 50, 50, 32, 24))
    with pytest.raises(DetectorError, match="colour.*frame 3"):
        movenet.detect(frame)
