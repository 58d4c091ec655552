"""``--detector SPEC`` (older name ``--joints``) -> detector: every form, its options, and the errors users see."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import ASSETS, needs_assets

from swarmpose.body.skeleton import COCO17
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError, DetectorError
from swarmpose.detect.registry import make_detector
from swarmpose.sources.base import Frame, FrameSource
from swarmpose.sources.groundtruth import load_ground_truth

MOVENET = ASSETS / "pose2d" / "movenet_singlepose_lightning.onnx"
BLAZEPOSE = ASSETS / "pose2d" / "blazepose_landmark_full.onnx"


def _sequence_source(folder: Path):
    """The sequence folder as ``--source`` opens it (the folder source, with its ``ground_truth``)."""
    try:
        from swarmpose.sources.registry import open_source
    except ImportError:  # the folder source is not in this checkout yet: what it exposes to detectors
        return _FolderWithGroundTruth(folder)
    return open_source(str(folder))


class _FolderWithGroundTruth(FrameSource):
    def __init__(self, folder: Path):
        self.uri = str(folder)
        self.ground_truth = load_ground_truth(folder)


@pytest.fixture(scope="module")
def sequence(tmp_path_factory) -> Path:
    from swarmpose.cli.main import main

    out = tmp_path_factory.mktemp("seq")
    assert main(["synth", "--body", "builtin", "--motion", "builtin:squat", "--frames", "3", "--out", str(out),
                 "--seed", "5", "--quiet"]) == 0
    return out


def _frame(folder: Path, index: int, timestamp_ns: int) -> Frame:
    rgb = cv2.cvtColor(cv2.imread(str(folder / "color" / f"{index:06d}.png")), cv2.COLOR_BGR2RGB)
    intr = Intrinsics.load(folder / "intrinsic.json")
    return Frame(index, timestamp_ns, np.zeros(rgb.shape[:2], np.float32), rgb, intr)


def test_simulated_replays_the_recorded_detections(sequence):
    records = [json.loads(line) for line in (sequence / "groundtruth.jsonl").read_text().splitlines()]
    detector = make_detector("simulated", _sequence_source(sequence))
    assert detector.name == "simulated" and detector.layout is COCO17
    for rec in records:
        j = detector.detect(_frame(sequence, rec["frame"], rec["timestamp_ns"]))
        assert (j.frame_index, j.timestamp_ns) == (rec["frame"], rec["timestamp_ns"])
        want = np.array([rec["detections"]["keypoints"][k] for k in COCO17.keypoints])
        np.testing.assert_array_equal(j.keypoints, want)
        # and they are the (noisy) ground-truth joints: median error 1% of a 300 px person plus the hip bias
        found = j.by_point()
        errors = [np.hypot(*(np.array(found[p][:2]) - rec["joints2d"][p])) for p in rec["joints2d"] if p in found]
        assert len(errors) >= 8 and np.median(errors) < 10
    with pytest.raises(DetectorError, match="no ground-truth record for frame 7"):
        detector.detect(Frame(7, 0, np.zeros((480, 640), np.float32), None, Intrinsics.kinect_v1()))


def test_simulated_without_ground_truth_says_what_it_needs():
    with pytest.raises(DetectorError, match="swarmpose synth.*groundtruth.jsonl"):
        make_detector("simulated")

    class Camera(FrameSource):
        uri = "realsense:0"

    with pytest.raises(DetectorError, match="realsense:0 has no ground truth"):
        make_detector("simulated", Camera())


@needs_assets
def test_onnx_specs_pick_the_adapter_from_the_model_and_take_options():
    movenet = make_detector(f"onnx:{MOVENET}")
    assert movenet.layout.name == "coco17" and movenet.name == "onnx:movenet_singlepose_lightning.onnx"
    blaze = make_detector(f"onnx:{BLAZEPOSE}?threads=2&margin=1.4")
    assert blaze.layout.name == "blazepose33" and blaze.threads == 2 and blaze.adapter.margin == 1.4
    with pytest.raises(DetectorError, match="not what adapter 'blazepose' needs"):
        make_detector(f"onnx:{MOVENET}?adapter=blazepose")
    with pytest.raises(ConfigError, match="unknown option 'thread'"):
        make_detector(f"onnx:{MOVENET}?thread=2")
    with pytest.raises(ConfigError, match="threads='two' is not an integer"):
        make_detector(f"onnx:{MOVENET}?threads=two")
    assert movenet.refine and not make_detector(f"onnx:{MOVENET}?refine=false").refine
    assert make_detector(f"onnx:{MOVENET}?refine=On").refine
    with pytest.raises(ConfigError, match=r"refine='maybe' is not a boolean \(true/false\)"):
        make_detector(f"onnx:{MOVENET}?refine=maybe")
    movenet.close()
    blaze.close()


def test_onnx_and_openpose_paths_that_do_not_exist_are_named(tmp_path):
    with pytest.raises(DetectorError, match=str(tmp_path / "m.onnx")):
        make_detector(f"onnx:{tmp_path / 'm.onnx'}")
    with pytest.raises(DetectorError, match=str(tmp_path / "json")):
        make_detector(f"openpose-json:{tmp_path / 'json'}")
    with pytest.raises(ConfigError, match="names no file"):
        make_detector("onnx:")


def test_openpose_json_spec(tmp_path):
    (tmp_path / "v_000000000000_keypoints.json").write_text(json.dumps({"people": []}))
    assert make_detector(f"openpose-json:{tmp_path}").layout.name == "body25"
    assert make_detector(f"openpose-json:{tmp_path}?layout=openpose18").layout.name == "openpose18"


@pytest.mark.parametrize("spec", ["openpose", "movenet2", "onnx", "simulated:3", ""])
def test_unknown_specs_list_the_forms(spec):
    with pytest.raises(ConfigError) as err:
        make_detector(spec)
    text = str(err.value)
    assert "simulated" in text and "onnx:MODEL" in text and "openpose-json:DIR" in text


def _still_source():
    """The real Kinect frame of five people as ``rgbd:`` opens it."""
    from swarmpose.sources.registry import open_source

    folder = ASSETS / "rgbd" / "kinect_five_people"
    return open_source(f"rgbd:{folder}/five_people_color.png,{folder}/five_people_depth_mm.png,"
                       f"{folder}/five_people_intrinsics.json")


@needs_assets
@pytest.mark.parametrize("name", ["movenet", "blazepose"])
def test_networks_by_name_come_from_the_models_folder_and_equal_the_onnx_form(name, tmp_path, monkeypatch):
    """``--detector NAME`` loads NAME's file from $SWARMPOSE_MODELS (here a folder holding a link to the
    asset) and detects exactly what ``onnx:PATH`` does on a real frame."""
    path = MOVENET if name == "movenet" else BLAZEPOSE
    (tmp_path / path.name).symlink_to(path)
    monkeypatch.setenv("SWARMPOSE_MODELS", str(tmp_path))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "no-data"))
    still = _still_source()
    frame = next(iter(still))
    still.close()
    by_name = make_detector(f"{name}?threads=1")
    by_path = make_detector(f"onnx:{path}?threads=1")
    try:
        assert by_name.path == tmp_path / path.name
        np.testing.assert_array_equal(by_name.detect(frame).keypoints, by_path.detect(frame).keypoints)
    finally:
        by_name.close()
        by_path.close()


def test_a_network_not_in_any_models_folder_names_the_folders_and_the_fix(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    monkeypatch.setenv("SWARMPOSE_ASSETS", str(tmp_path / "assets"))
    monkeypatch.delenv("SWARMPOSE_MODELS", raising=False)
    with pytest.raises(ConfigError) as err:
        make_detector("movenet", models=str(tmp_path))
    text = str(err.value)
    assert "movenet_singlepose_lightning.onnx" in text and str(tmp_path) in text
    assert str(tmp_path / "data" / "swarmpose" / "models") in text and "--models" in text and "onnx:PATH" in text
    with pytest.raises(ConfigError, match="no such folder"):
        make_detector("blazepose", models=str(tmp_path / "missing"))


def test_auto_replays_recorded_detections_and_otherwise_runs_a_network(sequence, tmp_path, monkeypatch):
    """auto: the synth sequence's recorded detections; a source without them (a still frame), or whose
    skeleton is what the run is measured against (UTD-MHAD), gets MoveNet, or, where MoveNet is in no
    models folder, an error that says so rather than the simulated detector."""
    from swarmpose.sources.utdmhad import UtdMhadSource

    assert make_detector("auto", _sequence_source(sequence)).name == "simulated"
    if not ASSETS.is_dir():
        pytest.skip(f"shared assets absent ({ASSETS}): the real Kinect frame is needed")
    still = _still_source()
    try:
        monkeypatch.setenv("SWARMPOSE_MODELS", str(ASSETS / "pose2d"))
        detector = make_detector("auto", still)
        assert detector.path.name == MOVENET.name
        detector.close()
        utd = UtdMhadSource(ASSETS / "rgbd" / "utd_mhad" / "depth" / "a1_s1_t1_depth.mat")
        detector = make_detector("auto", utd)
        assert detector.path.name == MOVENET.name
        detector.close()
        assert make_detector("simulated", utd).name == "simulated"  # asked for by name: the skeleton plus noise
        monkeypatch.setenv("SWARMPOSE_MODELS", str(tmp_path))
        monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path))
        monkeypatch.setenv("SWARMPOSE_ASSETS", str(tmp_path))
        with pytest.raises(ConfigError, match="--detector movenet"):
            make_detector("auto", still)
    finally:
        still.close()


@pytest.mark.parametrize("command", ["track", "eval"])
def test_the_models_flag_reaches_the_detector(command, sequence, tmp_path, capsys):
    """``--models DIR`` on the command line is where a named network is looked for first."""
    from swarmpose.cli.main import main

    missing = tmp_path / "no-models-here"
    assert main([command, "--source", str(sequence), "--detector", "movenet", "--models", str(missing),
                 "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert f"--models {missing}: no such folder" in capsys.readouterr().err
