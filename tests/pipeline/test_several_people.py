"""Several people through the whole per-frame step: segmentation, a detection per person, a
track per person with a stable id, scored against the synthetic scene's per-person truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import ValidatingSink, synthesize_scene

import swarmpose
from swarmpose.body.loader import load_body
from swarmpose.detect.people import segment_people
from swarmpose.detect.per_person import MASK_GREY, PersonDetection, masked_colour
from swarmpose.detect.simulated import SimulatedDetector
from swarmpose.people.people_tracker import PeopleTracker, _depth_removed
from swarmpose.pipeline.step import FramePipeline
from swarmpose.pipeline.worker import Worker
from swarmpose.sim.people_metrics import TruePerson, score_people
from swarmpose.sim.scoring import body_joints
from swarmpose.sources.folder import FolderSource
from swarmpose.sources.groundtruth import load_ground_truth
from swarmpose.sources.registry import open_source
from swarmpose.tracking.body_tracker import BodyTracker
from swarmpose.tracking.config import TrackerConfig

FRAMES = 6
PEOPLE = ("builtin:male:builtin:walk@-0.7,0.3", "builtin:female:builtin:wave@0.6,-0.6",
          "builtin:female-short:builtin:squat@0.0,-1.6")


@pytest.fixture(scope="module")
def three(tmp_path_factory) -> Path:
    return synthesize_scene(tmp_path_factory.mktemp("three"), PEOPLE, FRAMES, seed=3)


def _truth(folder: Path) -> dict[int, list[TruePerson]]:
    gt = load_ground_truth(folder)
    return {f: [TruePerson(p.id, p.joints3d, p.visible) for p in gt.people[gt.row(f)]] for f in gt.frames}


def _tracked(results) -> dict[int, dict[int, np.ndarray]]:
    return {r.index: {b.id: body_joints(b.to_message()) for b in r.bodies if b.state != "lost"} for r in results}


@pytest.mark.slow
def test_three_people_get_three_stable_ids_and_fits_near_their_truth(three):
    results = list(swarmpose.track(f"folder:{three}", detector="simulated", max_people=4, particles=24,
                                   generations=24))
    assert len(results) == FRAMES
    assert all(len({b.id for b in r.bodies}) == len(r.bodies) for r in results)  # ids distinct within a frame
    scores = score_people(_truth(three), _tracked(results))
    assert scores["id_switches"] == 0
    assert scores["misses"] == 0 and scores["false_positives"] == 0
    for person, s in scores["per_person"].items():
        assert len(s["ids"]) == 1, f"person {person} had ids {s['ids']}"
        assert s["mpjpe_mm"] < 120, f"person {person}: {s['mpjpe_mm']:.0f} mm"


@pytest.mark.slow
def test_max_people_caps_the_tracks_and_counts_the_rest(three):
    source = FolderSource(three)
    with swarmpose.Tracker(detector="simulated", source=source, max_people=2, particles=8, generations=8,
                           mode="joints") as tracker:
        results = [tracker.track_frame(frame) for frame in source]
        counts = tracker.pipeline.people.counts
    assert max(len(r.bodies) for r in results) == 2
    assert counts.beyond_max_people >= FRAMES  # the third person, on every frame
    assert counts.created == 2


@pytest.mark.slow
def test_one_person_in_view_is_tracked_as_before(wave_sequence):
    single = list(swarmpose.track(f"folder:{wave_sequence}", detector="simulated", max_people=1, particles=16,
                                  generations=16, frames=3))
    several = list(swarmpose.track(f"folder:{wave_sequence}", detector="simulated", max_people=4, particles=16,
                                   generations=16, frames=3))
    assert [len(r.bodies) for r in several] == [1, 1, 1]
    assert [b.id for r in several for b in r.bodies] == [0, 0, 0]
    for a, b in zip(single, several):  # the same detection and the same depth: the same fit
        assert np.nanmax(np.abs(a.bodies[0].joints3d - b.bodies[0].joints3d)) < 0.03


def test_other_people_are_painted_grey_for_the_detector_and_removed_from_the_depth(three):
    frame = next(iter(FolderSource(three)))
    seg = segment_people(frame.depth, frame.intrinsics)
    assert len(seg.people) == 3
    painted = masked_colour(frame.color, seg.labels, keep=1)
    others = (seg.labels > 1)
    assert np.all(painted[others] == MASK_GREY)
    assert np.array_equal(painted[seg.labels <= 1], frame.color[seg.labels <= 1])
    person = PersonDetection(seg.people[0], None)
    masked = _depth_removed(frame, PeopleTracker._others(seg.labels, 0, person))
    assert np.all(masked.depth[others] == 0)
    keep = ~others
    assert np.array_equal(masked.depth[keep], frame.depth[keep])


def test_an_unseen_track_keeps_its_id_then_is_retired(three):
    """Lift mode (no OpenCL): person k's detection and segment fed by hand; person 1 leaves."""
    source = FolderSource(three)
    gt = load_ground_truth(three)
    detector = SimulatedDetector(gt)
    intrinsics = next(iter(source)).intrinsics
    people = PeopleTracker(lambda i: BodyTracker(load_body("builtin"), intrinsics,
                                                 TrackerConfig(mode="lift"), body_id=i), retire_frames=2)
    frames = list(source)
    ids_seen = []
    for k, frame in enumerate(frames):
        seg = segment_people(frame.depth, frame.intrinsics)
        dets = [PersonDetection(s, detector.detect(frame, s.box)) for s in seg.people]
        if k >= 2:  # the leftmost person no longer found from frame 2 on
            dets = dets[1:]
            labels = np.where(seg.labels == 1, 0, np.maximum(seg.labels - 1, 0))
        else:
            labels = seg.labels
        bodies = people.step(frame, dets, labels)
        ids_seen.append(sorted(b.id for b in bodies))
    assert ids_seen[0] == [0, 1, 2] and ids_seen[1] == [0, 1, 2]
    left = ({0, 1, 2} - set(ids_seen[2])).pop()
    assert all(len(ids) == 2 and left not in ids for ids in ids_seen[2:])
    assert people.counts.retired == 1 and len(people.tracks) == 2  # unseen for frames 2, 3, 4 > 2


def test_the_worker_reports_people_in_its_status(three):
    uri = f"folder:{three}"
    source = open_source(uri)
    body = load_body("builtin")
    pipeline = FramePipeline(SimulatedDetector(source.ground_truth),
                             lambda intr, i: BodyTracker(body, intr, TrackerConfig(mode="lift"), body_id=i),
                             max_people=2)
    sink = ValidatingSink()
    Worker(lambda: open_source(uri), pipeline, [sink], camera="test", drop_stale=False, source_uri=uri,
           status_period_s=0.2, source=source).run()
    people = sink.statuses[-1]["tracker"]["people"]
    assert people["tracked"] == 2 and people["found"] == 3 and people["created"] == 2
    assert people["beyond_max_people"] == FRAMES and sink.statuses[-1]["frames"]["failed"] == 0
    assert all(len(m["bodies"]) == 2 for m in sink.frames)


def _lift_people(intrinsics, **kw) -> PeopleTracker:
    body = load_body("builtin")
    return PeopleTracker(lambda i: BodyTracker(body, intrinsics, TrackerConfig(mode="lift"), body_id=i), **kw)


def test_a_track_started_on_the_whole_frame_keeps_its_id_once_segmented(three):
    source = FolderSource(three)
    detector = SimulatedDetector(load_ground_truth(three))
    frames = list(source)
    people = _lift_people(frames[0].intrinsics)
    first = people.step(frames[0], [PersonDetection(None, detector.detect(frames[0]))])  # no segment: whole frame
    assert [b.id for b in first] == [0]
    seg = segment_people(frames[1].depth, frames[1].intrinsics)
    truth = load_ground_truth(three).people[1]
    person1 = next(p for p in truth if p.id == 1)
    # the segment whose centre lies nearest person 1's fit continues id 0; the others are new ids
    dets = [PersonDetection(s, detector.detect(frames[1], s.box)) for s in seg.people]
    bodies = people.step(frames[1], dets, seg.labels)
    by_id = {b.id: b for b in bodies}
    assert sorted(by_id) == [0, 1, 2]
    assert np.nanmean(np.linalg.norm(by_id[0].joints3d - person1.joints3d, axis=1)) < 0.15


def test_retired_ids_are_never_reused_and_a_full_house_makes_room(three):
    source = FolderSource(three)
    detector = SimulatedDetector(load_ground_truth(three))
    frames = list(source)
    people = _lift_people(frames[0].intrinsics, max_people=2, retire_frames=10)
    seg = segment_people(frames[0].depth, frames[0].intrinsics)
    dets = [PersonDetection(s, detector.detect(frames[0], s.box)) for s in seg.people]
    ids0 = [b.id for b in people.step(frames[0], dets[:2], np.where(seg.labels > 2, 0, seg.labels))]
    assert ids0 == [0, 1]
    # then only the third person is in view. Frame 1: both tracks were seen a frame ago, the
    # cap holds and the newcomer is refused; frame 2: both are unseen, so the longest-unseen
    # is retired to make room and the newcomer gets a fresh id (never 0 or 1 again)
    for k in (1, 2):
        seg = segment_people(frames[k].depth, frames[k].intrinsics)
        dets = [PersonDetection(s, detector.detect(frames[k], s.box)) for s in seg.people]
        bodies = people.step(frames[k], dets[2:], np.where(seg.labels == 3, 1, 0))
        assert [b.id for b in bodies] == ([] if k == 1 else [2])
    assert people.counts.beyond_max_people == 1 and people.counts.retired == 1 and people.next_id == 3
    people.reset()
    assert people.tracks == [] and people.next_id == 3  # ids go on counting after a reset


def test_crop_boxes_give_each_hint_to_one_segment_at_most():
    from swarmpose.detect.per_person import box_iou, crop_boxes

    class Seg:
        def __init__(self, box):
            self.box = np.array(box)

    segs = [Seg([0, 0, 100, 200]), Seg([90, 0, 190, 200])]
    hint = np.array([10.0, 20.0, 90.0, 180.0])  # the left person's joints
    out = crop_boxes(segs, [hint])
    assert np.array_equal(out[0], hint) and np.array_equal(out[1], segs[1].box)
    assert box_iou(np.array([0, 0, 2, 2]), np.array([1, 1, 3, 3])) == pytest.approx(1 / 7)
    far = np.array([500.0, 0.0, 600.0, 100.0])
    assert [np.array_equal(o, s.box) for o, s in zip(crop_boxes(segs, [far]), segs)] == [True, True]


def test_on_segment_share_is_the_share_of_keypoints_within_reach_of_the_mask():
    """Against OpenCV's dilation of the mask by the reach (a (2r+1)-square kernel)."""
    import cv2

    from swarmpose.body.skeleton import COCO17
    from swarmpose.detect.joints import Joints2D
    from swarmpose.detect.per_person import KEYPOINT_MIN_SCORE, ON_SEGMENT_PX, on_segment_share

    rng = np.random.default_rng(5)
    mask = np.zeros((120, 160), bool)
    mask[30:90, 50:100] = True
    near = cv2.dilate(mask.astype(np.uint8), np.ones((2 * ON_SEGMENT_PX + 1,) * 2, np.uint8)) > 0

    class Seg:  # on_segment_share reads only the mask
        pass

    segment = Seg()
    segment.mask = mask
    for _ in range(20):
        kp = np.column_stack([rng.uniform(-10, 170, 17), rng.uniform(-10, 130, 17), rng.uniform(0, 1, 17)])
        ok = kp[:, 2] >= KEYPOINT_MIN_SCORE
        u, v = np.round(kp[ok, 0]).astype(int), np.round(kp[ok, 1]).astype(int)
        inside = (kp[ok, 0] >= 0) & (kp[ok, 0] < 160) & (kp[ok, 1] >= 0) & (kp[ok, 1] < 120)
        want = np.mean(inside & near[np.clip(v, 0, 119), np.clip(u, 0, 159)]) if ok.any() else 1.0
        assert on_segment_share(Joints2D(COCO17, kp, 0, 0), segment) == pytest.approx(want)
