"""The OpenCL particle scorer against independent oracles (PoCL's CPU device in CI).

* Rendered depth tiles vs Open3D ray casting of the numpy-skinned (LBS) mesh through the
  same tile pixel centres: silhouette IoU >= 0.99, >= 99 % of common pixels within 2 mm.
* Per-particle sums and counts vs the float64 numpy formula on the kernel's own tiles
  (isolates the reduction: 1e-4 relative, counts exact) and on the Open3D tiles (tolerance
  from the silhouette / depth agreement above).
* Random poses from a fresh seed every run (printed, and named in failure messages);
  output buffers are poisoned before every launch, and a skipped launch is caught.
* Bad input: no particles, non-finite poses, empty observations, boxes off the image.
"""

from __future__ import annotations

import os
from dataclasses import replace

import numpy as np
import pytest
from conftest import MAKEHUMAN, needs_assets

from swarmpose.body.kinematics import quaternion_multiply
from swarmpose.body.skeleton import ANGLE_LIMITS, ANGLE_NAMES
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError, ShapeError
from swarmpose.gpu.reference import COUNT_NAMES, raycast_tiles, reference_score
from swarmpose.gpu.scorer import ParticleScorer
from swarmpose.gpu.tile import box_around
from swarmpose.sim.render import Renderer, Room

T = 0.30
TILE = (64, 48)  # TW x TH: a non-square tile catches swapped axes
INTR = Intrinsics.kinect_v1()
FACING = (0.0, 1.0, 0.0, 0.0)  # upright, facing the camera
A = {name: 7 + i for i, name in enumerate(ANGLE_NAMES)}


# ---------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def seed() -> int:
    value = int.from_bytes(os.urandom(4), "little")
    print(f"test_scorer seed = {value}")
    return value


def _builtin():
    from swarmpose.body.loader import load_body
    return load_body("builtin").tracking_lod(1500)


def _makehuman():
    if not MAKEHUMAN.is_dir():
        pytest.skip(f"MakeHuman assets not found at {MAKEHUMAN}")
    from swarmpose.body.loader import load_body
    return load_body("makehuman:" + str(MAKEHUMAN), "male").tracking_lod(1500)


@pytest.fixture(scope="module")
def builtin_body():
    return _builtin()


@pytest.fixture(scope="module", params=["builtin", pytest.param("makehuman", marks=needs_assets)])
def body(request, builtin_body):
    return builtin_body if request.param == "builtin" else _makehuman()


@pytest.fixture(scope="module")
def scorer(body):
    return ParticleScorer(body, INTR, TILE, threshold=T, context="cpu")


def named_poses(body) -> np.ndarray:
    """(4, 36): rest, arms up, crouch, side view; ~3 m in front of the camera."""
    rest = body.rest_pose((0.0, 0.1, 3.0), FACING)
    up = rest.copy()
    up[A["left_shoulder.roll"]] += 1.2
    up[A["right_shoulder.roll"]] -= 1.2
    crouch = rest.copy()
    for side in ("left", "right"):
        crouch[A[f"{side}_hip.pitch"]] = 1.2
        crouch[A[f"{side}_knee.pitch"]] = -1.8
    crouch[A["spine.pitch"]] = 0.3
    side_view = rest.copy()
    side_view[3:7] = quaternion_multiply(np.array(FACING), [np.cos(np.pi / 4), 0, np.sin(np.pi / 4), 0])
    return np.stack([rest, up, crouch, side_view])


def random_poses(body, rng: np.random.Generator, n: int, around: np.ndarray | None = None,
                 spread: float = 1.0) -> np.ndarray:
    """n poses: angles drawn within Table 1's limits (or around ``around``), small root motion."""
    base = body.rest_pose((0.0, 0.1, 3.0), FACING) if around is None else around
    h = np.tile(base, (n, 1))
    if around is None:
        lo, hi = ANGLE_LIMITS[:, 0], ANGLE_LIMITS[:, 1]
        h[:, 7:] = base[7:] + spread * (rng.uniform(lo, hi, (n, 29)) - base[7:]) * 0.5
    else:
        h[:, 7:] += rng.normal(0.0, 0.15 * spread, (n, 29))
    h[:, :3] += rng.normal(0.0, 0.05 * spread, (n, 3))
    yaw = rng.normal(0.0, 0.4 * spread, n)
    turn = np.stack([np.cos(yaw / 2), 0 * yaw, np.sin(yaw / 2), 0 * yaw], -1)
    h[:, 3:7] = quaternion_multiply(h[:, 3:7], turn)
    return h


def person_box(body, h: np.ndarray) -> tuple[float, float, float, float]:
    return box_around(INTR.project(body.pose(h).reshape(-1, 3)), margin=0.1)


def observation(body, h_true: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A 640x480 depth frame (m) of pose h_true (36,) in a room, with noise and holes."""
    room = Room(floor_point=np.array([0.0, 1.0, 0.0]), floor_normal=np.array([0.0, -1.0, 0.0]),
                wall_point=np.array([0.0, 0.0, 4.5]), wall_normal=np.array([0.0, 0.0, -1.0]))
    depth = Renderer(INTR).render(body.pose(h_true[None])[0], body.triangles, room)[0]
    depth = depth + rng.normal(0.0, 0.005, depth.shape).astype(np.float32) * (depth > 0)
    depth[rng.random(depth.shape) < 0.1] = 0.0
    return depth.astype(np.float32)


def oracle_tiles(scorer: ParticleScorer, h: np.ndarray) -> np.ndarray:
    verts = scorer.body.pose(h)
    return raycast_tiles(verts, scorer.body.triangles, scorer.tile_box.rays(INTR))


def assert_written(sums: np.ndarray, counts: dict) -> None:
    assert np.all(np.isfinite(sums)), "some sums are NaN: the kernel did not write them"
    for name in COUNT_NAMES:
        assert np.all(counts[name] >= 0), f"some {name} counts are -1: the kernel did not write them"


# ---------------------------------------------------------------------------- rendering
def test_rendered_tiles_match_open3d(scorer, body, seed):
    rng = np.random.default_rng(seed)
    h = np.concatenate([named_poses(body), random_poses(body, rng, 6)])
    scorer.set_observation(np.zeros((INTR.height, INTR.width), np.float32), person_box(body, h))
    tiles, sums, counts = scorer.render_and_score(h)
    assert tiles.shape == (len(h), TILE[1], TILE[0])
    assert not np.any(np.isnan(tiles)), "unwritten (poisoned) tile pixels"
    assert_written(sums, counts)
    ref = oracle_tiles(scorer, h)
    for i in range(len(h)):
        ours, theirs = tiles[i] > 0, ref[i] > 0
        assert theirs.sum() > 100, f"pose {i}: the body should cover the tile (seed {seed})"
        iou = (ours & theirs).sum() / (ours | theirs).sum()
        common = ours & theirs
        close = np.mean(np.abs(tiles[i] - ref[i])[common] <= 0.002)
        assert iou >= 0.99, f"{body.name} pose {i}: silhouette IoU {iou:.4f} < 0.99 (seed {seed})"
        assert close >= 0.99, f"{body.name} pose {i}: only {close:.2%} of pixels within 2 mm (seed {seed})"
        assert counts["rendered"][i] == ours.sum()


def rigid_mesh(body, verts: np.ndarray, tris: np.ndarray):
    """``body`` with its mesh replaced by verts (V, 3) / tris (F, 3), all on the root bone: at
    the pose :data:`IDENTITY` rest points are camera-frame points."""
    flat = replace(body, name="mesh", vertices=verts, triangles=np.asarray(tris, np.int32),
                   skin_indices=np.zeros((len(verts), 4), np.int32),
                   skin_weights=np.tile(np.array([1.0, 0, 0, 0], np.float32), (len(verts), 1)))
    h = flat.rest_pose((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))[None]
    assert np.allclose(flat.pose(h)[0], verts)
    return flat, h


@pytest.mark.slow
def test_fill_rule_is_exact_on_pixel_centres(builtin_body):
    """A flat grid whose edges (including diagonals) pass exactly through pixel centres:
    no cracks inside, and the outline is covered as a half-open pixel set."""
    intr = Intrinsics(64, 64, 64.0, 64.0, 31.5, 31.5)  # tile coordinate x_t = 64 X/Z + 32
    n, step, start = 8, 4.0, 8.5  # vertices on pixel centres 8.5, 12.5, ..., 40.5
    grid = start + step * np.arange(n + 1)
    xx, yy = np.meshgrid(grid, grid)
    verts = np.stack([(xx.ravel() - 32) / 64, (yy.ravel() - 32) / 64, np.ones(xx.size)], -1)
    tris = []
    for j in range(n):
        for i in range(n):
            a, b, c, d = j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i, (j + 1) * (n + 1) + i + 1
            tris += [[a, c, b], [b, c, d]] if (i + j) % 2 else [[a, c, d], [a, d, b]]
    flat, h = rigid_mesh(builtin_body, verts, tris)
    for cull in (False, True):
        sc = ParticleScorer(flat, intr, (64, 64), context="cpu", cull_backfaces=cull)
        sc.set_observation(np.zeros((64, 64), np.float32), (0, 0, 64, 64))
        tile = sc.render(h)[0]
        lo, hi = int(grid[0] - 0.5), int(grid[-1] - 0.5)  # pixel indices of the outline's centres
        inner = tile[lo + 1:hi, lo + 1:hi]
        assert np.all(inner == 1.0), f"cracks inside the grid (cull={cull}): {np.argwhere(inner != 1.0)[:5]}"
        covered = tile > 0
        rows, cols = np.flatnonzero(covered.any(1)), np.flatnonzero(covered.any(0))
        # exactly one of the two outline rows (and columns) of centres lies on a top-left edge
        assert len(rows) == hi - lo and len(cols) == hi - lo, f"outline covered as {rows[[0, -1]]}, {cols[[0, -1]]}"
        assert covered.sum() == (hi - lo) ** 2


def test_depth_is_perspective_correct(builtin_body):
    """Two big triangles of a plane receding from 1 m to 5 m: depth matches ray casting to
    1e-5 relative (interpolating z instead of 1/z would be off by decimetres)."""
    verts = np.array([[-1.5, -1.0, 1.0], [1.5, -1.0, 1.0], [-7.5, 5.0, 5.0], [7.5, 5.0, 5.0]])
    flat, h = rigid_mesh(builtin_body, verts, [[0, 2, 1], [1, 2, 3]])
    sc = ParticleScorer(flat, INTR, (40, 30), context="cpu")
    sc.set_observation(np.zeros((INTR.height, INTR.width), np.float32), (0, 0, INTR.width, INTR.height))
    ours = sc.render(h)[0]
    ref = raycast_tiles(flat.pose(h), flat.triangles, sc.tile_box.rays(INTR))[0]
    both = (ours > 0) & (ref > 0)
    assert both.sum() > 300 and np.ptp(ref[both]) > 1.0
    np.testing.assert_allclose(ours[both], ref[both], rtol=1e-5)


# ---------------------------------------------------------------------------- scoring
def test_scores_match_numpy_formula(scorer, body, seed):
    rng = np.random.default_rng(seed + 1)
    h_true = random_poses(body, rng, 1, spread=0.5)[0]
    h = np.concatenate([h_true[None], random_poses(body, rng, 15, around=h_true)])
    scorer.set_observation(observation(body, h_true, rng), person_box(body, h_true[None]))
    obs = scorer.observed
    assert obs.shape == (TILE[1], TILE[0]) and 0 < np.count_nonzero(obs) < obs.size

    tiles, dbg_sums, dbg_counts = scorer.render_and_score(h)
    sums, counts = scorer.score(h)
    assert_written(sums, counts)
    # the production kernel and the debug kernel agree
    np.testing.assert_allclose(sums, dbg_sums, rtol=1e-6, err_msg=f"seed {seed}")
    for name in COUNT_NAMES:
        np.testing.assert_array_equal(counts[name], dbg_counts[name], err_msg=f"{name}, seed {seed}")

    # the reduction alone: numpy's float64 formula on the kernel's own tiles
    ref_sums, ref_counts = reference_score(tiles, obs, T)
    np.testing.assert_allclose(sums, ref_sums, rtol=1e-4, atol=1e-6, err_msg=f"seed {seed}")
    for name in COUNT_NAMES:
        np.testing.assert_array_equal(counts[name], ref_counts[name], err_msg=f"{name}, seed {seed}")
    assert np.all(counts["observed"] == np.count_nonzero(obs))
    assert sums[0] == sums.min(), f"the true pose should score best (seed {seed}): {sums[:4]}"

    # rendering + reduction: the formula on Open3D's tiles, within what 99 % agreement allows
    o3d_sums, o3d_counts = reference_score(oracle_tiles(scorer, h), obs, T)
    n_obs = counts["observed"][0]
    tol = T * max(2.0, 0.01 * n_obs) + 0.002 * n_obs
    assert np.all(np.abs(sums - o3d_sums) <= tol), f"seed {seed}: {np.abs(sums - o3d_sums).max()} > {tol}"
    for name in ("rendered", "both"):
        assert np.all(np.abs(counts[name] - o3d_counts[name]) <= max(2, 0.01 * n_obs)), (name, seed)


def test_unwritten_results_are_poisoned(scorer, body, monkeypatch):
    """Skipping the launch must leave NaN sums and -1 counts, never stale results."""
    import pyopencl as cl

    h = named_poses(body)
    scorer.set_observation(np.full((INTR.height, INTR.width), 3.0, np.float32), person_box(body, h))
    sums, counts = scorer.score(h)
    assert_written(sums, counts)
    monkeypatch.setattr(cl, "enqueue_nd_range_kernel", lambda queue, *args, **kw: cl.enqueue_marker(queue))
    sums, counts = scorer.score(h)
    assert np.all(np.isnan(sums))
    assert all(np.all(counts[name] == -1) for name in COUNT_NAMES)


# ---------------------------------------------------------------------------- bad input
def test_no_particles(scorer, builtin_body):
    sc = scorer
    sc.set_observation(np.zeros((INTR.height, INTR.width), np.float32), (100, 50, 300, 400))
    sums, counts = sc.score(np.zeros((0, 36)))
    assert sums.shape == (0,) and all(counts[k].shape == (0,) for k in COUNT_NAMES)
    assert sc.render(np.zeros((0, 36))).shape == (0, TILE[1], TILE[0])


def test_bad_poses_raise(scorer, body):
    h = named_poses(body)
    scorer.set_observation(np.zeros((INTR.height, INTR.width), np.float32), person_box(body, h))
    bad = h.copy()
    bad[2, 10] = np.nan
    with pytest.raises(ShapeError, match=r"\[2\]"):
        scorer.score(bad)
    bad = h.copy()
    bad[1, 3:7] = 0.0
    with pytest.raises(ShapeError, match="quaternion"):
        scorer.score(bad)
    with pytest.raises(ShapeError, match="36"):
        scorer.score(h[:, :30])
    with pytest.raises(ShapeError, match="36"):
        scorer.score(h[0])  # one pose must still be a (1, 36) batch
    transforms = scorer.transforms(h)
    assert transforms.shape == (len(h), len(body.bone_names), 3, 4) and transforms.dtype == np.float32
    with pytest.raises(ShapeError, match="transforms"):
        scorer.score_transforms(transforms[:, 1:])
    transforms[0, 0, 0, 0] = np.inf
    with pytest.raises(ShapeError, match="non-finite"):
        scorer.score_transforms(transforms)


def test_degenerate_poses_give_defined_results(scorer, body):
    """Behind the camera, at the camera, absurdly far: no crash, no NaN."""
    h = np.tile(named_poses(body)[:1], (4, 1))
    scorer.set_observation(np.full((INTR.height, INTR.width), 2.5, np.float32), person_box(body, h))
    h[0, :3] = (0.0, 0.0, -3.0)  # behind the camera
    h[1, :3] = (0.0, 0.0, 0.0)  # the camera inside the body: triangles cross the near plane
    h[2, :3] = (1e20, -1e20, 1e20)
    h[3, :3] = (0.0, 0.0, 1e-3)
    sums, counts = scorer.score(h)
    assert_written(sums, counts)
    n_obs = counts["observed"][0]
    assert n_obs == TILE[0] * TILE[1]
    assert counts["rendered"][0] == 0 and sums[0] == pytest.approx(T * n_obs, rel=1e-5)


def test_empty_observation(scorer, body):
    h = named_poses(body)
    scorer.set_observation(np.zeros((INTR.height, INTR.width), np.float32), person_box(body, h))
    sums, counts = scorer.score(h)
    assert np.all(sums == 0) and np.all(counts["observed"] == 0) and np.all(counts["both"] == 0)
    assert np.all(counts["rendered"] > 0)
    nan_depth = np.full((INTR.height, INTR.width), np.nan, np.float32)
    scorer.set_observation(nan_depth, person_box(body, h))
    sums, counts = scorer.score(h)
    assert np.all(sums == 0) and np.all(counts["observed"] == 0)


def test_boxes_off_the_image(scorer, body, seed):
    rng = np.random.default_rng(seed + 2)
    h = named_poses(body)
    depth = observation(body, h[0], rng)
    scorer.set_observation(depth, (-200.0, 300.0, 400.0, 400.0))  # partly outside: clipped
    tb = scorer.tile_box
    assert (tb.u0, tb.v0, tb.u0 + tb.bw, tb.v0 + tb.bh) == (0.0, 300.0, 200.0, 480.0)
    tiles, sums, counts = scorer.render_and_score(h)
    ref_sums, ref_counts = reference_score(tiles, scorer.observed, T)
    np.testing.assert_allclose(sums, ref_sums, rtol=1e-4, atol=1e-6)
    scorer.set_observation(depth, (700.0, -500.0, 100.0, 100.0))  # wholly outside
    sums, counts = scorer.score(h)
    assert np.all(sums == 0) and np.all(counts["observed"] == 0)
    for box in [(0, 0, -5, 10), (0, 0, 10, 0), (np.nan, 0, 10, 10), (0, 0, 10)]:
        with pytest.raises(ConfigError, match="box"):
            scorer.set_observation(depth, box)
    with pytest.raises(ShapeError, match="480, 640"):
        scorer.set_observation(depth[:100], (0, 0, 10, 10))


def test_scoring_before_an_observation(builtin_body):
    sc = ParticleScorer(builtin_body, INTR, (16, 16), context="cpu")
    with pytest.raises(ConfigError, match="set_observation"):
        sc.score(builtin_body.rest_pose((0, 0, 3), FACING)[None])


def test_bad_construction(builtin_body):
    with pytest.raises(ConfigError, match="local memory"):
        ParticleScorer(builtin_body, INTR, (4096, 4096), context="cpu")
    with pytest.raises(ConfigError, match="power of two"):
        ParticleScorer(builtin_body, INTR, (16, 16), context="cpu", local_size=3)
    with pytest.raises(ConfigError, match="threshold"):
        ParticleScorer(builtin_body, INTR, (16, 16), threshold=0.0, context="cpu")


@pytest.mark.slow
def test_work_group_variants_agree(builtin_body, seed):
    """The GPU-style layout (many work-items per particle, atomic z-buffer) and the scalar
    reduction (tile width not a multiple of 8) give the CPU layout's results."""
    rng = np.random.default_rng(seed + 3)
    h = np.concatenate([named_poses(builtin_body), random_poses(builtin_body, rng, 4)])
    depth = observation(builtin_body, h[0], rng)
    box = person_box(builtin_body, h)
    for tile in ((32, 24), (36, 28)):
        results = []
        # vector_raster=False is the default path where the width is no multiple of 8: only at 32
        scalar = ({"vector_raster": False},) if tile[0] % 8 == 0 else ()
        for kw in ({}, {"local_size": 32}, {"atomic": True}) + scalar:
            sc = ParticleScorer(builtin_body, INTR, tile, context="cpu", **kw)
            sc.set_observation(depth, box)
            results.append(sc.render_and_score(h))
            tiles, sums, counts = results[-1]
            assert_written(sums, counts)
            ref_sums, ref_counts = reference_score(tiles, sc.observed, T)
            np.testing.assert_allclose(sums, ref_sums, rtol=1e-4, atol=1e-6, err_msg=f"{tile} {kw} seed {seed}")
            for name in COUNT_NAMES:
                np.testing.assert_array_equal(counts[name], ref_counts[name], err_msg=f"{tile} {kw} {name}")
        for tiles, sums, _ in results[1:]:
            np.testing.assert_array_equal(tiles, results[0][0])
            np.testing.assert_allclose(sums, results[0][1], rtol=1e-5)


@pytest.mark.slow
def test_vector_raster_is_bit_identical(body, seed):
    """The CPU layout's vector lanes (8 triangles set up at a time, rows 8 pixels at a time)
    draw exactly the z-buffer of the one-triangle-at-a-time path: on random poses, a box that
    cuts the body, poses crossing the near plane and behind the camera, with and without
    back-face culling, at tile widths of 1, 5 and 8 vector blocks a row."""
    rng = np.random.default_rng(seed + 5)
    h = np.concatenate([named_poses(body), random_poses(body, rng, 10)])
    odd = np.tile(h[:1], (3, 1))
    odd[0, :3] = (0.0, 0.0, -3.0)
    odd[1, :3] = (0.0, 0.3, 0.2)  # the near plane cuts the body
    odd[2, :3] = (0.4, 0.0, 2.0)
    h = np.concatenate([h, odd])
    depth = observation(body, h[0], rng)
    u0, v0, bw, bh = person_box(body, h[:1])
    for tile, box, cull in (((64, 48), (u0, v0, bw, bh), True), ((8, 8), (u0, v0, bw, bh), True),
                            ((40, 30), (u0 + 0.3 * bw, v0 - 0.2 * bh, 0.6 * bw, 0.7 * bh), True),
                            ((64, 48), (u0, v0, bw, bh), False)):
        got = []
        for vector in (True, False):
            sc = ParticleScorer(body, INTR, tile, context="cpu", vector_raster=vector, cull_backfaces=cull)
            assert sc.defines["VECROW"] == vector
            sc.set_observation(depth, box)
            got.append(sc.render_and_score(h))
        assert got[0][0][0].any(), f"{tile}: the first pose should be drawn"
        np.testing.assert_array_equal(got[0][0], got[1][0], err_msg=f"{tile} box {box} cull {cull}")
        np.testing.assert_array_equal(got[0][1], got[1][1])
        for name in COUNT_NAMES:
            np.testing.assert_array_equal(got[0][2][name], got[1][2][name])


def test_device_forward_kinematics_matches_numpy(scorer, body, seed):
    """The kernel's FK (bone transforms and named points) against the float64 numpy oracle on
    poses anywhere within Table 1's limits and any root orientation (quaternions not normalised),
    and the score of device-FK poses against the score of the oracle's transforms."""
    from swarmpose.body.kinematics import transform_points

    rng = np.random.default_rng([seed, 7])
    h = random_poses(body, rng, 48, spread=2.0)
    h[:, 7:] = rng.uniform(ANGLE_LIMITS[:, 0], ANGLE_LIMITS[:, 1], (48, 29))
    h[:, 3:7] = rng.normal(size=(48, 4)) * rng.uniform(0.2, 3.0, (48, 1))  # any orientation, any length
    want = scorer.transforms(h)
    got = scorer.device_transforms(h)
    assert np.abs(got - want).max() < 2e-5, f"seed {seed}"  # rotations (1) and translations (m)
    points = scorer.evaluate(h, render=False).points
    oracle = transform_points(body.point_bones, body.point_rest, want.astype(np.float64))
    assert points.shape == (48, len(body.point_names), 3)
    assert np.abs(points - oracle).max() < 1e-5, f"seed {seed}"  # m
    h_true = random_poses(body, rng, 1)[0]
    scorer.set_observation(observation(body, h_true, rng), person_box(body, h_true[None]))
    sums, counts = scorer.score(h)
    oracle_sums, oracle_counts = scorer.score_transforms(want)
    assert np.allclose(sums, oracle_sums, rtol=1e-3, atol=1e-3), f"seed {seed}"
    for name in COUNT_NAMES:  # a float32 ulp may move a pixel centre across an edge
        assert np.abs(counts[name] - oracle_counts[name]).max() <= 3, f"{name}, seed {seed}"
    joints_only = scorer.evaluate(h, render=False)
    assert not joints_only.sums.any() and not any(c.any() for c in joints_only.counts.values())
