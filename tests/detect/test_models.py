"""Models from anywhere: the named networks are found whatever the working directory, ``swarmpose
models`` says where it looks and what it found, ``swarmpose models add`` installs a network after
onnxruntime has loaded it. Oracles: the real MoveNet and BlazePose files of the shared assets."""

from __future__ import annotations

import json

import pytest
from conftest import ASSETS, needs_assets

from swarmpose.cli.main import main
from swarmpose.core.errors import ConfigError, DetectorError
from swarmpose.detect.models import add_model, found_models
from swarmpose.detect.registry import NETWORKS, find_network, model_folders

MOVENET = ASSETS / "pose2d" / NETWORKS["movenet"]
BLAZEPOSE = ASSETS / "pose2d" / NETWORKS["blazepose"]


@pytest.fixture
def elsewhere(tmp_path, monkeypatch):
    """A working directory with no ../shared beside it, an empty user folder, no variables."""
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    monkeypatch.delenv("SWARMPOSE_MODELS", raising=False)
    monkeypatch.delenv("SWARMPOSE_ASSETS", raising=False)
    return tmp_path


@needs_assets
def test_a_named_network_is_found_from_any_working_directory(elsewhere):
    assert find_network("movenet").samefile(MOVENET)
    folders = model_folders()
    assert folders[0] == elsewhere / "data" / "swarmpose" / "models"
    assert any(f.samefile(ASSETS / "pose2d") for f in folders if f.is_dir())


@needs_assets
def test_models_lists_the_folders_and_what_it_found_and_add_installs_a_checked_network(elsewhere, capsys):
    assert main(["models", "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert listed["folders"][0] == str(elsewhere / "data" / "swarmpose" / "models")
    by_name = {m["name"]: m for m in listed["models"] if m["used"]}
    assert by_name["movenet"]["layout"] == "coco17" and by_name["blazepose"]["layout"] == "blazepose33"
    assert by_name["movenet"]["bytes"] == MOVENET.stat().st_size and "Apache-2.0" in by_name["movenet"]["licence"]

    assert main(["models", "add", str(MOVENET)]) == 0
    installed = elsewhere / "data" / "swarmpose" / "models" / NETWORKS["movenet"]
    assert installed.read_bytes() == MOVENET.read_bytes() and "--detector movenet" in capsys.readouterr().out
    assert add_model(MOVENET) == ("movenet", installed)  # the same file again: nothing to refuse
    _, found = found_models()
    first = next(m for m in found if m.name == "movenet")
    assert first.used and first.path == installed  # the user folder comes before the assets
    assert find_network("movenet") == installed


@needs_assets
def test_add_refuses_what_is_no_known_network_and_a_different_file_of_the_same_name(elsewhere, capsys):
    garbage = elsewhere / "model.onnx"
    garbage.write_bytes(b"not a network")
    assert main(["models", "add", str(garbage)]) == 2
    assert "cannot load ONNX model" in capsys.readouterr().err
    with pytest.raises(DetectorError, match="no such file"):
        add_model(elsewhere / "missing.onnx")
    installed = elsewhere / "data" / "swarmpose" / "models" / NETWORKS["movenet"]
    installed.parent.mkdir(parents=True)
    installed.write_bytes(b"an older download")
    with pytest.raises(DetectorError, match="--force"):
        add_model(MOVENET)
    assert add_model(MOVENET, force=True)[1].read_bytes() == MOVENET.read_bytes()


def test_a_misspelt_models_folder_is_named_and_a_given_one_is_searched_first(elsewhere, capsys):
    with pytest.raises(ConfigError, match="no such folder"):
        find_network("movenet", str(elsewhere / "nope"))
    assert main(["models", "--models", str(elsewhere)]) == 0
    out = capsys.readouterr().out
    assert str(elsewhere) in out.splitlines()[1]


@needs_assets
def test_the_python_api_takes_a_models_folder(elsewhere, tmp_path):
    import shutil

    import swarmpose

    mine = tmp_path / "mine"
    mine.mkdir()
    shutil.copyfile(BLAZEPOSE, mine / NETWORKS["blazepose"])
    with swarmpose.Tracker(detector="blazepose", models=str(mine), mode="lift") as tracker:
        assert tracker.detector.path == mine / NETWORKS["blazepose"]


@needs_assets
def test_every_run_says_which_detector_and_model_file_it_uses(wave_sequence, tmp_path, capsys):
    """auto on a synthetic sequence says it replays the recorded detections (not a network); a named
    network says its file."""
    flags = ["--frames", "1", "--particles", "4", "--generations", "2", "--no-overlay", "--max-people", "1"]

    def notes() -> list[str]:
        return [line for line in capsys.readouterr().err.splitlines() if line.startswith("swarmpose: 2D joints:")]

    assert main(["track", str(wave_sequence), "--out", str(tmp_path / "a"), *flags]) == 0
    said = notes()
    assert len(said) == 1 and "detections the source recorded" in said[0] and "not a network" in said[0]
    assert main(["track", str(wave_sequence), "--out", str(tmp_path / "b"), "--detector", "movenet", *flags]) == 0
    said = notes()
    assert len(said) == 1 and NETWORKS["movenet"] in said[0] and "recorded" not in said[0]
