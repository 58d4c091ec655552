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
