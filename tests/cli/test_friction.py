"""Friction a new user met (issue 52), each checked as the user would meet it."""

from __future__ import annotations

import json

from conftest import ASSETS, needs_assets

from swarmpose.cli.main import main


@needs_assets
def test_probe_takes_the_models_folder_its_errors_name(wave_sequence, tmp_path, capsys):
    assert main(["probe", "--source", str(wave_sequence), "--detector", "movenet", "--models",
                 str(tmp_path / "nope"), "--frames", "1"]) == 2
    assert f"--models {tmp_path / 'nope'}: no such folder" in capsys.readouterr().err
    assert main(["probe", "--source", str(wave_sequence), "--detector", "movenet", "--models",
                 str(ASSETS / "pose2d"), "--frames", "1", "--json"]) == 0
    record = json.loads(capsys.readouterr().out.splitlines()[0])
    assert record["joints_layout"] == "coco17" and len(record["joints2d"]) == 17


def test_probe_help_names_every_source_form(capsys):
    try:
        main(["probe", "--help"])
    except SystemExit:
        pass
    text = " ".join(capsys.readouterr().out.split())
    for form in ("folder:", "rgbd:", "mkv:", "bag:", "utdmhad:", "realsense:", "azure:", "openni2:"):
        assert form in text, form


def test_eval_progress_says_eval(wave_sequence, capsys):
    assert main(["eval", str(wave_sequence), "--frames", "1", "--particles", "4", "--generations", "2",
                 "--max-people", "1"]) == 0
    err = capsys.readouterr().err
    assert "eval:" in err and "track:" not in err


def test_a_folder_whose_depth_images_are_all_corrupt_exits_1_and_says_so(wave_sequence, tmp_path, capsys):
    import shutil

    broken = tmp_path / "broken"
    shutil.copytree(wave_sequence, broken)
    for png in (broken / "depth").glob("*.png"):
        png.write_bytes(b"not a png")
    assert main(["track", str(broken), "--out", str(tmp_path / "out"), "--frames", "2", "--particles", "4",
                 "--generations", "2", "-q"]) == 1
    err = capsys.readouterr().err
    assert "none of the 2 frames could be read" in err and "cannot be decoded" in err


def test_a_garbage_recording_is_named_without_an_error_number(tmp_path, capsys):
    garbage = tmp_path / "garbage.mkv"
    garbage.write_bytes(bytes(range(256)) * 20)
    assert main(["track", str(garbage), "--out", str(tmp_path / "out"), "-q"]) == 2
    err = capsys.readouterr().err
    assert f"cannot open {garbage}" in err and "[Errno" not in err


def test_view_of_a_missing_recording_fails_before_it_announces_a_viewer(tmp_path, capsys):
    assert main(["view", str(tmp_path / "nope")]) == 2
    err = capsys.readouterr().err
    assert "no such file or folder" in err and "serving the view" not in err


def test_a_bvh_that_no_floor_placed_says_so(wave_sequence, tmp_path, capsys):
    flags = ["--frames", "2", "--particles", "4", "--generations", "2", "--no-overlay", "-q"]
    assert main(["track", str(wave_sequence), "--out", str(tmp_path / "off"), "--floor", "off", *flags]) == 0
    err = capsys.readouterr().err
    assert f"{tmp_path / 'off' / 'poses.bvh'}: no floor was known" in err and "--floor EXTRINSICS.json" in err
    assert main(["track", str(wave_sequence), "--out", str(tmp_path / "auto"), *flags]) == 0  # its floor is seen
    assert "no floor was known" not in capsys.readouterr().err


def test_run_json_says_what_the_run_was_made_with(wave_sequence, tmp_path):
    assert main(["track", str(wave_sequence), "--out", str(tmp_path), "--frames", "1", "--particles", "4",
                 "--generations", "2", "--no-overlay", "-q"]) == 0
    run = json.loads((tmp_path / "run.json").read_text())
    assert run["schema"] == "swarmpose.run" and run["source"] == str(wave_sequence)
    assert (run["detector_requested"], run["detector"], run["model"]) == ("auto", "simulated", None)
    assert run["tracker"]["particles"] == 4 and run["tracker"]["tile"] == [64, 64]


UTD = ASSETS / "rgbd" / "utd_mhad" / "depth" / "a1_s1_t1_depth.mat"
EMPTY_MKV = ASSETS / "rgbd" / "azure_kinect_one_frame" / "recording.mkv"


@needs_assets
def test_world_coordinates_without_a_floor_say_the_poses_stayed_in_the_camera_frame(tmp_path, capsys):
    """UTD-MHAD's depth has its background removed: no floor to fit."""
    assert main(["track", f"utdmhad:{UTD}", "--out", str(tmp_path), "--coordinates", "world", "--frames", "2",
                 "--particles", "4", "--generations", "2", "--no-overlay", "-q"]) == 0
    assert "--coordinates world: no floor was found" in capsys.readouterr().err
    messages = [json.loads(line) for line in (tmp_path / "poses.jsonl").read_text().splitlines()]
    assert {m["coordinates"] for m in messages} == {"camera"}


@needs_assets
def test_probe_counts_keypoints_as_the_tracker_does_and_says_when_nobody_is_there(capsys):
    assert main(["probe", "--source", str(EMPTY_MKV), "--detector", "movenet", "--frames", "1"]) == 0
    assert "no person found" in capsys.readouterr().out  # the recording shows a room with nobody in it


def test_an_earlier_runs_per_person_files_are_removed_from_the_output_folder(tmp_path):
    from swarmpose.body.loader import load_body
    from swarmpose.publish.files import open_recording

    (tmp_path / "poses_id3.bvh").write_text("an earlier run's person")
    (tmp_path / "notes.txt").write_text("the user's own")
    for sink in open_recording(tmp_path, load_body("builtin"), overlay=False):
        sink.close()
    assert not (tmp_path / "poses_id3.bvh").exists() and (tmp_path / "notes.txt").exists()


def test_help_all_works_before_a_command_too(capsys):
    try:
        main(["--help-all"])
    except SystemExit as exit_:
        assert exit_.code == 0
    assert "COMMAND" in capsys.readouterr().out
