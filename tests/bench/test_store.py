"""The resumable benchmarks' records: read back only when made with the same settings."""

from __future__ import annotations

import pytest

from swarmpose.bench.store import read_record, render_whole, tracker_settings, write_record


def test_a_record_is_read_back_only_with_its_own_settings(tmp_path):
    path = tmp_path / "cell.json"
    write_record(path, {"mpjpe_mm": 42.0, **tracker_settings({"arm_prior": 1.0})})
    assert read_record(path, tracker_settings({"arm_prior": 1.0}))["mpjpe_mm"] == 42.0
    assert read_record(path, tracker_settings(None)) is None, "made with another arm prior"
    assert read_record(tmp_path / "missing.json", {}) is None
    (tmp_path / "broken.json").write_text("{not json")
    assert read_record(tmp_path / "broken.json", {}) is None


def test_a_record_made_before_a_setting_existed_reads_as_what_the_tracker_did_then(tmp_path):
    """Records written before arm_prior, limb_flips, limb_exchanges, hidden_lifts, arm_proposals, hypotheses,
    polish, box_hold and search existed lack them: they were made with the prior off (0, still its default),
    without flips or exchanges, with every lift in the 3D term, without arm proposals, sub-swarms or polish, with
    the detector's box following the joints every frame and with the whole-pose swarm at 64
    generations (``search`` auto offline), so they resume a run with those off, and neither the
    default run nor one with the prior on or block by block."""
    path = tmp_path / "old.json"
    write_record(path, {"mpjpe_mm": 50.0, "particles": 64, "generations": 64, "max_people": 1})
    then = {"limb_flips": False, "limb_exchanges": False, "hidden_lifts": False, "arm_proposals": False,
            "hypotheses": 0, "polish": 0, "box_hold": 0.0, "search": "auto", "generations": 64, "turning_swarm": 0.0}
    assert read_record(path, tracker_settings(then))["mpjpe_mm"] == 50.0
    assert read_record(path, tracker_settings(None)) is None, "the default run has flips"
    assert read_record(path, tracker_settings({"limb_flips": False})) is None, "and drops hidden lifts"
    assert read_record(path, tracker_settings({"arm_prior": 1.0, **then})) is None
    assert read_record(path, tracker_settings({"particles": 32, **then})) is None
    assert read_record(path, tracker_settings({**then, "search": "blocks"})) is None, "the whole swarm's"
    assert read_record(path, tracker_settings({**then, "search": "swarm"}))["mpjpe_mm"] == 50.0, "auto is the swarm"


def test_a_record_made_with_search_auto_resumes_a_run_with_the_swarm_and_not_one_with_blocks(tmp_path):
    """The benchmarks have no frame budget, so ``search`` auto ran the whole-pose swarm."""
    path = tmp_path / "cell.json"
    write_record(path, {"mpjpe_mm": 44.1, **tracker_settings({"search": "auto", "generations": 64})})
    assert read_record(path, tracker_settings({"search": "swarm", "generations": 64}))["mpjpe_mm"] == 44.1
    assert read_record(path, tracker_settings({"search": "blocks", "generations": 64})) is None


def test_a_record_made_without_flips_does_not_resume_a_default_run(tmp_path):
    path = tmp_path / "cell.json"
    write_record(path, {"mpjpe_mm": 61.0, **tracker_settings({"limb_flips": False})})
    assert read_record(path, tracker_settings(None)) is None
    assert read_record(path, tracker_settings({"limb_flips": False}))["mpjpe_mm"] == 61.0


def test_a_record_made_before_the_limb_exchanges_resumes_only_a_run_without_them(tmp_path):
    """The exchanges came after the flips: a record with the flips but no ``limb_exchanges`` key was made
    without them, so it does not resume a default run (exchanges on), only one that turns them off."""
    path = tmp_path / "cell.json"
    made = tracker_settings(None)
    del made["limb_exchanges"]
    write_record(path, {"mpjpe_mm": 41.6, **made})
    assert read_record(path, tracker_settings(None)) is None
    assert read_record(path, tracker_settings({"limb_exchanges": False}))["mpjpe_mm"] == 41.6


def test_utdmhad_records_carry_the_automatic_height_only_where_it_acts(tmp_path):
    """A UTD-MHAD record made before the automatic height (no key) resumes a run without it, and
    a run with it only for the variants it does not act on (a given shape, the lift mode); a
    default-shape record made with it does not resume a run without it."""
    from swarmpose.bench.utdmhad import variant_settings

    on, off = tracker_settings({"auto_height": True}), tracker_settings({"auto_height": False})
    old = tmp_path / "old.json"
    write_record(old, {"mpjpe_mm": 70.0, **tracker_settings(None)})  # no auto_height key
    assert read_record(old, variant_settings(off, "hybrid", "default"))["mpjpe_mm"] == 70.0
    assert read_record(old, variant_settings(on, "hybrid", "default")) is None
    assert read_record(old, variant_settings(on, "hybrid", "measured"))["mpjpe_mm"] == 70.0
    old_lift = tmp_path / "old_lift.json"
    write_record(old_lift, {"mpjpe_mm": 55.0, **tracker_settings({"arm_proposals": False, "hypotheses": 0,
                                                                   "polish": 0})})
    assert read_record(old_lift, variant_settings(on, "lift", "default"))["mpjpe_mm"] == 55.0
    assert variant_settings(tracker_settings(None), "hybrid", "default")["auto_height"] is True  # the default
    new = tmp_path / "new.json"
    write_record(new, {"mpjpe_mm": 64.0, **variant_settings(on, "hybrid", "default")})
    assert read_record(new, variant_settings(off, "hybrid", "default")) is None
    assert read_record(new, variant_settings(on, "hybrid", "default"))["mpjpe_mm"] == 64.0


def test_utdmhad_records_made_before_the_skeleton_lag_read_as_the_files_pairing(tmp_path):
    """A UTD-MHAD record without ``lag_frames`` was scored against the skeleton as the files pair
    it (lag 0): it resumes ``--lag 0`` and not the default, measured lag."""
    from swarmpose.sources.utdmhad_sync import DEPTH_LAG_FRAMES

    old = tmp_path / "old.json"
    write_record(old, {"mpjpe_mm": 66.1, "requested_frames": 0, **tracker_settings(None)})
    assert read_record(old, {"requested_frames": 0, "lag_frames": 0.0, **tracker_settings(None)})["mpjpe_mm"] == 66.1
    assert read_record(old, {"requested_frames": 0, "lag_frames": DEPTH_LAG_FRAMES, **tracker_settings(None)}) is None


def test_records_of_the_modes_the_arm_proposals_do_not_act_in_resume_without_them(tmp_path):
    """The joints and lift modes have no depth term to judge arm proposals, so their records are
    made and resumed with the setting off: one made before it existed resumes a default run."""
    from swarmpose.bench.store import mode_settings

    old = tmp_path / "old.json"
    then = tracker_settings({"arm_proposals": False, "hypotheses": 0, "polish": 0})  # before the three settings
    write_record(old, {"mpjpe_mm": 90.0, **then})
    for mode in ("joints", "lift"):
        assert read_record(old, mode_settings(tracker_settings({"hypotheses": 0}), mode))["mpjpe_mm"] == 90.0
    for mode in ("hybrid", "depth"):
        assert read_record(old, mode_settings(tracker_settings({"hypotheses": 0}), mode)) is None
        assert mode_settings(tracker_settings({"arm_proposals": False}), mode)["arm_proposals"] is False


def test_records_made_before_the_hypotheses_sub_swarms_resume_only_where_they_do_not_act(tmp_path):
    """A record without ``hypotheses`` was made with single-particle proposals: every mode that
    searches tracks again by default and resumes with ``--hypotheses 0``; the lift mode (no
    search) resumes either way."""
    from swarmpose.bench.store import mode_settings

    for mode in ("lift", "hybrid", "depth", "joints"):
        old = tmp_path / f"old-{mode}.json"
        settings = mode_settings(tracker_settings(None), mode)
        write_record(old, {"mpjpe_mm": 70.0, **{k: v for k, v in settings.items() if k != "hypotheses"}})
        if mode == "lift":
            assert read_record(old, settings)["mpjpe_mm"] == 70.0
            continue
        assert read_record(old, settings) is None
        assert read_record(old, mode_settings(tracker_settings({"hypotheses": 0}), mode))["mpjpe_mm"] == 70.0


def test_records_without_the_backward_pass_resume_runs_without_it_and_lift_never_gets_one(tmp_path):
    """``backward`` is stored with every record; records made before it existed were forward only
    (0, still the default), and the lift mode, which fits no body, is always made with 0."""
    from swarmpose.bench.store import mode_settings

    old = tmp_path / "old.json"
    write_record(old, {"mpjpe_mm": 40.0, **{k: v for k, v in tracker_settings(None).items() if k != "backward"}})
    assert read_record(old, tracker_settings(None))["mpjpe_mm"] == 40.0
    assert read_record(old, tracker_settings({"backward": 40})) is None
    assert mode_settings(tracker_settings({"backward": 40}), "lift")["backward"] == 0
    assert mode_settings(tracker_settings({"backward": 40}), "hybrid")["backward"] == 40


def test_the_polish_acts_in_the_hybrid_records_only_and_older_records_read_as_without_it(tmp_path):
    """``polish`` (60 by default) is stored with every record; the baseline modes (joints, depth,
    lift) are made and resumed with 0 whatever was asked, so their records made before the setting
    existed resume a default run; a hybrid record made before it resumes only ``--polish 0``."""
    from swarmpose.bench.store import mode_settings

    assert tracker_settings(None)["polish"] == 60
    for mode in ("hybrid", "joints", "depth", "lift"):
        settings = mode_settings(tracker_settings(None), mode)
        assert settings["polish"] == (60 if mode == "hybrid" else 0), mode
        old = tmp_path / f"old-{mode}.json"
        write_record(old, {"mpjpe_mm": 45.0, **{k: v for k, v in settings.items() if k != "polish"}})
        assert (read_record(old, settings) is None) == (mode == "hybrid"), mode
        assert read_record(old, mode_settings(tracker_settings({"polish": 0}), mode))["mpjpe_mm"] == 45.0


def test_records_without_smoothing_resume_runs_without_it_and_lift_never_gets_it(tmp_path):
    """``smoothing`` is stored with every record; records made before it existed were unsmoothed ("off",
    still the default), and the lift mode, which publishes no pose to smooth, is always made "off"."""
    from swarmpose.bench.store import mode_settings

    old = tmp_path / "old.json"
    write_record(old, {"mpjpe_mm": 40.0, **{k: v for k, v in tracker_settings(None).items() if k != "smoothing"}})
    assert read_record(old, tracker_settings(None))["mpjpe_mm"] == 40.0
    assert read_record(old, tracker_settings({"smoothing": "centred"})) is None
    assert mode_settings(tracker_settings({"smoothing": "centred"}), "lift")["smoothing"] == "off"
    assert mode_settings(tracker_settings({"smoothing": "centred"}), "hybrid")["smoothing"] == "centred"


def test_a_sequence_is_rendered_whole_or_not_at_all(tmp_path):
    folder = tmp_path / "seq"
    folder.mkdir()
    (folder / "old.txt").write_text("too short")

    def interrupted(tmp):
        tmp.mkdir()
        (tmp / "half.txt").write_text("half")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        render_whole(folder, interrupted)
    assert (folder / "old.txt").exists(), "an interrupted render leaves what was there"

    def complete(tmp):
        assert not tmp.exists(), "the interrupted run's partial folder is thrown away first"
        tmp.mkdir()
        (tmp / "new.txt").write_text("whole")

    assert render_whole(folder, complete) == folder
    assert sorted(p.name for p in folder.iterdir()) == ["new.txt"]
    assert not (tmp_path / "seq.partial").exists()
