"""The localizer's phases recover labelled poses; switching, false-pose detection, robustness."""
import copy
import dataclasses
import math

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from hvloc.config import LocalizerConfig
from hvloc.geometry import Camera, compose, look_at_cam2world, make_transform, rotation_angle, so3_exp
from hvloc.localizer import DEFAULT_T_B_C, HierarchicalLocalizer, corner_sigma_px
from hvloc.phases import (Detection, FlowTracker, PadDesign, detect_markers, detect_outline, find_grey_outline, find_outline,
                          name_outline)
from hvloc.pose import planar_pose_candidates, solve_planar_pose
from pad_design import make_pad
from render.planar import nadir_cam2pad, warp_pad_view

CAM = Camera.from_hfov(800, 800, math.radians(60))
GROUND = (70, 110, 50)


def tilted(x, y, h, yaw, roll=0.0, pitch=0.0):
    """A camera above pad point (x, y) at height h, yawed, tilted a little about its own axes."""
    T = nadir_cam2pad(x, y, h, yaw)
    T[:3, :3] = T[:3, :3] @ so3_exp([pitch, roll, 0.0])
    return T


def up_in_camera(cam2pad):
    return cam2pad[:3, :3].T @ np.array([0.0, 0.0, 1.0])


def pose_error(T, G):
    return float(np.linalg.norm(T[:3, 3] - G[:3, 3])), math.degrees(rotation_angle(T[:3, :3], G[:3, :3]))


@pytest.fixture(scope="module")
def pad_fine():
    """The default pad with a 4000 px/m texture: the warped test views then have >= 4 texels per
    sample at 3 m, and bilinear texture sampling adds no phase bias to axis-aligned edges."""
    from pad_design import make_pad

    return make_pad(ppm=4000)


@pytest.mark.parametrize("yaw_deg", [0, 35, 80, 150, 260])
def test_adjustment_within_5mm_and_0p2deg_at_3m(pad_fine, yaw_deg):
    pad = pad_fine
    G = tilted(0.2, -0.1, 3.0, math.radians(yaw_deg), 0.04, -0.03)
    img = warp_pad_view(pad, CAM, G, GROUND)
    det, why = detect_markers(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), pad.geometry, CAM, rgb=img)
    assert det is not None, why
    assert len(det.pts_P) == 36 + 4
    res = solve_planar_pose(CAM, det.pts_P, det.px, up_C=up_in_camera(G))
    dp, da = pose_error(res.cam2pad, G)
    assert dp <= 0.005 and da <= 0.2, f"{dp * 1000:.2f} mm, {da:.3f} deg"


@pytest.mark.parametrize("yaw_deg", [10, 100, 200, 300])
def test_approaching_within_1pct_of_height_at_20m(pad, yaw_deg):
    G = tilted(1.5, -1.0, 20.0, math.radians(yaw_deg), 0.05, 0.02)
    img = warp_pad_view(pad, CAM, G, GROUND)
    det, why = detect_outline(img, pad.geometry, CAM)
    assert det is not None, why
    res = solve_planar_pose(CAM, det.pts_P, det.px, up_C=up_in_camera(G))
    dp, da = pose_error(res.cam2pad, G)
    assert dp <= 0.01 * 20.0, f"{dp:.3f} m at 20 m"


@pytest.mark.parametrize("h", [14.0, 20.0])
def test_approaching_height_is_unbiased_on_a_small_pad(pad, h):
    """A half-level edge fit put the outline ~0.18 px outside the border's edge at 30 px (the solid
    band is under a pixel wide, the checker inside it half as bright): the pad looked 1 % too big
    and the height came out 0.85 % low at 20 m, 0.38 % at 14 m.  Fitted with the border's own
    profile, the signed height error is within 0.2 % at each height (median of 16 views), on views
    summed in light as a camera's pixels sum it, where the sides are placed in light: placed in
    display values, 0.48 % (14 m) and 0.77 % (20 m) low.  JPEG'd, they are placed in display values
    as before (JPEG smears chroma there: ``test_jpeg_outline_is_fitted_on_luma_where_its_colour_edges_smear``)."""
    errs = []
    for yaw in np.linspace(0.1, 2 * np.pi, 8, endpoint=False):
        for x in (-1.0, 0.5):
            G = tilted(x, 0.3, h, yaw, 0.03, -0.02)
            det, why = detect_outline(warp_pad_view(pad, CAM, G, GROUND), pad.geometry, CAM)
            assert det is not None, why
            res = solve_planar_pose(CAM, det.pts_P, det.px, up_C=up_in_camera(G))
            errs.append((res.cam2pad[2, 3] - G[2, 3]) / G[2, 3] * 100.0)
    assert abs(np.median(errs)) < 0.2, np.round(errs, 2)


def test_a_frames_halved_chroma_is_told_from_a_whole_one(pad):
    """JPEG and H.264 keep chroma at half resolution, and there the outline's sides are placed in
    display values (its colour edges smear), elsewhere in light.  Told by the chroma's steps along
    its rows: a rendered view as it is, and the same through JPEG at 30-95 (OpenCV's libjpeg, 4:2:0),
    on a green ground and a grey one, near and far; a grey frame (no chroma) is not compressed chroma."""
    from hvloc.phases import chroma_halved

    for ground in (GROUND, (128, 128, 128)):
        for h in (1.5, 6.0):
            rgb = warp_pad_view(pad, CAM, tilted(0.2, -0.1, h, 0.4, 0.02, 0.01), ground)
            assert not chroma_halved(rgb), (ground, h)
            for q in (30, 50, 75, 95):
                assert chroma_halved(_jpeg(rgb, q)), (ground, h, q)
    grey = cv2.cvtColor(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY), cv2.COLOR_GRAY2RGB)
    assert not chroma_halved(grey)


def test_marker_names_and_flip_choice_at_every_10_degrees(pad):
    for k in range(36):
        yaw = math.radians(10 * k)
        G = tilted(-0.1, 0.15, 2.5, yaw, 0.06, 0.0)
        img = warp_pad_view(pad, CAM, G, GROUND)
        det, why = detect_markers(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), pad.geometry, CAM)
        assert det is not None, f"yaw {10 * k}: {why}"
        truth = CAM.project_from(G, det.pts_P)
        # names right: every corner lands on its own projection (a misnamed marker would be ~100 px off)
        assert np.abs(det.px - truth).max() < 1.0, f"yaw {10 * k}: corners misassigned"
        res = solve_planar_pose(CAM, det.pts_P, det.px, up_C=up_in_camera(G), gravity_sigma_deg=None)
        assert res.flip_choice == "gravity" and len(planar_pose_candidates(CAM, det.pts_P, det.px)) == 2
        da = pose_error(res.cam2pad, G)[1]
        # IMU used only to choose between the two IPPE solutions (no tilt prior): the right one
        assert da < 0.5, f"yaw {10 * k}: {da:.2f} deg off (the flipped solution is ~3 deg off)"


def test_flip_is_real_and_gravity_picks_the_right_one(pad):
    """Four near-nadir corners: both IPPE solutions fit the pixels; the gravity prior picks the
    true one, whichever has the lower reprojection error."""
    from hvloc.pose import reprojection_rms

    for seed in range(5):
        G = tilted(0.1, -0.05, 6.0, 0.7 + seed, 0.05, -0.03)
        px = CAM.project_from(G, pad.outer_corners_P) + np.random.default_rng(seed).normal(0, 0.15, (4, 2))
        cands = planar_pose_candidates(CAM, pad.outer_corners_P, px)
        assert len(cands) == 2
        assert all(reprojection_rms(CAM, c, pad.outer_corners_P, px) < 0.5 for c in cands)  # both fit
        errs = sorted(pose_error(c, G)[1] for c in cands)
        assert errs[1] > 3.0  # a real flip
        res = solve_planar_pose(CAM, pad.outer_corners_P, px, up_C=up_in_camera(G), gravity_sigma_deg=None,
                                refine=False)
        assert res.flip_choice == "gravity"
        assert pose_error(res.cam2pad, G)[1] == pytest.approx(errs[0])  # the candidate nearer the truth


def _decoy_scene(pad, with_pad=True):
    G = tilted(0.0, 0.0, 8.0, 0.3)
    img = warp_pad_view(pad, CAM, G, GROUND) if with_pad else np.full((800, 800, 3), GROUND, np.uint8)
    border = pad.geometry.border.color_rgb
    cv2.rectangle(img, (40, 40), (190, 170), border, -1)  # a solid patch of the pad's colour, bigger than the pad
    cv2.fillConvexPoly(img, np.array([[600, 620], [700, 640], [690, 740], [590, 720]]), border)
    sq = np.full((70, 70), 255, np.uint8)  # a lone finder-like square
    sq[7:63, 7:63] = 0
    sq[15:55, 15:55] = 255
    sq[23:47, 23:47] = 0
    img[600:670, 100:170] = sq[..., None]
    return img, G


def test_decoys_are_not_taken_for_the_pad(pad):
    img, G = _decoy_scene(pad)
    det, why = detect_outline(img, pad.geometry, CAM)
    assert det is not None, why
    assert np.abs(det.px - CAM.project_from(G, pad.outer_corners_P)).max() < 1.0
    det, why = detect_markers(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), pad.geometry, CAM)
    assert det is None or np.abs(det.px - CAM.project_from(G, det.pts_P)).max() < 1.0
    img, _ = _decoy_scene(pad, with_pad=False)
    assert detect_outline(img, pad.geometry, CAM)[0] is None
    assert detect_markers(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), pad.geometry, CAM)[0] is None



def _grey(img):
    """A monochrome camera's frame of a colour view (DESIGN.md's frames are RGB: R = G = B)."""
    return cv2.cvtColor(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), cv2.COLOR_GRAY2RGB)


@pytest.mark.parametrize("h", [10.0, 20.0])
@pytest.mark.parametrize("yaw_deg", [10, 200])
@pytest.mark.parametrize("ground", [GROUND, (232, 234, 238)], ids=["grass", "snow"])
def test_a_grey_frames_pad_is_found_by_its_white_field_and_named_by_its_design(pad, h, yaw_deg, ground):
    """In a monochrome camera's frame the magenta border is a grey like the ground's: the colour
    path finds nothing.  The pad is its white field, told from other bright squares by its whole
    printed design, which also names its corners (no prior, no yaw cue: the cue is grey too).  On
    snow the ground is as bright as the field: the field is an island in the ground's blob, inside
    the border's darker ring."""
    G = tilted(1.5, -1.0, h, math.radians(yaw_deg), 0.05, 0.02)
    img = _grey(warp_pad_view(pad, CAM, G, ground))
    assert find_outline(img, pad.geometry, CAM)[0] is None  # the premise: no colour to segment
    loc = HierarchicalLocalizer(pad, CAM)
    e = loc.process(img, 0.0, _imu_from(G))
    assert e.ok and e.method == "outline", e.reason
    dp, da = pose_error(e.cam2pad, G)
    assert dp <= 0.01 * h and da <= 1.0, f"{dp:.3f} m, {da:.2f} deg at {h} m"


def test_a_soft_grey_view_of_the_pad_is_named_by_what_a_quarter_turn_changes(pad):
    """Through a soft lens the finder markers fade while the white field in its dark ring keeps its
    contrast: the design's correlation leads the next naming's by under :data:`hvloc.phases.GREY_MIN_LEAD`
    (a paper pad of 39-56 px in a grey frame, fuzz seed 127: lost for 24 frames).  What a quarter
    turn changes, compared alone (:func:`hvloc.phases.asymmetric_design_scores`), still names it:
    such views are posed (before: 3 of 12 here), within 1 % of the height.  The design made
    symmetric under a quarter turn (the mean of its four turns: a white square in a ring with a
    finder in every corner) reads as well as the pad in every naming and is never posed."""
    import hvloc.phases as ph

    design = ph.PadDesign(pad.texture_rgb)
    t = pad.texture_rgb.astype(np.float32)
    symmetric = dataclasses.replace(pad, texture_rgb=np.round(sum(np.rot90(t, k) for k in range(4)) / 4).astype(np.uint8))
    rng = np.random.default_rng(1)
    posed = faint = 0
    for blur in (1.0, 1.4, 1.8):
        for side in (30, 40, 50):
            h = CAM.fx * pad.geometry.side_m / side
            G = tilted(rng.uniform(-1, 1), rng.uniform(-1, 1), h, rng.uniform(0, 2 * np.pi), 0.02, -0.01)
            grey = cv2.cvtColor(_camera_view(pad, rng, None, (120, 110, 90), G=G, blur_px=blur)[2], cv2.COLOR_RGB2GRAY)
            scores = np.sort(ph.name_by_design(grey, CAM.project_from(G, pad.geometry.outer_corners), pad.geometry, CAM, design)[1])
            faint += scores[-1] - scores[-2] < ph.GREY_MIN_LEAD
            e = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), T_B_C=np.eye(4)).process(np.dstack([grey] * 3), 0.0, imu=G[:3, :3])
            if e.ok:
                posed += 1
                assert pose_error(e.cam2pad, G)[0] < 0.01 * h, (blur, side, pose_error(e.cam2pad, G))
            decoy = cv2.cvtColor(_camera_view(symmetric, rng, None, (120, 110, 90), G=G, blur_px=blur)[2], cv2.COLOR_RGB2GRAY)
            e = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), T_B_C=np.eye(4)).process(np.dstack([decoy] * 3), 0.0, imu=G[:3, :3])
            assert not e.ok, (blur, side, e.method)
    assert faint >= 7 and posed >= 7, (faint, posed)


def test_points_far_out_of_view_are_sampled_without_overflow():
    """A cut pad's cells seen through a wide lens can land past float32's range (a grey fuzz scene's
    design read warned "overflow encountered in cast" into the logs).  They read as the nearest edge,
    as any point outside does, without a warning; points in view read bilinearly, as before, and a
    grid of them (an edge's profiles) as a grid."""
    import warnings

    from hvloc.features import sample_at

    img = np.arange(48, dtype=np.float32).reshape(6, 8) * 5.0
    px = np.array([[2.5, 3.0], [1e39, 2.0], [-1e300, -1e300], [7.0, 5.0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        v = sample_at(img, px)
    assert v.shape == (4,) and v.dtype == np.float64
    assert v[0] == (img[3, 2] + img[3, 3]) / 2.0 and v[3] == img[5, 7]
    assert v[1] == img[2, -1] and v[2] == img[0, 0]  # (the nearest edge's)
    rgb = np.dstack([img, img / 2, 255 - img])
    assert sample_at(rgb, px).shape == (4, 3)
    grid = np.stack([px, px[::-1]])  # (a side's profiles: a grid of points)
    assert sample_at(img, grid).shape == (2, 4) and np.array_equal(sample_at(img, grid)[1], v[::-1])


def test_a_grey_pad_too_small_to_show_its_design_and_grey_ground_are_never_posed(pad):
    """Under 24 px across (here 21 px, at 28 m) the design is a bright square in a dark ring, which
    bright blobs of ground make too: the pad is left to come nearer.  Blobs of grey ground at three
    scales (347 field-shaped ones) are never taken for it."""
    G = tilted(1.5, -1.0, 28.0, 0.2, 0.05, 0.02)
    e = HierarchicalLocalizer(pad, CAM).process(_grey(warp_pad_view(pad, CAM, G, GROUND)), 0.0, _imu_from(G))
    assert not e.ok and "px across at least" in e.reason, e.reason
    design = PadDesign(pad.texture_rgb)
    for seed in range(4):
        for sigma in (2.0, 4.0, 8.0):
            r = cv2.GaussianBlur(np.random.default_rng(seed).normal(0, 1, (800, 800)).astype(np.float32), (0, 0), sigma)
            g = np.clip(120 + 45 * (r - r.mean()) / r.std(), 0, 255).astype(np.uint8)
            found, why = find_grey_outline(cv2.cvtColor(g, cv2.COLOR_GRAY2RGB), g, pad.geometry, CAM, None, design)
            assert found is None, (seed, sigma, found.quad_px)



def test_a_grey_pads_field_is_placed_by_the_borders_whole_profile_not_its_own_edge(tmp_path):
    """The field's edge has the border's checker and solid band a pixel or two beyond it: a step fit
    of that edge alone came out 0.4-0.7 % small on rendered mono frames (the height as much high).
    Fitted with the border's three steps at their known places, the field's size is right within a
    few tenths of a percent from 26 px to 180 px (a rendered mono descent, labels as the truth).
    Rendered in display values (``mix_in_light: false``), where this was measured: mixed in light
    the field comes out 0.3-1.0 % large from 40 to 105 px and the pads under 35 px are not named
    (their design leads the next naming by under 0.08), which awaits fitting the field in light."""
    from hvloc.phases import _field_fit, _mean_side, _through_quad
    from render.dataset import Dataset
    from render.generate import generate
    from render.spec import DatasetSpec

    spec = {"name": "m", "seed": 3, "sequences": 1, "pad_ppm": 1000,
            "camera": {"width": 320, "height": 320, "fps": 2, "mono": True, "supersample": 2, "mix_in_light": False},
            "trajectory": {"start_height_m": 9.0, "duration_s": [6.0, 6.0], "lateral_offset_m": [0.0, 1.0],
                           "families": ["straight"]},
            "degradations": {"shot_noise": [0.0, 0.005], "read_noise": [0.0, 0.004]}}
    generate(DatasetSpec.model_validate(spec), tmp_path, show_progress=False)
    seq = Dataset(tmp_path)[0]
    geo, cam, C = seq.pad.geometry, seq.camera, seq.columns
    design = PadDesign(seq.pad.texture_rgb)
    banded, alone = [], []
    for k in range(len(seq)):
        outer = np.array([[C[f"c{i}u"][k], C[f"c{i}v"][k]] for i in range(4)])
        if not np.isfinite(outer).all():
            continue
        img = seq.image(k)
        truth = _mean_side(_through_quad(outer, geo, cam, geo.field_corners[:, :2]))
        found, why = find_grey_outline(img, img[..., 0].copy(), geo, cam, None, design)
        assert found is not None, (k, why)
        banded.append(_mean_side(found.field_px) / truth - 1)
        alone.append(_mean_side(_field_fit(img, outer, geo, cam, 3.0, rounds=3)[0]) / truth - 1)
    assert len(banded) >= 8
    assert np.median(alone) < -0.003  # the premise: the edge alone reads the field small
    assert abs(np.median(banded)) < 0.0025 and np.max(np.abs(banded)) < 0.007, np.round(np.array(banded) * 100, 2)


def test_a_grey_pads_field_whose_blob_runs_into_a_glare_is_read_where_its_sides_fit(monkeypatch):
    """A grey camera over a pad on a deck, glare washing the border's checker along two sides (fuzz
    seed 204, kept losslessly in tests/data: 50 and 92 px pads): at every threshold the field's bright
    blob runs into the washed checker, its hull's quad lies 1-5 px off, and the design read through it
    falls short of the bars (0.71-0.83, leading the next naming by under 0.08, what a quarter turn
    changes at under 0.55), where the labelled quad reads 0.84-0.91 and leads.  None of
    the blobs reading, the most alike are read again where the field's sides fit from them
    (GREY_REFIT_CANDIDATES, the same bars): found within a px of the labelled corners.  Without that
    second reading, lost where blobs are read as the field alone; read as the whole pad too (the glare
    joins the field's blob to the border's), found as well, as near."""
    import hvloc.phases as ph_mod

    doc, views = _crop_views("grey_glare_deck", 176)
    pad = make_pad(doc["pad_spec"])
    design = PadDesign(pad.texture_rgb)
    for crop, cam, fr in views:
        gray = cv2.cvtColor(crop, cv2.COLOR_RGB2GRAY)
        q = np.array(fr["corners_px"])
        found, why = find_grey_outline(crop, gray, pad.geometry, cam, None, design)
        assert found is not None, (fr["frame"], why)
        assert min(np.abs(np.roll(found.quad_px, k, axis=0) - q).max() for k in range(4)) < 1.0, (found.quad_px, q)
    monkeypatch.setattr(ph_mod, "GREY_REFIT_CANDIDATES", 0)
    for crop, cam, fr in views:
        gray = cv2.cvtColor(crop, cv2.COLOR_RGB2GRAY)
        found = find_grey_outline(crop, gray, pad.geometry, cam, None, design)[0]
        q = np.array(fr["corners_px"])
        assert found is not None and min(np.abs(np.roll(found.quad_px, k, axis=0) - q).max() for k in range(4)) < 1.0
    monkeypatch.setattr(ph_mod, "GREY_BLOB_READS", ("field",))
    for crop, cam, fr in views:
        gray = cv2.cvtColor(crop, cv2.COLOR_RGB2GRAY)
        assert find_grey_outline(crop, gray, pad.geometry, cam, None, design)[0] is None


def test_a_grey_pad_whose_quarter_turns_read_alike_is_read_by_what_a_turn_changes():
    """A 1.6 m pad with fine texture (5-20 mm blobs, an even grey at one sample per pixel) and 0.2 m
    markers, seen by a grey camera through a 100 degree lens at 27-30 px: the whole design read
    through the right naming correlates 0.98, every quarter turn 0.94-0.95, a lead of 0.03-0.035,
    under the 0.04 by which name_by_design names anything, so the part of the design a quarter turn
    changes, which leads by 0.9, was never asked and the pad was lost (fuzz seed 153's scene so
    changed, `u5`: its 21-30 px pads).  Now asked, the outline is found and posed within 0.5 % of the
    height, its corners named right; the ground beside it is not read as the pad."""
    import hvloc.phases as ph_mod

    spec = {"variant": "nested", "side_m": 1.6, "marker_size_m": 0.2, "texture_seed": 82, "border_m": 0.122,
            "border_dark_factor": 0.114, "quiet_zone_modules": 1.05, "nested_marker_size_m": 0.031,
            "texture_min_feature_m": 0.005, "texture_max_feature_m": 0.02, "texture_density": 0.15}
    pad = make_pad(spec)
    cam = Camera.from_hfov(480, 360, math.radians(100))
    design, half = PadDesign(pad.texture_rgb), pad.side_m / 2
    rng = np.random.default_rng(0)
    for side in (27.0, 30.0):
        h = cam.fx * pad.side_m / side
        G = tilted(rng.uniform(-0.3, 0.3) * h, rng.uniform(-0.3, 0.3) * h, h, rng.uniform(0, 2 * np.pi), 0.02, -0.01)
        q = cam.project_from(G, np.array([[-half, half, 0], [half, half, 0], [half, -half, 0], [-half, -half, 0]]))
        gray = cv2.cvtColor(warp_pad_view(pad, cam, G, (150, 140, 120), supersample=3, blur_sigma_px=0.5),
                            cv2.COLOR_RGB2GRAY).astype(np.float32)
        gray = np.clip(gray + rng.normal(0, 3, gray.shape), 0, 255).astype(np.uint8)
        gray = cv2.imdecode(cv2.imencode(".jpg", gray, [cv2.IMWRITE_JPEG_QUALITY, 60])[1], cv2.IMREAD_GRAYSCALE)
        k, scores = ph_mod.name_by_design(gray, q, pad.geometry, cam, design)
        assert k is None and np.sort(scores)[-1] - np.sort(scores)[-2] < ph_mod.DESIGN_MIN_LEAD, scores  # the case
        assert ph_mod._design_read(gray, q, pad.geometry, cam, design)[0] == ph_mod.READS
        assert int(np.argmax(ph_mod.asymmetric_design_scores(gray, q, pad.geometry, cam, design))) == 0  # named right
        assert ph_mod._design_read(gray, q + [1.5 * side, 0.0], pad.geometry, cam, design)[0] == 0
        found, why = find_grey_outline(np.dstack([gray] * 3), gray, pad.geometry, cam, None, design)
        assert found is not None and np.abs(found.quad_px.mean(axis=0) - q.mean(axis=0)).max() < 0.5, why
        loc = HierarchicalLocalizer(pad, cam, LocalizerConfig(), T_B_C=np.eye(4))
        e = loc.process(np.dstack([gray] * 3), 0.0, imu=G[:3, :3])  # the body is the camera; the pad lies level
        assert e.status == "ok" and e.method == "outline", e.reason
        assert np.linalg.norm(e.cam2pad[:3, 3] - G[:3, 3]) < 0.005 * h, (e.cam2pad[:3, 3] - G[:3, 3]) / h
        assert math.degrees(rotation_angle(e.cam2pad[:3, :3], G[:3, :3])) < 1.0


def test_a_far_grey_pad_read_faintly_is_posed_where_its_design_fit_reads_it(tmp_path):
    """A grey camera's far pad (fuzz seed 172's scene: a glossy, dirty paper pad 30-33 px across at
    10-11 m, JPEG 60, sharpened): its white field's blob, a pixel or two off the field, reads as the
    design 0.92-0.95, named alike by what a quarter turn changes (0.47-0.55, leading by 0.5) but under
    that part's bar (0.55), and fitted on luma the field came out 1-2 % large and read no better: no
    cold frame was posed above 9.5 m.  Such a blob is now fitted, and taken where the pad's design fit
    places it and the image there reads as the design at the full bars.  The far frames are posed
    (3 of 10 before here, 6 now), each within its 3 sigma; what is refused says why."""
    from benchmarks.fuzz import config_for, random_scene
    from benchmarks.run import localize_sequence
    from render.dataset import Dataset
    from render.generate import generate
    from render.spec import DatasetSpec

    scene = random_scene(172)
    scene["camera"]["fps"] = 2.0  # (as drawn, 5 Hz: 129 frames; here 26, ten above 7 m)
    spec = DatasetSpec.model_validate(scene)
    generate(spec, tmp_path, show_progress=False)
    seq = Dataset(tmp_path)[0]
    est = localize_sequence(seq, config_for(spec))
    far = [k for k in range(len(seq)) if seq.columns["height_above_pad"][k] > 7.0]
    posed = [k for k in far if est[k].ok]
    assert len(far) >= 8 and len(posed) >= 5, [(k, est[k].reason) for k in far if not est[k].ok]
    for k in posed:
        d = est[k].cam2pad[:3, 3] - seq.cam2pad_at(k)[:3, 3]
        assert d @ np.linalg.solve(est[k].cov[:3, :3], d) < 14.16, (k, d)  # (chi-square, 3 dof, 99.7 %)


def test_a_glossy_grey_pad_is_read_as_its_design_and_posed(tmp_path, monkeypatch):
    """A grey camera (fuzz seed 387's scene: 480x360, 88 degrees, 21 degrees off nadir, JPEG 60) over a
    glossy, stained 1.14 m pad on a moving deck, 26-45 px across at 5-10 m: its sheen and dirt dilute
    what a quarter turn changes, read through the labelled outline 0.40-0.54 where the full bar is
    0.55, and the far frames were lost.  Two things read it now:
    - what a turn changes is read relative to the local brightness too (the better of the two reads
      per naming; ``hvloc.phases._relative``): the sheen scales the markers' contrast where it lies.
      Through the labelled outline more far views read at the full bars so than without;
    - a view read only faintly is taken where its fitted drawing, lit square by square, matches the
      frame as a placed pad's does (``FAINT_READ_FIT_NCC``).  With that bar out of reach too, fewer are
      posed, and the others are refused as read faintly.
    Each far pose lies within its 3 sigma."""
    import hvloc.localizer as loc_mod
    import hvloc.phases as ph_mod
    from benchmarks.fuzz import config_for, random_scene
    from benchmarks.run import frame_image, localize_sequence
    from render.dataset import Dataset
    from render.generate import generate
    from render.spec import DatasetSpec

    scene = random_scene(387)
    scene["camera"]["fps"] = 2.0  # (as drawn, 10 Hz: 156 frames; here 32, fourteen above 5 m)
    spec = DatasetSpec.model_validate(scene)
    generate(spec, tmp_path, show_progress=False)
    seq = Dataset(tmp_path)[0]
    far = [k for k in range(len(seq)) if seq.columns["height_above_pad"][k] > 5.0]
    cam = seq.camera

    def reads():  # far views whose labelled outline reads as the design at the full bars
        design = ph_mod.PadDesign(seq.pad.texture_rgb)
        n = 0
        for k in far:
            gray = cv2.cvtColor(frame_image(seq, k)[0], cv2.COLOR_RGB2GRAY)
            q = np.array([[seq.columns[f"c{i}{a}"][k] for a in "uv"] for i in range(4)], np.float64)
            n += ph_mod._design_read(gray, q, seq.pad.geometry, cam, design)[0] == ph_mod.READS
        return n

    def posed():
        est = localize_sequence(seq, config_for(spec))
        for k in far:
            if est[k].ok:
                d = est[k].cam2pad[:3, 3] - seq.cam2pad_at(k)[:3, 3]
                assert d @ np.linalg.solve(est[k].cov[:3, :3], d) < 14.16, (k, d)  # (chi-square, 3 dof, 99.7 %)
        return [k for k in far if est[k].ok], {k: est[k].reason for k in far if not est[k].ok}

    got, why = posed()
    assert len(far) >= 12 and len(got) >= 11, why
    relative = reads()  # (14 of 14 here; the plain read alone: 2)
    monkeypatch.setattr(ph_mod, "_relative", lambda a: a)  # the plain read alone
    assert relative >= len(far) - 2 and reads() <= relative - 6
    monkeypatch.setattr(loc_mod, "FAINT_READ_FIT_NCC", 1.01)
    before, why = posed()
    assert len(before) <= len(got) - 4 and any("read faintly" in r for r in why.values()), (before, why)


def _grey_decoy_scene(pad, with_pad=True):
    """:func:`_decoy_scene` in grey, with bright squares besides: a plain one, one ringed dark as
    the pad's border is (a pad with no design), an ArUco marker and one on a white margin."""
    img, G = _decoy_scene(pad, with_pad)
    cv2.rectangle(img, (300, 80), (360, 140), (250, 250, 250), -1)
    cv2.rectangle(img, (450, 60), (540, 150), (90, 90, 90), -1)
    cv2.rectangle(img, (462, 72), (528, 138), (250, 250, 250), -1)
    aruco = cv2.aruco.generateImageMarker(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), 3, 60)
    img[250:310, 80:140] = aruco[..., None]
    img[400:484, 650:734] = cv2.copyMakeBorder(aruco, 12, 12, 12, 12, cv2.BORDER_CONSTANT, value=255)[..., None]
    return _grey(img), G


def test_grey_decoys_are_not_taken_for_the_pad(pad):
    """Bright squares alike under a quarter turn correlate with the design alike in every naming
    (0.75-0.83 here): no naming leads, and none is the pad."""
    design = PadDesign(pad.texture_rgb)
    img, G = _grey_decoy_scene(pad)
    gray = img[..., 0].copy()
    found, why = find_grey_outline(img, gray, pad.geometry, CAM, None, design)
    assert found is not None, why
    truth = CAM.project_from(G, pad.geometry.field_corners)
    assert min(np.abs(np.roll(found.field_px, k, axis=0) - truth).max() for k in range(4)) < 1.0
    img, _ = _grey_decoy_scene(pad, with_pad=False)
    found, why = find_grey_outline(img, img[..., 0].copy(), pad.geometry, CAM, None, design)
    assert found is None and "reads as the pad's design" in why, why
    loc = HierarchicalLocalizer(pad, CAM)
    for k in range(4):
        e = loc.process(img, 0.1 * k, _imu_from(G))
        assert not e.ok, (e.method, e.reason)


def test_a_grey_pad_whose_border_is_as_bright_as_its_field_is_posed_by_its_design(monkeypatch):
    """A grey camera over a small pad with a wide border (fzu164's proportions: 0.6 m, a 0.137 m
    border, 2.5 cm checker) whose colour is bright in luma (cyan here; fzu164's magenta under a midday
    sun): the field's bright blob runs into the border and is the whole pad's, and the field's edge
    against the checker, as bright around its squares, does not fit.  Each bright blob is read as the
    whole pad as well as the field, and one that reads as the design where its field's sides do not
    fit is taken where its design fit places it, reading as the design there (``hull_only``); the 70 px
    view's blob lies 1.4 px off and reads only where its sides are fitted against the ground.  Posed
    from 28 to 70 px within 0.7 % of the height and within its 3 sigma; without these, lost."""
    import hvloc.phases as ph_mod

    pad = make_pad({"side_m": 0.6, "border_m": 0.137, "border_color": "#30f0f0", "border_dark_factor": 0.19,
                    "border_checker_m": 0.025, "marker_size_m": 0.09, "quiet_zone_modules": 1.26})
    design = PadDesign(pad.texture_rgb)
    rng = np.random.default_rng(3)
    views = []
    for side in (28.0, 34.0, 40.0, 48.0, 58.0, 70.0):  # (poses drawn for six sizes, four viewed)
        h = CAM.fx * pad.side_m / side
        G = tilted(rng.uniform(-0.3, 0.3) * h, rng.uniform(-0.3, 0.3) * h, h, rng.uniform(0, 2 * np.pi), 0.03, -0.02)
        if side in (28.0, 40.0, 58.0, 70.0):
            views.append((h, G, _grey(warp_pad_view(pad, CAM, G, (110, 110, 110), blur_sigma_px=0.6))))
    for h, G, img in views:
        found, why = find_grey_outline(img, img[..., 0].copy(), pad.geometry, CAM, None, design)
        assert found is not None and found.hull_only and found.read_after_fit, why  # its field's sides did not fit
        e = HierarchicalLocalizer(pad, CAM).process(img, 0.0, _imu_from(G))
        assert e.ok and e.method == "outline", e.reason
        d = e.cam2pad[:3, 3] - G[:3, 3]
        assert np.linalg.norm(d) < 0.007 * h and d @ np.linalg.solve(e.cov[:3, :3], d) < 14.16, (d / h, e.cov)
    monkeypatch.setattr(ph_mod, "_grey_blob_only", lambda best, why: (None, why))
    for h, G, img in views:
        assert not HierarchicalLocalizer(pad, CAM).process(img, 0.0, _imu_from(G)).ok
    monkeypatch.setattr(ph_mod, "GREY_BLOB_READS", ("field",))  # nor blobs read as the whole pad: as before
    for h, G, img in views:
        assert not HierarchicalLocalizer(pad, CAM).process(img, 0.0, _imu_from(G)).ok


def test_flow_drift_bounded_over_60_touchdown_frames_without_reanchoring(pad):
    cam = Camera.from_hfov(480, 480, math.radians(60))
    poses = [tilted(0.05 + 0.002 * k, -0.03 + 0.001 * k, 0.30 - 0.0025 * k, 0.4 + 0.01 * k, 0.01 * math.sin(k / 9), 0.0)
             for k in range(61)]
    imgs = [cv2.cvtColor(warp_pad_view(pad, cam, T, GROUND), cv2.COLOR_RGB2GRAY) for T in poses]
    flow = FlowTracker(cam)
    assert flow.anchor(imgs[0], poses[0]) and len(flow.kf.px) >= 40
    errs = []
    for k in range(1, 61):
        res, n, why = flow.track(imgs[k], poses[k - 1], up_in_camera(poses[k]))
        assert res is not None, f"frame {k}: {why}"
        flow.accept(res.cam2pad, res.rms_px)  # keyframes renew from the tracker's own poses: no re-anchoring
        errs.append(pose_error(res.cam2pad, poses[k]))
    dp = max(e[0] for e in errs)
    da = max(e[1] for e in errs)
    assert dp < 0.005 and da < 1.0, f"drift {dp * 1000:.1f} mm, {da:.2f} deg over 60 frames"


def test_keyframe_corners_are_found_in_shadow_beside_a_sunlit_strip(pad):
    """At touchdown the drone's shadow may cover most of the view, with a strip of sunlit pad beside
    it: its corners' Harris response is hundreds of times the shadowed texture's, and judged
    against the frame's strongest every corner was on the strip (moving_deck at 0.17 m: 16 corners,
    none three frames on).  Judged cell by cell, the shadowed texture gives most of them, and the
    flow tracks the next frames from them.  (Beyond the pad, where the tracker must take corners
    from the whole frame, it takes the strongest: see harris_corners' cells.)"""
    from hvloc.phases import harris_corners

    cam = Camera.from_hfov(480, 480, math.radians(60))
    poses = [tilted(0.03 + 0.002 * k, -0.02, 0.22 - 0.004 * k, 0.3 + 0.01 * k) for k in range(6)]

    def shadowed(G):  # the drone's shadow over all but a strip of rows along the bottom
        img = warp_pad_view(pad, cam, G, GROUND).astype(np.float64)
        img[:420] *= 0.15
        return cv2.cvtColor(np.clip(img, 0, 255).astype(np.uint8), cv2.COLOR_RGB2GRAY)

    imgs = [shadowed(G) for G in poses]
    px = harris_corners(imgs[0])
    assert px is not None and len(px) >= 100
    assert np.mean(px[:, 1] < 410) > 0.6, np.mean(px[:, 1] < 410)  # most in the shadow, as most of the view is
    flow = FlowTracker(cam, region_P=pad.geometry.outer_corners)  # (the pad's corners, as the localizer's)
    assert flow.anchor(imgs[0], poses[0])
    for k in range(1, len(poses)):
        res, n, why = flow.track(imgs[k], poses[k - 1], up_in_camera(poses[k]))
        assert res is not None and n >= 60, (k, n, why)
        assert pose_error(res.cam2pad, poses[k])[0] < 0.002, (k, pose_error(res.cam2pad, poses[k]))
        flow.accept(res.cam2pad, res.rms_px)


def test_masked_harris_corners_read_only_the_masks_box_and_are_the_whole_frames(pad):
    """A mask's corners are read on its box (and a margin), not the whole frame: a 4K frame costs
    150-190 ms whole.  They must be the corners the whole frame gives under that mask: the same
    pixels and the same strongest response (the cells' floor is judged against it), for masks
    at the frame's edges and inside it, and none for an empty mask."""
    from hvloc.phases import HARRIS_QUALITY, _strongest, harris_corners

    cam = Camera.from_hfov(640, 480, math.radians(60))
    g = cv2.cvtColor(warp_pad_view(pad, cam, tilted(0.02, -0.01, 0.35, 0.4), GROUND), cv2.COLOR_RGB2GRAY)
    rng = np.random.default_rng(5)
    for x0, y0, x1, y1 in [(0, 0, 200, 150), (440, 330, 640, 480), (120, 90, 420, 300), (300, 0, 310, 480),
                           *[tuple(rng.integers([0, 0, 330, 250], [300, 230, 640, 480])) for _ in range(6)]]:
        mask = np.zeros_like(g)
        mask[y0:y1, x0:x1] = 255
        mask[(y0 + y1) // 2, x0:x1] = 0  # (not a plain box)
        whole, q = cv2.goodFeaturesToTrackWithQuality(g, 150, HARRIS_QUALITY, 8, mask, blockSize=5,
                                                      useHarrisDetector=True, k=0.04)
        px, top = _strongest(g, 150, mask)
        assert len(px) == len(whole) > 0
        assert np.abs(px - whole.reshape(-1, 2)).max() == 0.0, (x0, y0, x1, y1)
        assert abs(top - float(np.max(q))) <= 1e-6 * float(np.max(q))
        assert (mask[px[:, 1].astype(int), px[:, 0].astype(int)] > 0).all()
    assert harris_corners(g, mask=np.zeros_like(g)) is None


def _raised_pad_view(pad, cam, G, raise_m, ground_tex, tex_m):
    """``G``'s view of the pad lying ``raise_m`` above strongly textured ground (``ground_tex``
    spans ``tex_m`` metres about the pad's centre): each pixel's ray meets the pad's plane, and
    where that is off the pad, the ground's."""
    pad_img = warp_pad_view(pad, cam, G, GROUND)
    u, v = np.meshgrid(np.arange(cam.width, dtype=np.float64), np.arange(cam.height, dtype=np.float64))
    rays = np.column_stack([cam.normalized_from_pixels(np.column_stack([u.ravel(), v.ravel()])), np.ones(u.size)])
    d = rays @ G[:3, :3].T
    lo, hi = pad.geometry.outer_corners[:, :2].min(axis=0), pad.geometry.outer_corners[:, :2].max(axis=0)
    on_pad = G[:3, 3] + (-G[2, 3] / d[:, 2])[:, None] * d
    keep = np.all((on_pad[:, :2] >= lo) & (on_pad[:, :2] <= hi), axis=1).reshape(u.shape)
    ground = G[:3, 3] + ((-raise_m - G[2, 3]) / d[:, 2])[:, None] * d
    n = ground_tex.shape[0]
    mx = ((ground[:, 0] / tex_m + 0.5) * n).reshape(u.shape).astype(np.float32)
    my = ((ground[:, 1] / tex_m + 0.5) * n).reshape(u.shape).astype(np.float32)
    g = cv2.remap(ground_tex, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    return np.where(keep[..., None], pad_img, g[..., None].repeat(3, axis=2))


def test_flow_on_a_raised_pad_over_detailed_ground_follows_the_pad(pad):
    """A pad on a 0.4 m platform over detailed ground (grass seen from 1.5 m: many strong
    corners, most of the view): the ground is not the pad's plane.  Keyframe features come from
    the pad, so tracking the descent keeps the pad's height; taken from anywhere, the ground's
    corners outnumber the pad's and the descent is read too slow (the realism suite: 4-9 cm off
    at 0.7 m, accepted)."""
    cam = Camera.from_hfov(480, 480, math.radians(70))
    rng = np.random.default_rng(5)
    tex = cv2.GaussianBlur((rng.random((1024, 1024)) * 255).astype(np.float32), (0, 0), 1.2)
    tex = np.clip((tex - tex.mean()) * 4 + 128, 0, 255).astype(np.uint8)
    poses = [tilted(0.15 + 0.01 * k, -0.1, 1.6 - 0.06 * k, 0.3 + 0.01 * k, 0.01, -0.01) for k in range(8)]
    imgs = [cv2.cvtColor(_raised_pad_view(pad, cam, T, 0.4, tex, 6.0), cv2.COLOR_RGB2GRAY) for T in poses]
    worst = {}
    for name, region in (("pad", pad.geometry.outer_corners), ("anywhere", None)):
        flow = FlowTracker(cam, region_P=region)
        assert flow.anchor(imgs[0], poses[0])
        errs = []
        for k in range(1, len(poses)):
            res, n, why = flow.track(imgs[k], poses[k - 1], up_in_camera(poses[k]))
            if res is None:
                errs.append(np.inf)
                continue
            flow.accept(res.cam2pad, res.rms_px)
            errs.append(pose_error(res.cam2pad, poses[k])[0])
        worst[name] = max(errs)
    assert worst["pad"] < 0.01, worst
    assert worst["anywhere"] > 3 * worst["pad"], worst  # what the ground's corners did


def test_the_flow_takes_no_keyframe_corners_from_beside_a_moving_deck(pad):
    """A pad on a 0.4 m deck moving at 0.7 m/s over detailed ground, a quarter of it in view at 1.7
    m: it gives 13 Harris corners, fewer than a keyframe needs, and the keyframe took the whole
    frame's, the ground's, which is neither the pad's plane nor still under it: the chain drifted 25
    mm a frame (unseen58: four poses 19-28 cm off at 1.8 m, accepted).  The localizer's flow takes
    the pad's corners only (``FlowTracker.ground``), and here makes no keyframe; the flow-only
    ablation, which tracks whatever it sees, still may."""
    cam = Camera.from_hfov(480, 480, math.radians(70))
    rng = np.random.default_rng(5)
    tex = cv2.GaussianBlur((rng.random((1024, 1024)) * 255).astype(np.float32), (0, 0), 1.2)
    tex = np.clip((tex - tex.mean()) * 4 + 128, 0, 255).astype(np.uint8)

    def view(k):  # 20 Hz: the ground slides 35 mm a frame under the deck
        T = tilted(1.2, 1.2, 1.7 - 0.02 * k, 0.3, 0.01, -0.01)
        img = _raised_pad_view(pad, cam, T, 0.4, np.roll(tex, int(-0.035 * k / 6.0 * 1024), axis=1), 6.0)
        return cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), T

    assert not HierarchicalLocalizer(pad, CAM, LocalizerConfig()).flow.ground
    assert HierarchicalLocalizer(pad, CAM, LocalizerConfig(anchor_once=True)).flow.ground
    g0, T0 = view(0)
    flow = FlowTracker(cam, region_P=pad.geometry.outer_corners)
    assert len(flow._pad_corners(g0, T0)) < flow.min_tracks
    assert flow.anchor(g0, T0)  # the whole frame's corners (as before, and for the ablation)
    prev = T0
    for k in range(1, 6):
        g, T = view(k)
        res, n, why = flow.track(g, prev, up_in_camera(T))
        assert res is not None, why
        flow.accept(res.cam2pad, res.rms_px)
        prev = res.cam2pad
    assert pose_error(prev, T)[0] > 0.1  # the premise: the ground's chain ran off
    flow = FlowTracker(cam, region_P=pad.geometry.outer_corners)
    flow.ground = False
    assert not flow.anchor(g0, T0) and flow.kf is None


def _views(pad, n, h0=3.0, h1=2.4):
    out = []
    for k in range(n):
        G = tilted(0.1, 0.05, h0 + (h1 - h0) * k / max(n - 1, 1), 0.5 + 0.01 * k, 0.03, 0.01)
        out.append((warp_pad_view(pad, CAM, G, GROUND), G))
    return out


def _imu_from(G, T_B_C=DEFAULT_T_B_C, extra=np.eye(3)):
    R_W_C = G[:3, :3]  # the pad is level and its yaw is the world's
    return extra @ R_W_C @ T_B_C[:3, :3].T


def test_a_pad_turning_under_the_camera_is_followed_and_a_heading_jump_still_refused(pad):
    """A ship turning, or its deck yawing in a swell (20 degrees, period 9 s): the pad turns in the
    world under the camera, and the vision-IMU offset's heading with it.  The reference of a level
    pad, drawn a twentieth of the way toward each pose, lagged past the jump's bar (before: 9 of
    these 40 frames refused); the pad's heading is now followed at its turn rate
    (:class:`hvloc.localizer.PadHeading`): every frame posed.  A pose whose heading jumps 10
    degrees off that turn in one frame is still refused."""
    views = _views(pad, 40, 3.0, 2.0)
    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig())
    for k, (img, G) in enumerate(views):
        t = 0.1 * k
        yaw = math.radians(20.0) * math.sin(2.0 * math.pi * t / 9.0) + (math.radians(10.0) if k == 25 else 0.0)
        e = loc.process(img, t, _imu_from(G, extra=so3_exp([0.0, 0.0, yaw])))
        if k == 25:
            assert e.status == "rejected" and "vision-IMU rotation jumped" in e.reason, e.reason
        else:
            assert e.ok, f"frame {k}: {e.status} {e.reason}"
            assert np.linalg.norm(e.cam2pad[:3, 3] - G[:3, 3]) < 0.01 * G[2, 3], k



@pytest.mark.parametrize("turn_deg, posed", [(8.0, True), (-8.0, True), (30.0, False)])
def test_a_pad_that_turned_unseen_is_posed_again_and_a_larger_jump_still_refused(pad, turn_deg, posed):
    """A deck yawing while the pad is out of sight (2.5 s of frames with no pad) has turned when it
    is seen again: the jump's bar grants what it may have turned unseen, beyond what the heading
    filter carries (:meth:`hvloc.localizer.FalsePoseGates.unseen_turn_deg`).  Before, the 8 degrees
    a 5 degree yaw swell turned in such a gap (fz340, fzu17) were refused as a jump until the
    reference started again eight frames later.  What the bar grants is capped: a heading 30
    degrees off after the gap is still refused."""
    views = _views(pad, 14, 3.0, 2.6)
    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig())
    for k, (img, G) in enumerate(views[:8]):
        assert loc.process(img, 0.1 * k, _imu_from(G)).ok, k
    blank = np.full_like(views[0][0], 90)
    for k in range(25):
        assert not loc.process(blank, 0.8 + 0.1 * k, _imu_from(views[7][1])).ok
    for j, (img, G) in enumerate(views[8:]):
        e = loc.process(img, 3.3 + 0.1 * j, _imu_from(G, extra=so3_exp([0.0, 0.0, math.radians(turn_deg)])))
        if posed:
            assert e.ok, f"frame {j} after the gap: {e.status} {e.reason}"
            assert np.linalg.norm(e.cam2pad[:3, 3] - G[:3, 3]) < 0.01 * G[2, 3], j
        elif j < 3:  # (after eight refused poses the reference starts again: two a frame here)
            assert e.status == "rejected" and "vision-IMU rotation jumped 10.0 deg" in e.reason, (j, e.reason)
            assert "20 deg it may have turned unseen" in e.reason, e.reason

def _offsets(yaw_of, rate_hz, seconds, jitter_deg, seed):
    """``(t, R_W_P)``: the vision-IMU offset of a pad whose heading is ``yaw_of(t)`` (rad), seen
    through an AHRS whose heading jitters ``jitter_deg`` from row to row (white)."""
    rng = np.random.default_rng(seed)
    for k in range(int(seconds * rate_hz)):
        t = k / rate_hz
        yield t, so3_exp([0.0, 0.0, yaw_of(t) + math.radians(jitter_deg) * rng.normal()])


@pytest.mark.parametrize("rate_hz, jitter_deg", [(10.0, 0.3), (10.0, 0.6), (30.0, 0.3), (5.0, 1.0)])
def test_an_ahrs_heading_that_jitters_is_no_turn_of_the_pad(rate_hz, jitter_deg):
    """A still pad seen through an AHRS whose heading jitters (a magnetometer's, row to row) while
    each pose states its own heading to 0.05 degrees: the jitter is the offsets' noise, not a turn
    (:meth:`hvloc.localizer.PadHeading.unexplained_var`).  Weighed at the poses' sigma alone, 0.3
    degrees at 10 Hz read as turns of 10 degrees a second; carried through a second without a pose
    the reference was 10 degrees off and refused eight right poses (gusty_blur at 0.2 m)."""
    from hvloc.localizer import PadHeading

    turns, off, n = 0, 0, 0
    for seed in range(3):
        hd = PadHeading()
        for t, R in _offsets(lambda t: 0.4, rate_hz, 20.0, jitter_deg, seed):
            hd.update(t, R, math.radians(0.05) ** 2)
            if t > 2.0:  # after two seconds: the scatter is read from the offsets themselves
                n += 1
                turns += hd.turning()
                # were the pad lost now, its heading a second on past the gates' jump bar (4 degrees)
                off += abs(math.degrees(hd.predicted(t + 1.0) - 0.4)) > LocalizerConfig().imu_jump_deg
    # a turn read from noise at three sigmas stays possible (before: 16-42 % of the frames)
    assert turns <= 0.01 * n and off <= 0.01 * n, (turns, off, n)


@pytest.mark.parametrize("rate_hz, jitter_deg", [(10.0, 0.3), (10.0, 0.6), (30.0, 0.3)])
def test_an_ahrs_heading_that_jitters_is_no_turn_of_the_pad_from_the_first_pose(rate_hz, jitter_deg):
    """The same, in the flight's first three seconds, before the offsets have shown their scatter
    (:data:`hvloc.localizer.PAD_HEADING_JITTER_PRIOR_DEG`).  Read from the first few triples alone,
    the scatter came out nil as often as not: fz549's AHRS (its heading jittering 0.46 degrees)
    showed a turn of -11 degrees a second 0.8 s in, and carried on, it refused seven right outline
    poses at 6.5-8.4 m as jumps of 4.6-12.5 degrees.  Before, in 14-64 % of these flights the heading
    predicted a second ahead was at some pose past the gates' jump bar."""
    from hvloc.localizer import PadHeading

    bar = LocalizerConfig().imu_jump_deg
    off = 0
    for seed in range(100):
        hd = PadHeading()
        for t, R in _offsets(lambda t: 0.4, rate_hz, 3.0, jitter_deg, seed):
            hd.update(t, R, math.radians(0.05) ** 2)
            if abs(math.degrees(hd.predicted(t + 1.0) - 0.4)) > bar:
                off += 1
                break
    assert off <= 2, off


def test_poses_from_the_first_are_taken_through_a_jittering_ahrs(pad):
    """The localizer through it from its first pose: a still pad at 10 Hz, a fifth of the frames
    dropped, an AHRS whose heading jitters 0.5 degrees from frame to frame: every pose is taken, in
    each of 30 flights (before, one of them lost two right poses as jumps; fz549 lost seven, after a
    turn read from its first eight offsets)."""
    views = _views(pad, 30, 3.0, 2.4)
    for seed in range(30):
        rng = np.random.default_rng(seed)
        loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig())
        for k, (img, G) in enumerate(views):
            if k > 0 and rng.random() < 0.2:
                continue
            jitter = so3_exp([0.0, 0.0, math.radians(0.5) * rng.normal()])
            e = loc.process(img, 0.1 * k, _imu_from(G, extra=jitter))
            assert e.ok, f"flight {seed}, frame {k}: {e.status} {e.reason}"


def test_a_turning_deck_is_followed_through_a_jittering_ahrs():
    """The same jitter (0.3 degrees at 10 Hz) over a deck yawing 20 degrees in 9 s: the turn is
    still followed, not smoothed away as noise (the offsets' scatter is read about the line
    through their neighbours, which a turn lies on): its heading predicted a frame ahead within 1.6
    degrees in 95 % of the frames (the jitter's 0.3 and the turn's 1.4 a frame), and the turn known
    in most of the frames where it is fast."""
    from hvloc.localizer import PadHeading

    def yaw(t):
        return math.radians(20.0) * math.sin(2.0 * math.pi * t / 9.0)

    off, fast, known = [], 0, 0
    for seed in range(3):
        hd = PadHeading()
        for t, R in _offsets(yaw, 10.0, 27.0, 0.3, seed):
            if t > 3.0:
                off.append(abs(math.degrees(math.remainder(hd.predicted(t) - yaw(t), 2.0 * math.pi))))
                if abs(math.cos(2.0 * math.pi * t / 9.0)) > 0.8:  # turning faster than 11 degrees a second
                    fast += 1
                    known += hd.turning()
            hd.update(t, R, math.radians(0.05) ** 2)
    assert np.percentile(off, 95) < 1.6 and known >= 0.7 * fast, (np.percentile(off, 95), known, fast)


def test_poses_after_a_second_lost_are_taken_through_a_jittering_ahrs(pad):
    """The localizer through it: a still pad, an AHRS whose heading jitters 0.5 degrees from frame
    to frame (10 Hz), a second with nothing in view, then the pad again: every pose after the gap
    is taken, in each of four flights (before, a turn read from the jitter was carried through the
    gap and the right poses after it refused as a vision-IMU jump)."""
    views = _views(pad, 30, 3.0, 2.4)
    blank = np.full_like(views[0][0], 90)
    for seed in range(4):
        rng = np.random.default_rng(seed)
        loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig())
        for k in range(60):
            img, G = views[k % 30] if not 30 <= k < 40 else (blank, views[29][1])
            jitter = so3_exp([0.0, 0.0, math.radians(0.5) * rng.normal()])
            e = loc.process(img, 0.1 * k, _imu_from(G, extra=jitter))
            if k >= 40:
                assert e.ok, f"flight {seed}, frame {k}: {e.status} {e.reason}"


def test_injected_orientation_jump_is_rejected_smooth_drift_is_not(pad):
    views = _views(pad, 14)
    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig())
    statuses = []
    for k, (img, G) in enumerate(views):
        drift = so3_exp([0, 0, math.radians(0.15 * k)])  # slow AHRS yaw drift: 2 degrees over the run
        jump = so3_exp([math.radians(8.0), 0, 0]) if k == 10 else np.eye(3)
        e = loc.process(img, 0.05 * k, _imu_from(G, extra=jump @ drift))
        statuses.append(e.status)
        if k == 10:
            assert e.status == "rejected" and "IMU" in e.reason, e.reason
        else:
            assert e.status == "ok", f"frame {k}: {e.status} {e.reason}"
    assert statuses.count("rejected") == 1


def test_phase_switching_follows_height(pad):
    cfg = LocalizerConfig(adjust_height_m=5.0, touchdown_height_m=0.5)
    loc = HierarchicalLocalizer(pad, CAM, cfg)
    phases = []
    for k, h in enumerate([12.0, 10.0, 8.0, 6.0, 4.0, 3.0, 2.5]):
        G = tilted(0.0, 0.0, h, 0.2)
        e = loc.process(warp_pad_view(pad, CAM, G, GROUND), 0.5 * k, _imu_from(G))  # 4 m/s at most
        assert e.status == "ok", e.reason
        phases.append(e.phase)
    assert phases[:3] == ["approaching"] * 3 and phases[-2:] == ["adjustment"] * 2


BAD_IMAGES = [None, "image", np.zeros((0, 0, 3), np.uint8), np.zeros((5, 5, 3), np.uint8),
              np.zeros((800, 800, 5), np.uint8), np.zeros((800, 800), np.complex64),
              np.full((800, 800, 3), np.nan, np.float32), np.zeros((800, 800, 3), np.uint8),
              np.full((800, 800, 3), 255, np.uint8), np.zeros((400, 300, 3), np.uint8)]


@pytest.mark.parametrize("image", BAD_IMAGES, ids=range(len(BAD_IMAGES)))
def test_bad_images_are_lost_with_a_reason(pad, image):
    loc = HierarchicalLocalizer(pad, CAM)
    e = loc.process(image, 0.0)
    assert e.status == "lost" and e.reason and "internal error" not in e.reason


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                    HealthCheck.too_slow])
@given(st.one_of(
    arrays(st.sampled_from([np.uint8, np.float32, np.float64, np.int16, np.uint16]),
           st.tuples(st.sampled_from([1, 16, 64, 800]), st.sampled_from([1, 16, 64, 800]),
                     st.sampled_from([1, 3, 4])),
           elements=None),
    arrays(np.uint8, st.just((800, 800, 3)), elements=st.integers(0, 255)),
), st.floats(allow_nan=True, allow_infinity=True))
def test_no_image_makes_process_raise(pad, image, t):
    loc = HierarchicalLocalizer(pad, CAM)
    for _ in range(2):
        e = loc.process(image, t, imu=np.eye(3))
        assert e.status in ("ok", "rejected", "lost")
        assert "internal error" not in e.reason, e.reason


def test_bad_localizer_config_exits_2(tmp_path):
    import subprocess
    import sys

    cfg = tmp_path / "c.yaml"
    cfg.write_text("adjust_height_m: 2\ntouchdown_height_m: 3\n")
    ds = tmp_path / "ds"
    ds.mkdir()
    r = subprocess.run([sys.executable, "-m", "hvloc.cli", "localize", str(ds), "--out", str(tmp_path / "o"),
                        "--config", str(cfg)], capture_output=True, text=True)
    assert r.returncode == 2 and "touchdown_height_m" in r.stderr, r.stderr
    cfg.write_text("adjust_hieght_m: 2\n")
    r = subprocess.run([sys.executable, "-m", "hvloc.cli", "localize", str(ds), "--out", str(tmp_path / "o"),
                        "--config", str(cfg)], capture_output=True, text=True)
    assert r.returncode == 2 and "adjust_hieght_m: unknown key" in r.stderr, r.stderr


def test_a_marker_found_in_part_lends_the_others_no_error(monkeypatch):
    """A marker found by one of its squares alone, 4 px off (a square taken from something else), is
    left out of the markers pose; its offset is its own finding's, not an error the markers found
    whole share.  Lent to them (as 4/sqrt(3) px of shared shift and swell), the pose of the two left
    was free to swell and slid 17-26 % of the height off, "ok" (a random scene found it: a nested
    pad's centre set at 0.9 m, JPEG 60, 20 % high).  A descent over the nested pad to 0.44 m, the
    corners found with 0.3 px of noise and 0.3 px more each marker shares, one marker of each set
    found by its outer square alone, shifted: every pose that left it out within 5 % of the height."""
    import dataclasses

    import hvloc.phases as phm

    nested = make_pad({"variant": "nested"}, ppm=2000)
    cam = Camera.from_hfov(640, 480, math.radians(60))
    real, on = phm.detect_markers, [False]
    rng = np.random.default_rng(1)

    def found_in_part(*a, **kw):
        det, why = real(*a, **kw)
        if det is None or not on[0]:
            return det, why
        P, px = det.pts_P, det.px + rng.normal(0.0, 0.3, det.px.shape)
        whole = {i: np.all(np.abs(P[:, :2] - m.center[:2]) <= m.size_m / 2 + 1e-9, axis=1)
                 for i, m in enumerate(a[1].markers)}
        whole = {i: w for i, w in whole.items() if w.sum() >= 8}
        if len(whole) < 3:
            return det, why
        for w in whole.values():
            px[w] += rng.normal(0.0, 0.3, 2)
        i = sorted(whole)[1]
        d = np.abs(P[:, :2] - a[1].markers[i].center[:2])
        outer = whole[i] & (np.abs(d - d[whole[i]].max()) < 1e-9).all(axis=1)  # its outer square's corners
        px[outer] += [4.0, 0.0]
        keep = ~whole[i] | outer
        return dataclasses.replace(det, pts_P=P[keep], px=px[keep]), why

    monkeypatch.setattr(phm, "detect_markers", found_in_part)
    loc = HierarchicalLocalizer(nested, cam, LocalizerConfig())
    left_out = []
    for k in range(40):
        h = 2.0 - 0.04 * k
        G = tilted(0.03, -0.02, h, 0.4 + 0.01 * k, 0.03, -0.02)
        on[0] = k >= 10
        ahrs = so3_exp([math.radians(0.3), math.radians(-0.3), 0.0])  # an AHRS a little off
        e = loc.process(warp_pad_view(nested, cam, G, GROUND), 0.1 * k, _imu_from(G, extra=ahrs))
        if e.ok and e.extras.get("marker_dropped"):
            left_out.append(pose_error(e.cam2pad, G)[0] / h)
    assert len(left_out) >= 20 and max(left_out) < 0.05, (len(left_out), max(left_out, default=None))


def test_nested_variant_gives_both_marker_sets(pad):
    from pad_design import make_pad

    nested = make_pad({"variant": "nested"}, ppm=2000)
    G = tilted(0.05, -0.02, 1.6, 0.8, 0.02, 0.01)
    img = warp_pad_view(nested, CAM, G, GROUND)
    det, why = detect_markers(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), nested.geometry, CAM)
    assert det is not None, why
    assert set(det.info["sets"]) == {"corner", "centre"} and len(det.pts_P) == 72
    assert np.abs(det.px - CAM.project_from(G, det.pts_P)).max() < 0.5
    # low over the centre, only the small set is in view, and it alone gives the pose
    G = tilted(0.0, 0.0, 0.25, 0.3)
    img = warp_pad_view(nested, CAM, G, GROUND)
    det, why = detect_markers(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), nested.geometry, CAM)
    assert det is not None and det.info["sets"] == ["centre"], why
    res = solve_planar_pose(CAM, det.pts_P, det.px, up_C=up_in_camera(G))
    assert pose_error(res.cam2pad, G)[0] < 0.002


def test_a_stale_height_does_not_lock_out_the_only_method(pad):
    """markers only: one far detection must not keep markers from being tried later."""
    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(use_outline=False, use_flow=False, adjust_height_m=5.0))
    far = tilted(0.0, 0.0, 9.0, 0.2)
    loc.last = type("E", (), {"height": 9.0, "t": 0.0, "cam2pad": far, "method": "markers"})()
    G = tilted(0.0, 0.0, 2.5, 0.2)
    e = loc.process(warp_pad_view(pad, CAM, G, GROUND), 0.1, _imu_from(G))
    assert e.status == "lost"  # a fresh 9 m prior: markers are not tried
    e = loc.process(warp_pad_view(pad, CAM, G, GROUND), 3.0, _imu_from(G))
    assert e.status == "ok" and e.method == "markers", e.reason  # the prior went stale


def test_flow_only_ablation_anchors_once_then_tracks_at_any_height(pad):
    """``anchor_once``: a pad detector gives the first pose; every later one is the flow tracker's,
    here at 3 m (far above the touchdown height, where the full localizer uses markers).  Chained
    from one anchor, the tracks drift: on views summed in light up to 20.7 mm (0.46 degrees) by
    the ninth frame, on views mixed in display values 11.5 mm (each tracked Harris corner moves
    on the texture as the scale changes)."""
    views = _views(pad, 12)
    flow_only = HierarchicalLocalizer(pad, CAM, LocalizerConfig(anchor_once=True))
    full = HierarchicalLocalizer(pad, CAM, LocalizerConfig())
    for k, (img, G) in enumerate(views):
        e = flow_only.process(img, 0.05 * k, _imu_from(G))
        f = full.process(img, 0.05 * k, _imu_from(G))
        assert e.status == "ok" and f.status == "ok", (e.reason, f.reason)
        assert f.method in ("outline", "markers")
        assert e.method == (f.method if k == 0 else "flow"), (k, e.method)
        dp, da = pose_error(e.cam2pad, G)
        assert dp < 0.03 and da < 0.7, f"frame {k}: {dp * 1000:.1f} mm, {da:.2f} deg"


def _image_motion(G, P, v, w, e):
    """(N, 2) how far each of ``P`` moves in the image over an exposure ``e`` centred on the view at
    ``G``, the camera moving at ``v`` (pad frame) and turning at ``w`` (camera frame)."""
    ends = []
    for s in (-e / 2, e / 2):
        T = G.copy()
        T[:3, 3] += v * s
        T[:3, :3] = T[:3, :3] @ so3_exp(w * s)
        ends.append(CAM.project_from(T, P))
    return ends[1] - ends[0]


def test_an_edge_fitted_outline_is_not_taken_where_the_motion_smears_past_the_fits_reach(pad):
    """The smear an outline's path is chosen by is read on the white field's edge, as one kernel
    for each pair of sides; a turn smears each corner its own way, and a pad filling the view read
    5.7-9.2 px where 20-40 px lay across its sides (unseen55's gusty turns, a 40 ms exposure): the
    edge fit put its sides 7-21 px out, posed 98 mm off, "ok".  Where the last poses' velocity and
    the gyro's rate predict more smear across a side than an edge fit holds to, and over twice what
    was read, such an outline is refused; the predicted smear is each side's own (checked against
    the same motion applied to the corners), and nothing is refused under a slow motion, with no
    exposure known, or for an outline placed otherwise."""
    import hvloc.localizer as L
    from hvloc.phases import EDGE_FIT_SMEAR_PX

    G = tilted(0.1, -0.05, 2.0, 0.3, 0.02, -0.01)
    P = pad.geometry.outer_corners
    pose = solve_planar_pose(CAM, P, CAM.project_from(G, P), up_C=up_in_camera(G), prev_cam2pad=G)

    def across(v, w, e):  # the largest smear across a side, from the corners' own motion over the exposure
        d, q = _image_motion(G, P, v, w, e), CAM.project_from(G, P)
        side = np.roll(q, -1, axis=0) - q
        n = np.stack([-side[:, 1], side[:, 0]], axis=1) / np.linalg.norm(side, axis=1)[:, None]
        return float(np.max(np.maximum(np.abs(np.sum(d * n, 1)), np.abs(np.sum(np.roll(d, -1, axis=0) * n, 1)))))

    v, w_C = np.array([0.4, -0.3, -0.9]), np.array([0.05, -0.05, 1.6])  # a descent turning at 1.6 rad/s
    for exposure, slow in ((0.04, 1.0), (0.04, 0.1), (0.0, 1.0)):
        loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), exposure_s=exposure)
        loc.velocity, loc.rate_B = slow * v, DEFAULT_T_B_C[:3, :3] @ (slow * w_C)
        truth = across(slow * v, slow * w_C, 0.04)
        if exposure > 0 and slow == 1.0:
            assert truth > 1.5 * EDGE_FIT_SMEAR_PX, truth
            why = loc._edge_fit_outrun(pose, P, 6.0)
            assert why and abs(float(why.split("predicts ")[1].split(" px")[0]) - truth) < 0.1 * truth, (why, truth)
            assert loc._edge_fit_outrun(pose, P, truth / 1.5) == ""  # read as much: the image is believed
            assert loc._edge_fit_outrun(pose, P, None) == ""  # (placed otherwise)
            loc.velocity = None  # the gyro's rate alone (the first frame): no motion predicted whole
            assert loc._edge_fit_outrun(pose, P, 6.0) == ""
        else:
            assert loc._edge_fit_outrun(pose, P, 2.0) == "", (exposure, slow, truth)


def _grid_at_0_3m():
    """``(cam2pad, pts_P, solve)``: a 7x7 grid of pad points seen by CAM from 0.3 m, and their pose
    from pixels (with the true gravity)."""
    G = tilted(0.05, -0.04, 0.3, 0.4, 0.02, -0.01)
    g = np.linspace(-0.12, 0.12, 7)
    P = np.array([[x, y, 0.0] for x in g for y in g])
    up = G[:3, :3].T @ np.array([0.0, 0.0, 1.0])

    def solve(px):
        return solve_planar_pose(CAM, P, px, up_C=up, prev_cam2pad=G)

    return G, P, solve


def test_tracks_shifted_along_their_smear_stay_within_the_poses_covariance(pad):
    """Lucas-Kanade's tracks in a smeared frame shift together along their smear (features alike
    land alike in a smeared patch); the pose takes that shared shift whole, and its covariance,
    from the tracks' scatter, did not say so (unseen49's texture at 0.25 m: 1.1 mm off, 0.2-0.3 mm
    stated; a deck's flow at 0.15-0.2 m under 30-37 px: 1.4-2.2 mm, 1.1-1.3 stated).  Now the
    pose's covariance holds what a shift of a tenth of each track's own smear (the last poses'
    velocity and the gyro's rate over the exposure) moves it by; a frame smeared under 4 px, or
    one with no exposure known, is as it was.  The flow's tracks are doubted for how much more
    they are smeared than in their keyframe: one smeared alike (a steady descent) is not doubted."""
    import hvloc.localizer as L
    from hvloc.phases import Keyframe
    from hvloc.shutter import Twist

    G, P, solve = _grid_at_0_3m()

    def smear(v, w, e):  # each point's image motion over the exposure
        return _image_motion(G, P, v, w, e)

    v, w_C = np.array([0.3, -0.5, -0.3]), np.array([0.2, -0.1, 0.3])
    for exposure, slow in ((0.03, 1.0), (0.03, 0.05), (0.0, 1.0)):
        loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), exposure_s=exposure)
        loc.velocity, loc.rate_B = slow * v, DEFAULT_T_B_C[:3, :3] @ (slow * w_C)
        d = smear(slow * v, slow * w_C, 0.03)
        rng = np.random.default_rng(1)
        px = CAM.project_from(G, P) + L.TRACK_SMEAR_DOUBT * d + rng.normal(0.0, 0.05, (len(P), 2))
        pose = solve(px)
        err = pose.cam2pad[:3, 3] - G[:3, 3]
        spread = loc._smear_spread(pose, P, px, solve)
        nees = (float(err @ np.linalg.solve(pose.cov[:3, :3], err)), float(err @ np.linalg.solve(spread.cov[:3, :3], err)))
        if exposure > 0 and np.linalg.norm(d, axis=1).max() >= L.TRACK_SMEAR_MIN_PX:
            assert np.linalg.norm(d, axis=1).max() > 20 and nees[0] > 50 and nees[1] < 3.0, (nees, np.abs(d).max())
            # a keyframe exposed under the same motion from nearly the same place: nothing to doubt;
            # one exposed still: the whole smear, as from a sharp drawing
            kf = Keyframe(None, tilted(0.052, -0.041, 0.302, 0.4, 0.02, -0.01), None, P, True,
                          motion=Twist(slow * v, slow * w_C))
            assert np.array_equal(loc._smear_spread(pose, P, px, solve, kf).cov, pose.cov)
            kf.motion = Twist(np.zeros(3), np.zeros(3))
            assert np.allclose(loc._smear_spread(pose, P, px, solve, kf).cov, spread.cov, rtol=1e-3, atol=0)
        else:
            assert np.array_equal(spread.cov, pose.cov), (exposure, slow)


def test_a_smear_from_a_velocity_known_loosely_is_doubted_as_loosely(pad):
    """After a gap the velocity filter's velocity is the IMU's rows' integral, known to a few
    tenths of a metre per second; the smear doubt counted only the smear that velocity makes, as
    if it were exact (unseen88: a texture pose at 0.18 m 0.53 mm off stated 0.15, the flow chained
    from it NEES 8-21).  Now one sigma of the filter's velocity along each of its principal axes is
    counted too: tracks shifted by a tenth of the smear of a velocity two of those sigmas off the
    filter's stay within the pose's covariance, and a velocity the filter is sure of adds nearly
    nothing."""
    import hvloc.localizer as L

    G, P, solve = _grid_at_0_3m()

    v_filter, e = np.array([0.05, 0.0, -0.05]), 0.03
    v_true = v_filter + np.array([0.35, -0.35, 0.0])  # 2 sigma at 0.25 m/s per axis
    d = _image_motion(G, P, v_true, np.zeros(3), e)
    rng = np.random.default_rng(2)
    px = CAM.project_from(G, P) + L.TRACK_SMEAR_DOUBT * d + rng.normal(0.0, 0.05, (len(P), 2))
    pose = solve(px)
    err = pose.cam2pad[:3, 3] - G[:3, 3]
    assert np.linalg.norm(d, axis=1).max() > 20 and np.linalg.norm(err) > 0.001, (np.abs(d).max(), err)
    nees = {}
    for sigma in (None, 0.01, 0.25):
        loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), exposure_s=e)
        x = np.zeros(9)
        x[3:6] = v_filter
        Pv = np.zeros((9, 9))
        Pv[3:6, 3:6] = (sigma or 0.0) ** 2 * np.eye(3)
        loc.vfilter.pred, loc.vfilter.n, loc.last_t = (0.0, x, Pv), 2, 0.0  # a filter with two poses in
        if sigma is None:
            loc.vfilter.velocity_doubt = lambda t: None  # (the velocity taken as exact, as before)
        cov = loc._smear_spread(pose, P, px, solve).cov[:3, :3]
        nees[sigma] = float(err @ np.linalg.solve(cov, err))
        if sigma == 0.01:
            exact = nees[None]
            assert abs(nees[sigma] - exact) < 0.1 * exact, nees
    assert nees[None] > 14.16 and nees[0.25] < 9.0, nees  # (14.16: 3 sigma in three dimensions)


def test_whether_the_texture_is_drawn_smeared_is_judged_over_the_view_not_at_the_matches(pad):
    """A turn about the optical axis smears the view's edges and not its centre.  Matches that
    happen to lie near the centre (unseen92's 55 at 1.8 m, under 4 px in the median where the
    frame's centre was smeared 6.9 px) left the texture refined against its sharp drawing, 5.1 mm
    off where the smeared one put it 1.7 mm off.  The smear is read over the pad's part in view (a
    grid of the frame's pixels on the pad): drawn smeared wherever that is, and sharp where not."""
    from hvloc.shutter import Twist

    G = tilted(0.02, -0.03, 0.3, 0.4, 0.01, -0.02)
    g = np.linspace(-0.02, 0.02, 5)
    P = np.array([[x, y, 0.0] for x in g for y in g])  # within ~50 px of the frame's centre
    px = CAM.project_from(G, P)
    up = G[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), exposure_s=0.03)
    for w, smeared in ((1.2, True), (0.2, False)):
        turn = Twist(np.zeros(3), np.array([0.0, 0.0, w]))
        at_matches = np.median(np.linalg.norm(_image_motion(G, P, np.zeros(3), turn.w_C, 0.03), axis=1))
        plan = loc._smear_of(turn, up)(P, px)
        assert (plan is not None) == smeared, (w, at_matches)
        if smeared:
            assert at_matches < 4.0, at_matches  # (the matches alone would not have said so)
            assert np.allclose(plan[0], G, atol=1e-6) and plan[1] is turn and plan[2] == 0.03


def test_the_texture_is_drawn_smeared_by_what_the_gyro_surely_says_not_by_its_vibration():
    """A multirotor's gyro reads its vibration in every sample: the rate over a frame can be mostly
    its doubt.  Drawn smeared by the rate as read, the texture's drawing lays its streaks' ends on a
    sharp frame's edges and its tracks move half the miss (fzu11: 0.3-0.4 rad/s read on 0.24-0.27
    of doubt smeared the drawing 5-6.5 px where the pad moved 1.4-2.4 over the exposure, texture poses 1.5-7
    % of the height off, NEES 14-178).  Smeared by the rate less its doubt (here nothing), the sharp
    frame is refined against a sharp drawing and the pose is right; a turn read on little doubt
    keeps all but its doubt."""
    from hvloc.texture import PadTexture

    pad = make_pad(ppm=1000.0)
    tex = PadTexture(pad)
    cam = Camera.from_hfov(1280, 720, math.radians(95), dist=(-0.2, 0.0, 0.0, 0.0, 0.0))  # a cheap wide lens
    rng = np.random.default_rng(1)
    errs = {"read": [], "sure": []}
    for _ in range(3):
        h = rng.uniform(0.6, 1.0)
        G = tilted(rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), h, rng.uniform(0, 2 * np.pi),
                   rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3))
        gray = cv2.cvtColor(_motion_blurred(pad, G, np.zeros(3), GROUND, n=1, cam=cam), cv2.COLOR_RGB2GRAY)  # sharp
        det, why = tex.locate(gray, cam, h)
        assert det is not None, why
        loc = HierarchicalLocalizer(pad, cam, LocalizerConfig(), T_B_C=np.eye(4), exposure_s=0.02)
        loc.velocity, loc.unposed = np.zeros(3), 0  # the last two poses: hovering
        loc.rate_B, loc.rate_doubt = rng.choice([-1.0, 1.0], 3) * rng.uniform(0.25, 0.4, 3), np.full(3, 0.25)
        for name, motion in (("read", loc._motion()), ("sure", loc._drawn_motion())):
            plan = loc._smear_of(motion, up_in_camera(G))(det.pts_P, det.px)
            found, why = (det, "") if plan is None else tex.refined_under(gray, cam, *plan)
            assert found is not None, why
            pose = solve_planar_pose(cam, found.pts_P, found.px, up_C=up_in_camera(G))
            errs[name].append(pose_error(pose.cam2pad, G)[0] / h)
    assert max(errs["sure"]) < 0.001, errs  # within 0.1 % of the height
    assert max(errs["read"]) > 3 * max(errs["sure"]), errs  # (the scene is one the rate as read misdraws)
    loc.rate_B, loc.rate_doubt = np.array([1.0, -0.5, 0.0]), np.full(3, 0.05)  # a real turn
    assert np.allclose(loc._drawn_motion().w_C, [0.95, -0.45, 0.0])


def test_tracks_whose_tilt_gravity_contradicts_widen_their_noise_until_it_does_not():
    """Tracks between frames smeared differently (a turn, a fast descent) are off together, as a
    tilted plane's homography would move them: they fit it to a fraction of a pixel and fix the
    tilt "to 0.1 degrees" where it is 2 degrees off (unseen55 at 1 m: 30 mm sideways, 3.4 mm
    stated, NEES 88).  The IMU's gravity says so: where the tracks' tilt disagrees with it beyond
    both's noise, their noise is widened until it does not, and the pose follows the gravity as
    far as the two then weigh.  Tracks that agree with gravity are left as they were: in at most
    a fifth of consistent draws is anything widened (a chi-square of 2 degrees of freedom exceeds
    4 in 13.5 %); there the pose moves toward an IMU that was off by two of its sigmas or more,
    and says so."""
    from types import SimpleNamespace

    from hvloc.phases import pose_from_tracks

    rng = np.random.default_rng(3)
    P = np.column_stack([rng.uniform(-0.45, 0.45, (140, 2)), np.zeros(140)])
    kf = SimpleNamespace(pts_P=P)

    def nees(res, G):
        d = res.cam2pad[:3, 3] - G[:3, 3]
        return float(d @ np.linalg.solve(res.cov[:3, :3], d))

    # the tracks as a camera tilted 2 degrees about its x axis (about the ground under it) sees them
    widened = 0
    for k, yaw in enumerate(np.linspace(0.0, 2 * np.pi, 8, endpoint=False)):
        G = tilted(0.1, -0.05, 1.0, yaw, 0.01, -0.02)
        c = np.array([G[0, 3] - G[2, 3] * G[0, 2] / G[2, 2], G[1, 3] - G[2, 3] * G[1, 2] / G[2, 2], 0.0])
        Rx = so3_exp(G[:3, :3] @ np.array([math.radians(2.0), 0.0, 0.0]))  # about C's x, in P
        B = G.copy()
        B[:3, :3], B[:3, 3] = Rx @ G[:3, :3], c + Rx @ (G[:3, 3] - c)
        px = CAM.project_from(B, P) + rng.normal(0.0, 0.3, (len(P), 2))
        up = up_in_camera(G)
        res = pose_from_tracks(CAM, kf, px, G, up)[0]
        old = solve_planar_pose(CAM, P, px, up_C=up, prev_cam2pad=G)  # as the tracks were posed before
        assert res.tilt_err_deg > 1.7 and res.tilt_sigma_deg < 0.1  # the premise: sure and wrong
        assert nees(old, G) > 50 and pose_error(old.cam2pad, G)[0] > 0.025, (yaw, nees(old, G))
        assert res.tilt_noise_scale > 3 and nees(res, G) < 11.3, (yaw, nees(res, G), res.tilt_noise_scale)
        assert pose_error(res.cam2pad, G)[0] < 0.5 * pose_error(old.cam2pad, G)[0]
        # the same tracks where they are right, the IMU's up off by its own noise (0.5 degrees)
        for j in range(25):
            tip = rng.normal(0.0, math.radians(0.5), 2)
            up_n = so3_exp([tip[0], tip[1], 0.0]) @ up
            px = CAM.project_from(G, P) + rng.normal(0.0, 0.3, (len(P), 2))
            res, inl, _ = pose_from_tracks(CAM, kf, px, G, up_n)
            old = solve_planar_pose(CAM, P[inl], px[inl], up_C=up_n, prev_cam2pad=G)  # (its tracks: within 3 sigma)
            if res.tilt_noise_scale > 1.0:
                widened += 1
                assert nees(res, G) < 11.3, (yaw, j, nees(res, G), nees(old, G))
            else:
                assert np.array_equal(res.cam2pad, old.cam2pad) and np.array_equal(res.cov, old.cov)
    assert widened <= 0.2 * 8 * 25, widened


def test_noisy_tracks_are_posed_by_all_that_agree_not_by_a_chance_subset():
    """Tracks into a frame smeared otherwise than their keyframe scatter about their homography by
    more than RANSAC's 2 px (unseen85 at 0.25 m: 2.4 px).  RANSAC then keeps a chance subset, and
    the pose is wherever that subset agrees: two runs whose tracks differed by 0.1 px at most kept
    44 and 45 of 111 tracks and were posed 0.5 and 5.9 mm off, stating 1.5.  Taken within three
    of their own noise, every track that agrees is kept and the pose is as sure as it says; the
    tracks a checker cell off (40 px) stay out."""
    from types import SimpleNamespace

    from hvloc.phases import pose_from_tracks

    rng = np.random.default_rng(7)
    errors, nees, jumps = [], [], []
    for _ in range(40):
        G = tilted(*rng.uniform(-0.02, 0.02, 2), 0.25, rng.uniform(0.0, 2 * np.pi), *rng.normal(0.0, 0.03, 2))
        P = np.column_stack([rng.uniform(-0.12, 0.12, (110, 2)) + G[:2, 3], np.zeros(110)])
        px = CAM.project_from(G, P) + rng.normal(0.0, 2.0, (110, 2))
        slipped = rng.random(110) < 0.15
        px[slipped, 0] += 40.0
        kf, up = SimpleNamespace(pts_P=P), up_in_camera(G)
        res, inliers, _ = pose_from_tracks(CAM, kf, px, G, up)
        assert not (inliers & slipped).any() and inliers.sum() > 0.6 * len(P)
        d = res.cam2pad[:3, 3] - G[:3, 3]
        errors.append(float(np.linalg.norm(d)))
        nees.append(float(d @ np.linalg.solve(res.cov[:3, :3], d)))
        again = pose_from_tracks(CAM, kf, px + rng.uniform(-0.1, 0.1, px.shape), G, up)[0]
        sigma = math.sqrt(np.linalg.eigvalsh(res.cov[:3, :3])[-1])
        jumps.append(float(np.linalg.norm(again.cam2pad[:3, 3] - res.cam2pad[:3, 3])) / sigma)
    # RANSAC's subset alone: RMSE 2.8 mm, NEES beyond 11.3 (3 dof, 1 %) in 32 of 40, and 0.1 px moved
    # the pose 0.4 sigma in the median, up to 5.8 (here: a track or two at the threshold, 1 sigma at most)
    assert math.sqrt(np.mean(np.square(errors))) < 0.0015, errors
    assert sum(n > 11.34 for n in nees) <= 4, nees
    assert np.median(jumps) < 0.1 and max(jumps) < 1.5, jumps


def test_tracks_are_judged_against_an_ahrs_as_far_off_as_their_keyframe_saw_it(pad):
    """The tracks' tilt test blames the tracks for disagreeing with the IMU's gravity beyond the
    AHRS's stated error.  But an AHRS is sometimes further off than it states, and where the pose
    that anchored the keyframe fixed the tilt from its image (markers below a metre: to hundredths
    of a degree), it saw by how much.  Tracks judged against an AHRS 1.2 degrees off where it states
    0.5 were widened and the pose went with the AHRS (unseen48: 0.7 degrees, the height 1.4 % high
    down to touchdown); judged against the AHRS as far off as the keyframe saw it, they are right,
    and the pose is theirs.  Keyframes renewed from the tracks' poses keep what their anchor saw."""
    from types import SimpleNamespace

    from hvloc.localizer import ahrs_off_deg

    cam = Camera.from_hfov(480, 480, math.radians(60))
    poses = [tilted(0.05 + 0.004 * k, -0.03, 0.65 * 0.92 ** k, 0.4 + 0.02 * k, 0.12, -0.3) for k in range(4)]
    imgs = [cv2.cvtColor(warp_pad_view(pad, cam, G, GROUND), cv2.COLOR_RGB2GRAY) for G in poses]
    tip = so3_exp([math.radians(1.0), math.radians(-0.66), 0.0])  # the AHRS's gravity 1.2 degrees off

    def tilt_deg(T, G):
        return math.degrees(math.acos(min(1.0, float(up_in_camera(T) @ up_in_camera(G)))))

    def fly(off):
        flow = FlowTracker(cam, region_P=pad.geometry.outer_corners)
        assert flow.anchor(imgs[0], poses[0], ahrs_off_deg=off)
        out = []
        for k in range(1, len(poses)):
            res, n, why = flow.track(imgs[k], poses[k - 1], tip @ up_in_camera(poses[k]))
            assert res is not None, (off, k, why)
            G = poses[k]
            out.append((tilt_deg(res.cam2pad, G), 100 * (res.cam2pad[2, 3] - G[2, 3]) / G[2, 3], res.tilt_noise_scale))
            flow.accept(res.cam2pad, res.rms_px, res.cov)
        return flow, out

    flow, blind = fly(0.0)
    assert flow.gravity_sigma == 0.5
    assert blind[0][2] > 3 and blind[0][0] > 0.3, blind  # the premise: right tracks widened, the pose the AHRS's
    flow, seen = fly(1.0)
    assert flow.gravity_sigma == pytest.approx(math.hypot(0.5, 1.0))
    assert flow.keyframes >= 2 and flow.kf.ahrs_off_deg == 1.0  # renewed from the tracks' poses, it kept it
    for tilt, dz, k in seen:
        # (the tracks' own error: 0.05-0.17 degrees on these views summed in light, 0.01-0.05 on views
        # mixed in display values; widened: 0.35-0.40 degrees, 0.09-0.12 % low)
        assert k == 1.0 and tilt < 0.25 and abs(dz) < 0.05, seen
    # the least the anchoring pose's image says the AHRS is off: its disagreement less two sigmas
    est = SimpleNamespace(extras={"tilt_err_deg": 1.0, "tilt_sigma_deg": 0.05})
    assert ahrs_off_deg(est) == pytest.approx(0.9)
    for extras in ({"tilt_err_deg": 1.0, "tilt_sigma_deg": 0.6}, {"tilt_err_deg": float("nan"), "tilt_sigma_deg": 0.1}, {}):
        assert ahrs_off_deg(SimpleNamespace(extras=extras)) == 0.0


def test_the_flow_keeps_its_keyframe_over_a_pose_less_sure_than_it(pad):
    """A markers pose renews the flow's keyframe (its chain may have drifted) only when it is at
    least as sure as the keyframe: a marginal markers fit under blur (bench_v2's
    x_field_rs_oblique at 0.5 m: 2.6 px RMS, 6.6 mm off, 3 mm stated) became the keyframe of a
    chain that was within 0.3 mm (2.5 mm stated), and every later touchdown pose carried its 4-6 mm."""
    from hvloc.localizer import Estimate

    img, G = _views(pad, 1)[0]
    gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig())
    h = float(G[2, 3])
    loc.config = loc.config.model_copy(update={"touchdown_height_m": h})  # the flow runs at this height

    def est(sd_m, method="markers"):
        cov = np.eye(6) * 1e-6
        cov[:3, :3] = np.eye(3) * sd_m ** 2
        return Estimate(0.0, "touchdown", "ok", G.copy(), 30, 0.2, cov, method=method)

    loc._after_accept("markers", est(0.002), gray)  # no keyframe yet: this one
    first = loc.flow.kf
    assert first is not None and np.isclose(first.cov[0, 0], 0.002 ** 2)
    first.anchored = False  # a chained keyframe: the tracker's own, which an anchored pose renews
    loc._after_accept("markers", est(0.003), gray)
    assert loc.flow.kf is first  # less sure: kept
    loc._after_accept("markers", est(0.001), gray)
    assert loc.flow.kf is not first and loc.flow.kf.anchored and loc.flow.kf.serial == first.serial + 1


def test_a_keyframe_out_of_the_flows_reach_is_renewed_by_a_less_sure_pose(pad):
    """The keyframe is kept over a less sure pose only while the tracker can still use it: once the
    camera has come down (or turned) out of its reach, LK against it degrades, and a markers pose
    renews it however sure.  Without gravity a markers pose states 4-8 mm at 1 m; a keyframe made
    at 1.16 m (2.7 mm stated) was kept down to 0.9 m, where the flow from it was 11.5 mm off against
    the markers' 0.1 (bench_v1's no_imu ablation, sim800)."""
    from hvloc.localizer import Estimate

    img, G = _views(pad, 1)[0]
    gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig())
    loc.config = loc.config.model_copy(update={"touchdown_height_m": float(G[2, 3])})  # the flow runs here

    def est(sd_m, cam2pad):
        cov = np.eye(6) * 1e-6
        cov[:3, :3] = np.eye(3) * sd_m ** 2
        return Estimate(0.0, "touchdown", "ok", cam2pad.copy(), 30, 0.2, cov, method="markers")

    loc._after_accept("markers", est(0.002, G), gray)
    first = loc.flow.kf
    first.anchored = False  # a chained keyframe: an anchored pose renews it when it is surer
    near, low, turned = G.copy(), G.copy(), G.copy()
    near[:3, 3] *= 0.95
    low[:3, 3] /= 1.3
    turned[:3, :3] = turned[:3, :3] @ so3_exp([0.0, 0.0, math.radians(12.0)])
    assert loc.flow.reaches(near) and not loc.flow.reaches(low) and not loc.flow.reaches(turned)
    loc._after_accept("markers", est(0.003, near), gray)
    assert loc.flow.kf is first  # within reach and less sure: kept
    loc._after_accept("markers", est(0.003, low), gray)
    assert loc.flow.kf is not first and loc.flow.kf.anchored and np.isclose(loc.flow.kf.cam2pad[2, 3], low[2, 3])
    second = loc.flow.kf
    second.anchored = False
    loc._after_accept("markers", est(0.004, low @ np.linalg.inv(G) @ turned), gray)
    assert loc.flow.kf is not second


def test_the_flow_follows_a_gusty_turn_over_the_pads_checker_by_the_ahrss_turn(pad):
    """A 10 Hz descent from 1.3 m toward the pad's border, the drone rocking 3 degrees one way and
    the other frame by frame (6 degrees between frames, 70 px at this lens): from a frame's
    features where they were, Lucas-Kanade's pyramid does not reach the next frame's on the
    checker, and every frame below the markers' reach was lost (6, then 0 tracks left; on
    unseen61's 1080p frames the tracks slipped a cell together instead and 28 poses 65-88 mm off
    were accepted).  The features are guessed where the turn since the last pose puts them
    (``HierarchicalLocalizer._predicted``; here a bare attitude, the AHRS's, says it); the texture
    is off, so only the flow can pose them."""
    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(use_texture=False))
    flows = []
    for k in range(16):
        s = (-1) ** k * math.radians(3.0)
        G = tilted(0.36 * min(1.0, k / 8), 0.1 * min(1.0, k / 8), 1.3 - 0.06 * k, 0.3 + 0.3 * s, s, 0.6 * s)
        e = loc.process(warp_pad_view(pad, CAM, G, GROUND), 0.1 * k, _imu_from(G))
        if k >= 8:  # the markers are out of view from here on: 1 finder, then none
            assert e.status == "ok" and e.method == "flow", f"frame {k}: {e.status} {e.reason}"
            d = e.cam2pad[:3, 3] - G[:3, 3]
            assert np.linalg.norm(d) < 0.015 * G[2, 3], f"frame {k}: {np.linalg.norm(d) * 1000:.1f} mm off"
            assert d @ np.linalg.solve(e.cov[:3, :3], d) < 14.16, f"frame {k}: beyond 3 sigma"
            # the velocity filter is told the keyframe's doubt apart, under a global shutter too
            key, S = e.extras["still_shared"][:2]
            assert key == loc.flow.kf.serial or loc.flow.kf.parent == key
            assert np.allclose(e.extras["still_cov"] + S, e.cov[:3, :3])
            flows.append(k)
    assert len(flows) == 8


def test_the_previous_frame_is_warped_to_the_guess_only_where_it_reshapes_patches():
    """The flow's guess (``HierarchicalLocalizer._predicted``) is where LK starts; the previous frame
    is warped to it only where the guess scales the patches past 1.1 or turns them past 5 degrees
    about the features (a gap near the ground): warped every frame, the interpolation softened
    bench_v1's field1080 touchdown 0.15 -> 0.25 mm median.  A frame's shift, a 3 degree turn and
    a 7 % zoom keep LK on the frame as it is."""
    from hvloc.phases import _reshapes_patches

    c = np.array([400.0, 300.0])

    def about(A, t=(0.0, 0.0)):  # the affine A about pixel c, then shifted by t
        H = np.eye(3)
        H[:2, :2] = A
        H[:2, 2] = c - A @ c + np.asarray(t)
        return H

    def turn(deg, s=1.0):
        r = math.radians(deg)
        return s * np.array([[math.cos(r), -math.sin(r)], [math.sin(r), math.cos(r)]])

    assert not _reshapes_patches(about(np.eye(2), (60.0, -45.0)), c)
    assert not _reshapes_patches(about(turn(3.0)), c) and not _reshapes_patches(about(turn(-3.0, 1.07)), c)
    assert _reshapes_patches(about(turn(8.0)), c) and _reshapes_patches(about(turn(-8.0)), c)
    assert _reshapes_patches(about(np.eye(2) * 1.4), c) and _reshapes_patches(about(np.eye(2) / 1.2), c)
    assert _reshapes_patches(about(np.diag([1.0, 1.25])), c)  # a tilt's stretch along one axis
    P = np.eye(3)
    P[2, :2] = [5e-5, 0.0]  # a perspective: about c, x scaled 0.96, y 0.98
    assert not _reshapes_patches(P, c)
    P[2, :2] = [4e-4, 0.0]  # ... x 0.73, y 0.86
    assert _reshapes_patches(P, c) and _reshapes_patches(np.diag([1.0, 1.0, 0.0]), c)  # (w = 0: nothing to start from)


def _shaded(gray, edge_px, dark, angle_deg=30.0, width_px=3.0):
    """``gray`` darkened to ``dark`` beyond a soft straight edge (a shadow's: ``width_px`` wide) at
    ``edge_px`` from the frame's centre along the direction ``angle_deg``."""
    h, w = gray.shape
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    a = math.radians(angle_deg)
    d = (x - w / 2) * math.cos(a) + (y - h / 2) * math.sin(a) - edge_px
    return np.clip(gray * (1.0 - (1.0 - dark) * 0.5 * (1.0 + np.tanh(d / (2.0 * width_px)))), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("lens", ["pinhole", "barrel"])
def test_tracks_are_refined_on_their_keyframe_through_a_zoom_and_a_shadows_edge(pad, monkeypatch, lens):
    """The tracks' refinement against their keyframe is what keeps the flow's error from growing frame
    by frame, and it was what made it: up to the next renewal a keyframe's patches are seen up to 15 %
    larger and turned, and the drone's own shadow crosses the view near the ground (unseen102, the
    smoke deck: poses 4 mm off at 0.5 m stating 1.1-1.3, the tracks 0.4-0.9 px off together).  The
    keyframe warped to the frame by the tracks' homography, through the lens, both divided by their
    local mean: 12 % nearer, turned 2 degrees, half the view in a shadow, the tracks refined within
    hundredths of a pixel of where the features are."""
    import hvloc.phases as ph
    from hvloc.geometry import invert, transform_points

    cam = CAM if lens == "pinhole" else Camera.from_hfov(800, 800, math.radians(90), dist=(-0.25, 0.05, 0.0, 0.0, 0.0))
    G0, Gp, G1 = tilted(0.01, -0.02, 0.45, 0.3, 0.02, -0.01), tilted(0.011, -0.019, 0.41, 0.325, 0.024, -0.006), \
        tilted(0.012, -0.018, 0.40, 0.33, 0.025, -0.005)
    view = lambda G: cv2.cvtColor(warp_pad_view(pad, cam, G, GROUND), cv2.COLOR_RGB2GRAY)
    g0, gp, g1 = view(G0), _shaded(view(Gp), 17.0, 0.45), _shaded(view(G1), 20.0, 0.45)
    kf = ph.make_keyframe(g0, G0, cam, anchored=True)
    at = lambda G: cam.project(transform_points(invert(G), kf.pts_P))
    truth, prev = at(G1), at(Gp)
    # on the plane the tracks' homography gives, as they are tracked in frame-to-frame (hundredths off)
    seen = np.all((truth > 24) & (truth < [cam.width - 24, cam.height - 24]), axis=1)
    seen &= np.all((prev > 24) & (prev < [cam.width - 24, cam.height - 24]), axis=1)

    def errors():
        px = ph.track_to_keyframe(kf, gp, np.where(seen[:, None], prev, np.nan), g1, cam, 1.0)
        return np.linalg.norm(px - truth, axis=1)[seen]

    e = errors()
    ok = np.isfinite(e)
    assert ok.sum() >= 0.8 * seen.sum(), (ok.sum(), seen.sum())
    assert np.median(e[ok]) < 0.08 and np.percentile(e[ok], 90) < 0.2, np.percentile(e[ok], [50, 90, 100])

    def as_it_was(kf, gray, kf_px, p1, good, camera):  # the keyframe as it is, undivided
        p2, st2, _ = cv2.calcOpticalFlowPyrLK(kf.gray, gray, kf_px, p1.copy(), flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
                                              **{**ph.LK_PARAMS, "maxLevel": 1})
        return p2, st2

    monkeypatch.setattr(ph, "refined_on_keyframe", as_it_was)
    e = errors()
    assert np.median(e[np.isfinite(e)]) > 0.15, np.percentile(e[np.isfinite(e)], [50, 90, 100])


@pytest.mark.parametrize("slip", [(1.0, 0.0), (0.0, -1.0), (0.7, 0.7)])
def test_a_marker_square_refined_a_module_off_is_left_out_and_the_others_kept(slip):
    """A finder square whose contour was a module off (a dirt splotch joined to its dark ring) is refined
    onto the next ring's edges: its four corners a module off together, which the set's homography fits
    by tilting the pad (fz537 at 1.4 m: the pose 5 degrees off at RMS 0.45 px).  Held against the
    homography of the other squares it is left out; squares as sharp as refined ones are all kept, on
    a view tilted 25 degrees and at 0.15 px of noise."""
    from hvloc.geometry import invert, transform_points
    from hvloc.phases import _slipped_squares_out

    rng = np.random.default_rng(7)
    G = tilted(0.05, -0.03, 1.4, 0.4, math.radians(25.0), math.radians(-10.0))
    module_m = 0.014
    squares = []
    for c in ((-0.24, -0.24), (0.24, -0.24), (-0.24, 0.24)):  # three markers, three nested squares each
        for half in (3.5, 2.5, 1.5):
            r = half * module_m
            squares.append(np.array([[c[0] - r, c[1] - r, 0.0], [c[0] + r, c[1] - r, 0.0],
                                     [c[0] + r, c[1] + r, 0.0], [c[0] - r, c[1] + r, 0.0]]))
    px = [CAM.project(transform_points(invert(G), P)) + rng.normal(0.0, 0.15, (4, 2)) for P in squares]
    module_px = float(np.mean([np.linalg.norm(q[1] - q[0]) for q in px[::3]])) / 7.0
    assert 4.0 < module_px < 12.0, module_px
    assert all(_slipped_squares_out(squares, px, module_px))
    bad = 4
    slipped = [q.copy() for q in px]
    slipped[bad] += module_px * np.asarray(slip) / np.linalg.norm(slip)
    keep = _slipped_squares_out(squares, slipped, module_px)
    assert not keep[bad] and sum(keep) == len(squares) - 1, keep
    # a square a fifth of a module off stays (a refinement's own error, not a slip)
    slipped[bad] = px[bad] + 0.2 * module_px * np.asarray(slip) / np.linalg.norm(slip)
    assert all(_slipped_squares_out(squares, slipped, module_px))


@pytest.mark.parametrize("scale, shift", [(1.005, (1.0, -0.5)), (1.01, (0.8, -0.5)), (0.994, (-0.5, 1.2))])
def test_tracks_that_slipped_together_are_refined_from_where_the_others_put_them(pad, monkeypatch, scale, shift):
    """Frame-to-frame tracks that slipped together (after an untracked frame, a guess off) are 1-3 px
    off at the view's edge, past the 2 px a refinement on the keyframe may move a track: they were
    kept as they were, and the few left after RANSAC tilted the pose (fz445 at 1.5 m: 5.3 degrees
    stating 1.2, 10.7 % of the height off).  Refined again from where the refined tracks' homography
    puts them, every one lands on its feature."""
    import hvloc.phases as ph
    from hvloc.geometry import invert, transform_points

    G0, G1 = tilted(0.01, -0.02, 0.45, 0.3, 0.02, -0.01), tilted(0.012, -0.018, 0.40, 0.33, 0.025, -0.005)
    view = lambda G: cv2.cvtColor(warp_pad_view(pad, CAM, G, GROUND), cv2.COLOR_RGB2GRAY)
    g0, g1 = view(G0), view(G1)
    kf = ph.make_keyframe(g0, G0, CAM, anchored=True)
    truth = CAM.project(transform_points(invert(G1), kf.pts_P))
    seen = np.all((truth > 24) & (truth < [CAM.width - 24, CAM.height - 24]), axis=1)
    c = truth[seen].mean(axis=0)
    slipped = np.where(seen[:, None], c + scale * (truth - c) + np.asarray(shift), np.nan)
    off = np.linalg.norm(slipped - truth, axis=1)[seen]
    assert np.median(off) > 1.0 and np.mean(off > 2.0) > 0.2, np.percentile(off, [50, 100])

    def errors():  # tracked from the frame itself: the frame-to-frame step keeps them where they slipped to
        px = ph.track_to_keyframe(kf, g1, slipped, g1, CAM, 1.0)
        return np.linalg.norm(px - truth, axis=1)[seen]

    e = errors()
    assert np.isfinite(e).all() and np.median(e) < 0.05 and e.max() < 0.2, np.percentile(e, [50, 90, 100])
    monkeypatch.setattr(ph, "_reseeded_on_keyframe", lambda kf, gray, kf_px, p1, *a: p1)
    e = errors()
    assert np.percentile(e, 90) > 1.0, np.percentile(e, [50, 90, 100])


def test_a_few_tracks_that_slipped_together_are_no_inliers_of_sharp_tracks():
    """Sharp tracks agree with their homography to hundredths of a pixel; RANSAC's 2 px kept the
    few that slipped a pixel, and where they lie together on one side of the view they tilt the pose
    (the smoke deck at 0.55 m: five tracks 0.7-1.2 px off among 126, the pose 2.9 mm off stating 1.3).
    Taken at the tracks' own noise (at least 0.3 px), they are out and the pose is the others'."""
    import hvloc.phases as ph
    from hvloc.geometry import invert, transform_points

    rng = np.random.default_rng(5)
    G = tilted(0.02, -0.01, 0.5, 0.4, 0.01, 0.02)
    P, _ = ph._on_pad_plane(CAM, G, rng.uniform(60, 740, (120, 2)))
    kf = ph.Keyframe(gray=np.zeros((CAM.height, CAM.width), np.uint8), cam2pad=G, px=CAM.project(
        transform_points(invert(G), P)), pts_P=P, anchored=True)
    px = kf.px + rng.normal(0.0, 0.05, kf.px.shape)
    side = np.argsort(px[:, 0])[-8:]  # the eight rightmost, slipped 1.2 px outwards together
    px[side, 0] += 1.2
    res, inl, why = ph.pose_from_tracks(CAM, kf, px, None, up_in_camera(G), gravity_sigma_deg=3.0)
    assert why == "ok" and not inl[side].any() and inl.sum() >= 110, (why, inl[side], inl.sum())
    err = np.linalg.norm(res.cam2pad[:3, 3] - G[:3, 3])
    assert err < 0.15e-3 and err < 2.0 * math.sqrt(np.trace(res.cov[:3, :3])), (err, res.cov)
    # tracks noisier than the floor keep every one of them within three of their own noise
    px = kf.px + rng.normal(0.0, 0.25, kf.px.shape)
    res, inl, why = ph.pose_from_tracks(CAM, kf, px, None, up_in_camera(G), gravity_sigma_deg=3.0)
    assert inl.sum() >= 116, inl.sum()


@pytest.mark.parametrize("shift_mm", [(100.0, -60.0), (-70.0, 110.0)])
def test_a_guess_far_off_sideways_is_found_again_by_the_frames_shift(pad, monkeypatch, shift_mm):
    """Near the ground a guess a few millimetres off sideways is 100-200 px off, past Lucas-Kanade's
    pyramid (a 5 Hz descent with a vibrating accelerometer: the velocity filter's guess 10-25 mm off
    at 0.2 m, 60-180 px, the airframe suite's a_slow_vibrating lost 9 of 33 touchdown frames).  The
    frames' shift after the guess, by phase correlation (``guess_shift``), moves the guess first:
    the tracks land where the camera's move puts them.  Without it they are lost or wrong."""
    import hvloc.phases as ph
    from hvloc.geometry import invert, transform_points

    G0 = tilted(0.02, -0.03, 0.4, 0.3, 0.02, -0.01)
    G1 = G0.copy()
    G1[:3, 3] += G0[:3, :3] @ np.array([shift_mm[0], shift_mm[1], -15.0]) / 1000.0  # 100-170 px sideways
    g0 = cv2.cvtColor(warp_pad_view(pad, CAM, G0, GROUND), cv2.COLOR_RGB2GRAY)
    g1 = cv2.cvtColor(warp_pad_view(pad, CAM, G1, GROUND), cv2.COLOR_RGB2GRAY)
    kf = ph.make_keyframe(g0, G0, CAM, anchored=True)
    truth = CAM.project(transform_points(invert(G1), kf.pts_P))
    guess = CAM.project(transform_points(invert(G0), kf.pts_P))  # the camera guessed not to have moved sideways
    d = ph.guess_shift(g0, g1, np.eye(3))
    moved = np.median(truth - kf.px, axis=0)  # (the 4 % zoom of the descent about it: no one shift)
    assert d is not None and np.linalg.norm(d - moved) < 0.1 * np.linalg.norm(moved), (d, moved)
    assert ph.guess_shift(g0, g0, np.eye(3)) is None  # no shift: the guess left as it was

    seen = np.all((truth > 12) & (truth < [CAM.width - 12, CAM.height - 12]), axis=1)  # still in view

    def tracked():
        px = ph.track_to_keyframe(kf, g0, kf.px, g1, CAM, 1.0, guess)[seen]
        err = np.linalg.norm(px - truth[seen], axis=1)
        return int(np.sum(err < 0.5)), int(np.sum(err >= 0.5))  # right, wrong (NaN: lost, neither)

    right, wrong = tracked()
    assert right >= 0.9 * seen.sum() and wrong <= 0.03 * seen.sum(), (right, wrong, seen.sum())
    monkeypatch.setattr(ph, "SHIFT_MIN_PX", np.inf)
    right, wrong = tracked()
    assert right < 0.5 * seen.sum(), (right, wrong, seen.sum())


def test_flow_only_needs_flow():
    with pytest.raises(ValueError, match="anchor_once"):
        LocalizerConfig(anchor_once=True, use_flow=False)


def _run(loc, views, times, imus=None):
    return [loc.process(img, t, None if imus is None else imus[k]) for k, ((img, G), t) in enumerate(zip(views, times))]


def test_a_second_run_on_the_same_localizer_is_not_locked_out(pad):
    """Time going back (a new sequence, a replay) starts a new run; it does not reject every frame
    as an impossible jump from the last pose of the previous run."""
    views = _views(pad, 6)
    far = [(warp_pad_view(pad, CAM, G, GROUND), G) for G in [tilted(1.5, -1.0, 6.0, 1.0)] * 3]
    loc = HierarchicalLocalizer(pad, CAM)
    first = _run(loc, far, [10.0, 10.1, 10.2])
    assert all(e.ok for e in first), [e.reason for e in first]
    second = _run(loc, views, [0.1 * k for k in range(len(views))])
    assert all(e.ok for e in second), [e.reason for e in second]
    assert "time went back" in second[0].extras.get("clock", "")
    # said in estimates.csv's reason too, ok as the frame is (DESIGN.md); not on the frames after
    assert second[0].reason.startswith("time went back") and "state reset" in second[0].reason
    assert not any("time went back" in e.reason for e in first + second[1:])
    for e, (_, G) in zip(second, views):
        assert pose_error(e.cam2pad, G)[0] < 0.05


@pytest.mark.parametrize("bad_t", [float("inf"), float("nan"), 1e9, -1e9, None, "abc", [1.0, 2.0], True])
def test_one_odd_timestamp_never_locks_out_or_lets_a_stale_pose_through(pad, bad_t):
    views = _views(pad, 8)
    loc = HierarchicalLocalizer(pad, CAM)
    times = [0.1 * k for k in range(8)]
    out = []
    for k, (img, G) in enumerate(views):
        t = bad_t if k == 3 else times[k]
        e = loc.process(img, t)
        out.append(e)
        if k == 3 and not isinstance(bad_t, float):
            assert e.status == "lost" and "timestamp" in e.reason and "internal error" not in e.reason
        elif k == 3 and not math.isfinite(bad_t):
            assert e.status == "lost" and "not finite" in e.reason
    assert all(e.ok for k, e in enumerate(out) if k >= 4), [(k, e.status, e.reason) for k, e in enumerate(out)]


def test_a_stale_prior_is_not_used_by_the_gates(pad):
    """A pose accepted long ago (more than prior_timeout_s) no longer limits the next one, and a
    frame arriving after a gap is not judged against it; within the timeout the motion gate holds."""
    cfg = LocalizerConfig(max_speed_mps=2.0)
    A, B = tilted(0.0, 0.0, 3.0, 0.3), tilted(1.2, 0.6, 3.0, 0.3)
    img_a, img_b = warp_pad_view(pad, CAM, A, GROUND), warp_pad_view(pad, CAM, B, GROUND)
    loc = HierarchicalLocalizer(pad, CAM, cfg)
    assert loc.process(img_a, 0.0).ok
    e = loc.process(img_b, 0.1)  # 1.3 m in 0.1 s: impossible
    assert e.status == "rejected" and "moved" in e.reason
    e = loc.process(img_b, 5.0)  # 5 s later: possible, and the old pose is stale anyway
    assert e.ok, e.reason
    assert "prior dropped" in e.extras.get("clock", "")


@pytest.mark.parametrize("imu", [np.full(4, np.nan), np.zeros(4), np.full((3, 3), np.inf), np.zeros((3, 3)),
                                 np.ones(7), "up", np.array([0, 0, 0, 1e-9])])
def test_an_unusable_imu_sample_means_vision_alone(pad, imu):
    views = _views(pad, 3)
    loc = HierarchicalLocalizer(pad, CAM)
    for k, (img, G) in enumerate(views):
        e = loc.process(img, 0.1 * k, imu)
        assert e.ok, e.reason
        assert "vision alone" in e.extras.get("imu", "")
        assert e.reason.endswith(e.extras["imu"])  # said where estimates.csv shows it
        assert pose_error(e.cam2pad, G)[0] < 0.05


def test_markers_are_found_on_a_pathological_background_and_its_contours_are_bounded(pad):
    """A 1-pixel checkerboard around the pad (hundreds of thousands of contours, minutes of
    findContours at 1080p) is despeckled first: the contour work is bounded and the markers are
    still found at their labelled corners."""
    from hvloc import markers as mk

    G = tilted(0.1, -0.05, 2.5, 0.7)
    img = warp_pad_view(pad, CAM, G, GROUND)
    ground = np.all(img == np.array(GROUND, np.uint8), axis=2)
    checker = (np.indices(ground.shape).sum(0) % 2).astype(bool)
    img[ground & checker] = 255
    img[ground & ~checker] = 0
    gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    b = mk.binarize_dark(gray)
    assert np.count_nonzero(b[:, 1:] != b[:, :-1]) > mk.CLUTTERED_TRANSITIONS * b.size  # it is cluttered
    clean = mk.despeckle(b)
    assert clean is not None
    n_regions = cv2.connectedComponents(clean, connectivity=8)[0] + cv2.connectedComponents(255 - clean, connectivity=4)[0]
    assert n_regions <= mk.MAX_REGIONS
    det, why = detect_markers(gray, pad.geometry, CAM)
    assert det is not None, why
    err = np.linalg.norm(det.px - CAM.project_from(G, det.pts_P), axis=1)
    assert len(det.pts_P) >= 36 and np.median(err) < 0.2, (len(det.pts_P), np.median(err))


def test_the_gravity_prior_wins_over_a_far_pad_whose_corners_are_a_little_off(pad):
    """At 12 m a 1 m pad is ~50 px wide: two corners 2.5 px off (a border edge lost in shadow) tilt
    the image-only pose by >10 degrees at sub-pixel RMS.  The AHRS knows the tilt to a fraction of
    a degree: the refined pose follows it, and the image-only disagreement is reported."""
    G = tilted(0.8, -0.5, 12.0, 0.6, 0.02, -0.01)
    P = pad.geometry.outer_corners
    px = CAM.project_from(G, P) + np.array([[0.0, 0.0], [0.0, 0.0], [2.5, -1.7], [2.1, -1.7]])
    alone = solve_planar_pose(CAM, P, px)
    assert pose_error(alone.cam2pad, G)[1] > 8.0  # the premise: the image alone is far off
    res = solve_planar_pose(CAM, P, px, up_C=up_in_camera(G))
    dp, da = pose_error(res.cam2pad, G)
    assert da < 1.5 and dp < 0.05 * 12.0, (dp, da)
    assert res.tilt_err_deg > 8.0 and res.tilt_sigma_deg < res.tilt_err_deg / 3


def _hard_shadow(img, G, offset_px, k=0.25, sky=(0.85, 0.95, 1.15)):
    """A hard shadow over the part of the image beyond a line through the pad: lit by the sky alone
    (a quarter of the light, half desaturated, bluish), as behind a box in low sun."""
    H, W = img.shape[:2]
    c = CAM.project_from(G, np.zeros((1, 3)))[0]
    yy, xx = np.mgrid[:H, :W]
    side = (xx - c[0]) * 0.6 + (yy - c[1]) * 0.8 > offset_px
    lin = (img.astype(np.float32) / 255.0) ** 2.2
    shade = (0.55 * lin + 0.45 * lin.mean(axis=2, keepdims=True)) * k * np.array(sky, np.float32)
    lin = np.where(side[..., None], shade, lin)
    return np.clip(lin ** (1 / 2.2) * 255 + 0.5, 0, 255).astype(np.uint8)


@pytest.mark.parametrize("h", [4.0, 12.0])
def test_outline_and_cue_are_found_under_a_hard_shadow_edge(pad, h):
    """Before: 21 of 36 such views failed and the rest gave corners ~30 px off (the shadowed border
    and cue fell out of the colour ranges); colour read relative to brightness finds them all."""
    for yaw in (0.3, 1.4, 2.5, 4.0):
        for off in (-20.0, 0.0, 15.0):
            G = tilted(0.3, -0.2, h, yaw)
            img = _hard_shadow(warp_pad_view(pad, CAM, G, GROUND), G, off * 12 / h)
            det, why = detect_outline(img, pad.geometry, CAM)
            assert det is not None, (yaw, off, why)
            err = np.linalg.norm(det.px - CAM.project_from(G, det.pts_P), axis=1).max()
            assert err < 0.6, (yaw, off, err)


@pytest.mark.parametrize("ground", [(120, 95, 60), (90, 70, 45)])
def test_outline_is_never_misnamed_on_ground_of_the_cue_colour(pad, ground):
    """Brown soil lies inside the yellow cue's colour range.  Before: the cue's blob merged with the
    ground and left the mask, the cut corner bent the quad, and the cue was read on soil: every
    view found was named wrong (30 to 77 px).  Now the cut corner is restored from the two sides
    beside it and the cue is read inside the corner square against its neighbours: a view is named
    right or not at all, in sun and at dusk, with and without a shadow edge over the pad."""
    hsv = cv2.cvtColor(np.uint8([[ground]]), cv2.COLOR_RGB2HSV)[0, 0]
    rng = pad.geometry.cue.segmentation_hsv
    assert np.all(hsv >= rng.lo) and np.all(hsv <= rng.hi)  # the premise: the ground reads as cue colour
    found, views = 0, 0
    for h in (8.0, 20.0):
        for yaw in np.linspace(0.2, 2 * np.pi, 5, endpoint=False):
            for shadow, dusk in ((False, 1.0), (True, 0.45)):
                G = tilted(0.3, -0.2, h, yaw, 0.1, 0.15)
                img = warp_pad_view(pad, CAM, G, ground)
                if shadow:
                    img = _hard_shadow(img, G, 0.0)
                img = (img * dusk).astype(np.uint8)
                views += 1
                det, why = detect_outline(img, pad.geometry, CAM)
                if det is None:
                    continue
                found += 1
                err = np.linalg.norm(det.px - CAM.project_from(G, det.pts_P), axis=1).max()
                assert err < 1.0, (h, yaw, shadow, err)
    assert found >= 0.9 * views


def test_an_outline_whose_sides_contradict_its_colour_hull_is_refused(pad):
    """A smear of border colour 5 px past a corner of a 29 px pad (JPEG chroma bleeding onto soil
    does this): the hull's corner is off, the sides' lines disagree with it.  Before, the hull's
    corners were kept and the pose took a 5-6 px corner error (2 m at 19 m on bench_v2's 720p JPEG
    camera, accepted); now such an outline is refused, and no corner is ever that far off."""
    for yaw in np.linspace(0.1, 2 * np.pi, 8, endpoint=False):
        G = tilted(0.3, -0.2, 20.0, yaw, 0.03, 0.02)
        img = warp_pad_view(pad, CAM, G, (120, 95, 60))
        c = CAM.project_from(G, pad.geometry.outer_corners)
        d = (c[1] - c.mean(axis=0)) / np.linalg.norm(c[1] - c.mean(axis=0))
        side = np.array([-d[1], d[0]])
        smear = np.array([c[1] - 3 * d + 3 * side, c[1] + 5 * d, c[1] - 3 * d - 3 * side])
        cv2.fillConvexPoly(img, np.round(smear * 16).astype(np.int32), (230, 50, 200), cv2.LINE_AA, shift=4)
        det, why = detect_outline(img, pad.geometry, CAM)
        if det is not None:
            assert np.linalg.norm(det.px - CAM.project_from(G, det.pts_P), axis=1).max() < 1.0, yaw
        else:
            assert "disagree" in why, why


def test_a_hull_with_a_corner_cut_off_gives_the_whole_quad():
    """A square whose corner is missing from the mask (by 4 to 12 px of a 60 px side) comes back
    whole: the short side is dropped where the two sides beside it meet (to the 2 px a rasterised
    contour allows; the sides' sub-pixel fit comes after)."""
    from hvloc.phases import _contour_quad

    sq = np.array([[100.0, 100.0], [160.0, 104.0], [156.0, 164.0], [96.0, 160.0]])
    for k in range(4):
        for cut in (4.0, 8.0, 12.0):
            a, b, c = sq[k - 1], sq[k], sq[(k + 1) % 4]
            p1 = b + (a - b) / np.linalg.norm(a - b) * cut
            p2 = b + (c - b) / np.linalg.norm(c - b) * cut
            poly = np.concatenate([sq[:k], [p1, p2], sq[k + 1:]]) if k else np.concatenate([[p1, p2], sq[1:]])
            mask = np.zeros((260, 260), np.uint8)
            cv2.fillPoly(mask, [np.round(poly * 4).astype(np.int32)], 255, shift=2)
            contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
            q = _contour_quad(contours[0])
            d = np.linalg.norm(q[:, None, :] - sq[None, :, :], axis=2).min(axis=0)
            assert d.max() < 2.0, (k, cut, d)


def test_markers_are_named_off_nadir_behind_a_wide_lens_with_the_imu_gravity(pad):
    """A camera ~30 degrees off nadir behind a 100 degree barrel lens sees the marker triangle far
    from right-isosceles in pixels; seen head-on (undistorted, turned by the IMU's gravity) it is one
    again, and every view with the markers inside the frame is named and refined."""
    wide = Camera.from_hfov(1280, 720, math.radians(100))
    wide = Camera(wide.width, wide.height, wide.fx, wide.fy, wide.cx, wide.cy, (-0.2, 0.03, 0.0, 0.0, 0.0))
    found, found_plain, views = 0, 0, 0
    corners = np.concatenate([m.outer_corners for m in pad.geometry.markers_in(kind="finder")])
    for pitch in (0.45, 0.55):
        for yaw in (0.2, 1.3, 2.6, 4.0):
            for x in (-0.8, 0.8):
                G = tilted(x, 1.2, 2.2, yaw, 0.0, pitch)
                c = wide.project_from(G, corners)
                if not (np.all(c > 80) and np.all(c < [wide.width - 80, wide.height - 80])):  # the warp's lens holds
                    continue
                views += 1
                gray = cv2.cvtColor(warp_pad_view(pad, wide, G, GROUND), cv2.COLOR_RGB2GRAY)
                det, why = detect_markers(gray, pad.geometry, wide, up_C=up_in_camera(G))
                assert det is not None, (pitch, yaw, x, why)
                assert np.median(np.linalg.norm(det.px - wide.project_from(G, det.pts_P), axis=1)) < 0.3
                found += 1
                found_plain += detect_markers(gray, pad.geometry, wide)[0] is not None
    assert views >= 8 and found == views and found_plain < views  # the premise: pixels alone miss some


@pytest.mark.parametrize("offset_deg,accepted", [(1.5, True), (8.0, False)])
def test_a_pose_whose_tilt_the_imu_contradicts_is_never_accepted_on_a_pad_taken_for_level(pad, offset_deg, accepted):
    """The jump gate compares with a running vision-IMU offset and so cannot see a disagreement
    that is there from the first frame; the tilt gate can where the image fixes the tilt (the
    markers' many corners): the pad is taken for level.  Contradicted so three times, the pad is
    taken for one that tilts (a deck, a slope; or the AHRS is that far off: the reason says so), and
    from the next frame the image's tilt is tracked: a pose is then as right as the image makes it."""
    views = _views(pad, 6)
    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(use_outline=False))
    taken = None
    for k, (img, G) in enumerate(views):
        e = loc.process(img, 0.1 * k, _imu_from(G, extra=so3_exp([math.radians(offset_deg), 0.0, 0.0])))
        if accepted:
            assert e.ok, e.reason
        elif taken is None:
            assert e.status != "ok" and "disagrees with the IMU's gravity" in e.reason, e.reason
            if "taken for a deck" in e.reason:
                taken = k
        else:
            assert e.ok, e.reason
            assert np.linalg.norm(e.cam2pad[:3, 3] - G[:3, 3]) < 0.01 * G[2, 3], (k, e.cam2pad[:3, 3], G[:3, 3])
    assert loc.config.pad_tilt_deg == (0.0 if accepted else pytest.approx(1.5 * offset_deg, abs=0.5))
    assert taken == (None if accepted else 2)


@pytest.mark.parametrize("off_nadir_deg", [30.0, 60.0])
def test_image_only_tilt_sigma_is_calibrated_off_nadir(off_nadir_deg):
    """The tilt gate weighs the image-only tilt by its predicted sigma: for a camera looking at the
    pad obliquely that prediction must match the spread of the tilt under pixel noise."""
    import math

    from hvloc.geometry import Camera, make_transform
    from hvloc.pose import solve_planar_pose, tilt_disagreement
    from pad_design import make_pad

    cam = Camera.from_hfov(640, 480, math.radians(70))
    pts = np.concatenate([m.points for m in make_pad().geometry.markers])
    a = math.radians(off_nadir_deg)
    eye = np.array([0.0, -2.5 * math.sin(a), 2.5 * math.cos(a)])
    z = -eye / np.linalg.norm(eye)
    x = np.array([1.0, 0.0, 0.0])
    R = np.column_stack([x, np.cross(z, x), z])
    px0 = cam.project_from(make_transform(R, eye), pts)
    up = R.T @ np.array([0.0, 0.0, 1.0])
    rng = np.random.default_rng(0)
    tilts, sig = [], []
    for _ in range(200):
        px = px0 + rng.normal(0, 0.3, px0.shape)
        res = solve_planar_pose(cam, pts, px)
        n = res.cam2pad[:3, :3].T @ np.array([0.0, 0.0, 1.0])
        tilts.append(math.degrees(math.acos(np.clip(n @ up, -1, 1))))
        sig.append(tilt_disagreement(cam, res.cam2pad, pts, px, up, 0.3)[1])
    measured = math.sqrt(np.mean(np.square(tilts)) / 2)  # per axis: the tilt angle is 2-D
    assert np.median(sig) == pytest.approx(measured, rel=0.2)


def test_gravity_chooses_between_the_fits_minima_not_ippes_starting_points():
    """A far planar target (36 corners over 0.6 m at 7.5 m, 0.15 px of noise): IPPE's two poses are
    only starting points, a few degrees from the fit's minima, along a long flat valley of the tilt.
    Refined by OpenCV's Levenberg-Marquardt they stopped short (0.2 degrees in the median, up to
    6.6), and gravity chose between where they stopped: in 114 of 300 such views the image-only
    normal taken was further from the IMU's up than the other refined minimum.  Each is now taken
    to its minimum first (checked by our own solver, started where it ended, with the gravity
    prior weighing nothing), and gravity chooses between minima."""
    from hvloc.pose import refine_with_gravity

    rng = np.random.default_rng(7)
    g = np.linspace(-0.3, 0.3, 6)
    pts = np.array([[x, y, 0.0] for x in g for y in g])
    z = np.array([0.0, 0.0, 1.0])

    def angle(a, b):
        return math.degrees(math.acos(np.clip(a @ b, -1.0, 1.0)))

    for _ in range(150):
        G = tilted(rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), 7.5, rng.uniform(0, 6.28))
        px = CAM.project_from(G, pts) + rng.normal(0, 0.15, (len(pts), 2))
        up = up_in_camera(G)
        res = solve_planar_pose(CAM, pts, px, up_C=up)
        assert res.flip_choice == "gravity" and res.other_cam2pad is not None
        other = refine_with_gravity(CAM, res.other_cam2pad, pts, px, up, 0.15, 1e6, iterations=40)
        assert angle(other[:3, :3].T @ z, res.other_cam2pad[:3, :3].T @ z) < 0.1  # it was at its minimum
        assert angle(res.normal_img_C, up) <= angle(other[:3, :3].T @ z, up) + 0.05


@pytest.mark.parametrize("h", [6.0, 12.0])
def test_sides_fitted_beside_the_border_are_told_from_the_border(pad, h):
    """On a pitched 95-degree JPEG camera the outline's sides were fitted to the platform's rim
    beside the pad (the colour mask swelled over it): straight sides, line residuals of 0.1 px, one
    corner 5 to 10 px out, poses 10-15 % of the height off and accepted.  The border's solid band
    must lie just inside every stretch of every side: it does for the true outline, in the sun,
    under a hard shadow edge and through JPEG; it does not when a corner is pushed onto the rim
    (by 15 % of the side: the sides near it 4-5 px out)."""
    from hvloc.phases import _band_missing

    rim = (128, 128, 130)
    for yaw in (0.3, 1.4, 2.5, 4.0):
        G = tilted(0.3, -0.2, h, yaw, 0.05, 0.1)
        clean = warp_pad_view(pad, CAM, G, rim)
        true = CAM.project_from(G, pad.geometry.outer_corners)
        ok, jpg = cv2.imencode(".jpg", cv2.cvtColor(clean, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 50])
        jpeg = cv2.cvtColor(cv2.imdecode(jpg, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        for img in (clean, _hard_shadow(clean, G, 0.0), _hard_shadow(clean, G, 15.0 * 12 / h), jpeg):
            assert not _band_missing(img, true, pad.geometry, CAM), yaw
        side = np.linalg.norm(true[1] - true[0])
        for k in range(4):
            out = true.copy()
            out[k] += (true[k] - true.mean(axis=0)) / np.linalg.norm(true[k] - true.mean(axis=0)) * 0.15 * side
            # (a 50 px pad through JPEG 50 smears the border's chroma over the 7 px: not seen there)
            for img in (clean, jpeg) if h < 10 else (clean,):
                assert _band_missing(img, out, pad.geometry, CAM), (yaw, k)

def _jpeg(img, quality):
    ok, jpg = cv2.imencode(".jpg", cv2.cvtColor(img, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, quality])
    return cv2.cvtColor(cv2.imdecode(jpg, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


@pytest.mark.parametrize("ground", [(128, 128, 130), (120, 95, 60), (70, 110, 50)])
def test_jpeg_outline_is_fitted_on_luma_where_its_colour_edges_smear(pad, ground):
    """JPEG keeps chroma at half resolution: the magenta border's colour edges smear outward and the
    outline's largest corner error was 1.1 to 3.5 px in the median on JPEG 50 views of a 40-80 px
    pad (a grey platform worst).  The white field's edge is sharp in luma: where it says the outline
    is swollen, its corners are used, and the median falls under 0.7 px on every ground.  The field's
    sides start where luma rises most into the white (the swollen outline put them beyond the fit's
    narrow window: 7 px off on a grey platform), so no view is 2 px off.

    Drawn in display values (``in_light=False``), where this was measured.  Open on views summed in
    light: JPEG smears the chroma in display values, and a green ground's outline comes out 0.70-1.01
    px off in the median (grey 0.42-0.46, brown 0.35-0.49); its sides placed in light, 1.15-1.21 px,
    inside the pad, which the field does not mend: it replaces only a swollen outline.  Fitted in
    light and allowed to replace an outline either way, the field placed every ground within
    0.33-0.43 px, but took a hard shadow's edge across the field for its own, 2.8 px off (README,
    "Mixing in light")."""
    for h in (8.0, 12.0, 16.0):
        errs, field = [], 0
        for yaw in np.linspace(0.1, 2 * np.pi, 8, endpoint=False):
            G = tilted(0.3, -0.2, h, yaw, 0.05, 0.1)
            det, why = detect_outline(_jpeg(warp_pad_view(pad, CAM, G, ground, in_light=False), 50), pad.geometry, CAM)
            if det is None:
                continue
            field += det.info.get("corners") == "field"
            errs.append(np.linalg.norm(det.px - CAM.project_from(G, det.pts_P), axis=1).max())
        assert len(errs) >= 5 and field >= len(errs) // 2, (h, len(errs), field)
        assert np.median(errs) < 0.7 and max(errs) < 2.0, (h, np.round(errs, 2))


def test_an_outline_whose_sides_fold_is_never_found(pad, monkeypatch):
    """On unseen47 (21-27 px pads at dusk, JPEG 45 over a 1 px lens blur, 0.5 px of motion) the
    border's centroids read 7 px of smear that was not there and placed one side across the pad:
    a quad with two corners at one pixel came back as found, in 44 of 224 frames an outline more
    than half its side off (its cue then unreadable, or its pose refused with a NaN RMS).  However
    its sides were placed, an outline is a quadrilateral a pad can be, or it is not found; here
    the smear is read as there and the centroids turn one side across the pad (each offset within
    what that smear explains), and the outline is placed as a sharp one instead."""
    import hvloc.phases as ph

    geo = pad.geometry
    real_smear = ph._smear_near

    def misread(*a, **kw):  # 7 px of smear read where the pad is sharp
        lin, lo, smear, pairs = real_smear(*a, **kw)
        return lin, lo, max(smear, 6.9), pairs

    def folding(chan, quad_px, bands, levels, camera=None, segments=2, **kw):  # side 0 turned across the pad
        at = np.tile((np.arange(segments) + 0.5) / segments * 0.5 + 0.25, (4, 1))
        e = np.zeros((4, segments))
        e[0] = np.linspace(4.0, -4.0, segments)
        return e, np.full((4, segments), 6.9), at

    monkeypatch.setattr(ph, "_smear_near", misread)
    monkeypatch.setattr(ph, "band_centroid_offsets", folding)
    G = tilted(0.3, -0.2, 30.0, 0.4, 0.03, -0.02)
    img = _jpeg(warp_pad_view(pad, CAM, G, (112, 116, 124)), 60)
    c = CAM.project_from(G, geo.outer_corners)
    assert ph._deblurred(img, c, geo, CAM, min_blur_px=3.0, profile=False)[0] is None  # the shared placement refuses it
    found_n = 0
    for yaw in (0.4, 1.9, 3.3):
        G = tilted(0.3, -0.2, 30.0, yaw, 0.03, -0.02)  # a 23 px pad
        found, why = find_outline(_jpeg(warp_pad_view(pad, CAM, G, (112, 116, 124)), 60), geo, CAM)
        if found is None:
            continue
        found_n += 1
        assert ph._quad_shaped(found.quad_px), (yaw, found.quad_px.round(1))
        q, P = (found.quad_px, geo.outer_corners) if found.field_px is None else (found.field_px, geo.field_corners)
        err = min(np.linalg.norm(np.roll(q, s, axis=0) - CAM.project_from(G, P), axis=1).max() for s in range(4))
        assert err < 1.5, (yaw, err)
    assert found_n >= 2
    flat = np.array([[10.0, 10.0], [30.0, 10.0], [30.0, 30.0], [10.0, 10.0]])
    assert ph._outline_quad(np.zeros((40, 40, 3), np.uint8), flat, geo, CAM, 20.0, 0.1, None, False) == \
        (None, ph.NO_QUADRILATERAL)
    assert not ph._quad_shaped(np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 3.0], [0.0, 3.0]]))  # a sliver
    assert ph._quad_shaped(np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 9.0], [0.0, 9.0]]))


def _washed_by_glare(img, corners, share):
    """``img`` with white light ``share`` of full added in linear light over the pad whose outer
    corners are ``corners`` (px), fading past it (a glossy pad's specular lobe)."""
    inside = np.zeros(img.shape[:2], np.uint8)
    cv2.fillConvexPoly(inside, np.round(corners).astype(np.int32), 1)
    inside = cv2.GaussianBlur(inside.astype(np.float32), (0, 0), 6.0)  # the lobe fades past the pad
    lin = (img.astype(np.float32) / 255.0) ** 2.2 + share * inside[..., None]
    return (np.clip(lin, 0, 1) ** (1 / 2.2) * 255 + 0.5).astype(np.uint8)


@pytest.mark.parametrize("h", [6.0, 12.0])
def test_outline_is_found_under_glare_that_washes_out_the_border(pad, h):
    """Noon glare on a glossy pad adds white light: the border keeps its hue and its own chroma but
    loses half its saturation (198,51,176 -> 232,138,218 in the realism suite), below the colour
    range, and every frame was "no pad-coloured quadrilateral" (hvloc 36 % available in Approaching
    on the realism suite's real tier).  Read relative to brightness when nothing saturated is found,
    the outline comes back in most views, as exact as in clear light, and is refused in the others
    (never a wrong one).  (On views summed in light the glare that washes the border out is 0.42 of
    full light: at 0.36 the colour range still saw 26-27 % of the border at 12 m.)"""
    found = 0
    for yaw in (0.3, 1.4, 2.5, 4.0):
        G = tilted(0.3, -0.2, h, yaw, 0.05, 0.1)
        c = CAM.project_from(G, pad.geometry.outer_corners)
        img = _washed_by_glare(warp_pad_view(pad, CAM, G, (120, 118, 112)), c, 0.42)
        from hvloc.phases import _hsv_mask

        ring_px = cv2.contourArea(c.astype(np.float32)) * (1 - (pad.geometry.field_side_m / pad.geometry.side_m) ** 2)
        strong = cv2.countNonZero(_hsv_mask(cv2.cvtColor(img, cv2.COLOR_RGB2HSV), pad.geometry.border.segmentation_hsv))
        assert strong < 0.25 * ring_px, (strong, ring_px)  # the colour range sees little of the border
        det, why = detect_outline(img, pad.geometry, CAM)
        if det is None:
            continue
        found += 1
        err = np.linalg.norm(det.px - CAM.project_from(G, det.pts_P), axis=1).max()
        assert err < 0.6, (yaw, err)
    assert found >= 3, found


@pytest.mark.parametrize("off", [3.3, 3.4])
def test_a_pad_washed_by_glare_and_cut_by_the_images_edge_is_found(pad, off):
    """fz216 (a glossy blue pad on snow, a camera 23 degrees off nadir): glare broke the border's
    colour mask into pieces, and the pad ran out of the top of the image.  The washed-out colour is
    read relative to brightness where nothing saturated is found, but that read looked for a whole
    ring only, and a ring whose corner lies out of view is read as cut: "no pad-coloured
    quadrilateral" from 8 m down to 3.6 m (28 frames).  The glare's read now looks for a cut ring
    too, as the plain mask's does.  Views at 6 m with one corner 14 and 22 px out of view (found
    before only with it 5 px out): every corner within 0.6 px."""
    G = tilted(off, 0.0, 6.0, 3.9, 0.05, 0.1)
    c = CAM.project_from(G, pad.geometry.outer_corners)
    out = ((c < -0.5) | (c > CAM.width - 0.5)).any(axis=1)
    assert out.sum() == 1 and 10 < max(-c.min(), c.max() - CAM.width) < 25  # one corner just out of view
    img = _washed_by_glare(warp_pad_view(pad, CAM, G, (120, 118, 112)), c, 0.42)
    det, why = detect_outline(img, pad.geometry, CAM)
    assert det is not None, why
    err = np.linalg.norm(det.px - CAM.project_from(G, det.pts_P), axis=1)
    assert err.max() < 0.6, err


def _glare_spot(img, centre, sigma_px, share):
    """``img`` with a specular highlight: white light, ``share`` of full at its peak, added in linear
    light in a Gaussian spot of ``sigma_px`` around ``centre`` (px)."""
    yy, xx = np.mgrid[:img.shape[0], :img.shape[1]]
    g = share * np.exp(-((xx - centre[0]) ** 2 + (yy - centre[1]) ** 2) / (2.0 * sigma_px ** 2))
    lin = (img.astype(np.float32) / 255.0) ** 2.2 + g[..., None]
    return (np.clip(lin, 0, 1) ** (1 / 2.2) * 255 + 0.5).astype(np.uint8)


@pytest.mark.parametrize("h", [8.0, 12.0])
def test_a_band_washed_out_by_a_highlight_is_read_where_the_field_agrees_with_the_colour(pad, h):
    """fz216: a glossy pad's highlight washed a stretch of its band to the ground's grey, so the
    band check failed for the labelled outline too, and the pad was refused in every view from 11
    m down ("its border band is missing along a side").  The check stands in for a second look at
    where the sides are; the white field's luma edges are one.  Where the field's outer square and
    the colour's quad agree (within 2.5 % of the side), the sides are where both put them.  Views
    of 50-75 px pads on pale ground, a highlight over a stretch of one side: every corner within
    0.6 px.  (A side fitted on a wrong edge lies 3-10 px from the field's: still refused, see
    test_sides_fitted_beside_the_border_are_told_from_the_border and the rim tests.)  Posed by those
    corners: the design, drawn without the highlight, is not fitted to them (fitted, fz216's pads came
    out 2.6-2.9 % of the height off, NEES 28-53)."""
    from hvloc.phases import _band_missing

    for yaw in (0.3, 1.4, 2.5, 4.0):
        G = tilted(0.3, -0.2, h, yaw, 0.05, 0.1)
        c = CAM.project_from(G, pad.geometry.outer_corners)
        side = np.linalg.norm(c[1] - c[0])
        img = _glare_spot(warp_pad_view(pad, CAM, G, (196, 200, 206)), c[1] + 0.3 * (c[2] - c[1]), 0.12 * side, 1.0)
        assert _band_missing(img, c, pad.geometry, CAM), yaw  # the labelled outline fails the band check
        det, why = detect_outline(img, pad.geometry, CAM)
        assert det is not None, (yaw, why)
        err = np.linalg.norm(det.px - CAM.project_from(G, det.pts_P), axis=1)
        assert err.max() < 0.6, (yaw, err)
        # posed by those corners: the design, drawn without the highlight, is not fitted to it
        e = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), T_B_C=np.eye(4)).process(img, 0.0, imu=G[:3, :3])
        assert e.ok and e.method == "outline" and e.extras.get("washed"), (yaw, e.status, e.reason)
        assert not isinstance(e.extras.get("design_fit"), dict), e.extras.get("design_fit")
        d = e.cam2pad[:3, 3] - G[:3, 3]
        assert np.linalg.norm(d) < 0.01 * h and d @ np.linalg.solve(e.cov[:3, :3], d) < 16.3, (yaw, d, e.cov)


def test_refine_quad_told_the_polarity_keeps_a_narrow_bands_outer_edge():
    """A bright band 3 px wide around a dark inside (a far pad's border), the start 1-2 px inside
    one side: each profile across that side holds the whole band, and a crossing taken by the
    profile's own ends may be the band's inner edge (the side tilted, a corner 3.4 px out).  Told
    the inside is brighter than beyond, the fit takes the first crossing from outside."""
    from hvloc.features import refine_quad

    ss = 8
    truth = np.array([[20.3, 15.2], [62.1, 25.7], [51.6, 67.4], [9.8, 56.9]])
    c = truth.mean(axis=0)
    inner = c + (truth - c) * (1 - 3.0 * math.sqrt(2) / np.linalg.norm(truth - c, axis=1))[:, None]
    big = np.zeros((80 * ss, 80 * ss), np.float32)
    for q, v in ((truth, 100.0), (inner, 8.0)):
        cv2.fillConvexPoly(big, np.round(((q + 0.5) * ss - 0.5) * 16).astype(np.int32), v, cv2.LINE_AA, shift=4)
    img = cv2.resize(big, (80, 80), interpolation=cv2.INTER_AREA)
    n = np.array([truth[0, 1] - truth[3, 1], truth[3, 0] - truth[0, 0]])
    n = n / np.linalg.norm(n) * (1 if n @ (c - truth[0]) > 0 else -1)  # side 3 -> 0, inward
    worst = {}
    for off in (1.0, 1.5, 2.0):
        start = truth.copy()
        start[[0, 3]] += off * n
        for pol in (None, True):
            got, _ = refine_quad(img, start, half_width=2.5, inside_brighter=pol)
            worst[pol] = max(worst.get(pol, 0.0), np.inf if got is None else float(np.abs(got - truth).max()))
    assert worst[None] > 1.5  # (the scene is hard: by each profile's ends, a corner goes astray)
    assert worst[True] < 0.3, worst


def test_a_far_outline_under_strong_glare_is_fitted_on_its_outer_edge(pad):
    """Strong glare on a far pad (30-37 px, a border of 3-4 px) washes out its rim, and the colour
    hull comes out a pixel or two inside it.  The sides' profiles then held the whole border,
    half a side's crossings were its inner edge, and the outline was refused ("sides and hull
    disagree", "band missing": 7 of 16 views found).  The sides are fitted knowing the border
    channel is higher on the pad than beyond it."""
    found = 0
    for h in (16.0, 19.0):
        for yaw in np.linspace(0.2, 6.0, 8):
            G = tilted(0.3, -0.2, h, yaw, 0.05, 0.1)
            img = warp_pad_view(pad, CAM, G, (120, 118, 112)).astype(np.float32)
            c = CAM.project_from(G, pad.geometry.outer_corners)
            inside = np.zeros(img.shape[:2], np.uint8)
            cv2.fillConvexPoly(inside, np.round(c).astype(np.int32), 1)
            lin = (img / 255.0) ** 2.2 + 0.6 * cv2.GaussianBlur(inside.astype(np.float32), (0, 0), 6.0)[..., None]
            img = (np.clip(lin, 0, 1) ** (1 / 2.2) * 255 + 0.5).astype(np.uint8)
            got, _ = find_outline(img, pad.geometry, CAM)
            if got is None:
                continue
            found += 1
            err = max(np.linalg.norm(c - q, axis=1).min() for q in got.quad_px)
            assert err < 0.5, (h, yaw, err)
    assert found >= 14, found


def _linear(srgb):
    v = np.asarray(srgb, np.float64) / 255.0
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def _srgb(lin):
    lin = np.clip(lin, 0.0, 1.0)
    return (np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055) * 255 + 0.5).astype(np.uint8)


def _motion_blurred(pad, G, shift_m, ground, n=24, cam=CAM, supersample=2):
    """The view of ``cam`` at ``G`` with the camera moving ``shift_m`` (pad frame) over an exposure
    centred on it: the pad warped, pixels integrated and views averaged in linear light, as light
    mixes on a sensor (a checker of cells under a pixel averages to half its two colours' light)."""
    from types import SimpleNamespace

    lit = SimpleNamespace(texture_rgb=(_linear(pad.texture_rgb) * 4096).astype(np.float32), ppm=pad.ppm,
                          side_m=pad.side_m)
    acc = 0.0
    for s in np.linspace(-0.5, 0.5, n):
        T = G.copy()
        T[:3, 3] += s * np.asarray(shift_m)
        acc = acc + warp_pad_view(lit, cam, T, tuple(_linear(ground) * 4096), supersample=supersample, in_light=False) / 4096.0
    return _srgb(acc / n)


@pytest.mark.parametrize("ground", [(128, 128, 130), (110, 80, 50)])
def test_outline_is_placed_under_motion_blur_wider_than_the_border(pad, ground):
    """A 12 px smear of a 6 px border leaves no edge for the edge fit's +-2.5 px window: on the
    conditions suite's gusty descent every corner came out 4-5 px outside the pad and the pose, 3.8 m
    off at 12 m, was accepted.  Blur symmetric about the frame time moves no light, so the border's
    centroid (in linear light) still says where it is: within 0.5 px (0.2 px here, where light is
    exactly sRGB-encoded)."""
    for yaw, direction in ((0.3, 0.0), (1.2, 0.8), (2.6, 2.0), (4.4, 1.3)):
        G = tilted(0.2, -0.1, 12.0, yaw, 0.03, -0.04)
        shift = 0.2 * np.array([np.cos(direction), np.sin(direction), 0.0])  # 11-12 px at 12 m
        img = _motion_blurred(pad, G, shift, ground)
        ends = [CAM.project_from(make_transform(G[:3, :3], G[:3, 3] + s * shift), pad.geometry.outer_corners)
                for s in (-0.5, 0.5)]
        assert np.linalg.norm(ends[1] - ends[0], axis=1).max() > 10.0  # the smear is as wide as meant
        det, why = detect_outline(img, pad.geometry, CAM)
        assert det is not None, (yaw, why)
        err = np.linalg.norm(det.px - CAM.project_from(G, det.pts_P), axis=1).max()
        assert err < 0.5, (yaw, err)


def test_a_pad_smeared_past_the_edge_fit_is_placed_or_refused(pad):
    """Smear of 30-45 px, 15-45 % of the pad's side, merges the border's two edges into one ramp.
    The smear was read on the steepest rise within 20 px of the field's edge: on such a ramp the
    rise ran on past both ends, the side read nothing, and the other pair's 1.6 px was taken for
    the pad's smear; the border's centroid, read within 16 px, ran out of its window too; and the
    sides were then fitted as sharp edges, 7-20 % of a side out, "ok" (unseen18: the pad read 6 %
    large under 43 px of smear, a false accept).  The smear and the centroid are read again
    reaching twice as far (up to four times), and a pad smeared past the edge fit's 10 px whose
    centroid cannot be read is refused.  Of these 24 views 14 were read more than 5 % of a side out
    and 4 within 2 %; now 1 (a smear both pairs under-read) and 21."""
    geo = pad.geometry
    placed = wrong = 0
    for h in (3.0, 4.0, 6.0):
        for yaw in (0.3, 2.6):
            for direction in (0.0, 0.8):
                for blur in (30.0, 45.0):
                    G = tilted(0.2, -0.1, h, yaw, 0.02, -0.03)
                    shift = blur * h / CAM.fx * np.array([np.cos(direction), np.sin(direction), 0.0])
                    out, why = find_outline(_motion_blurred(pad, G, shift, (110, 90, 60), n=24), geo, CAM)
                    if out is None:
                        continue
                    truth = CAM.project_from(G, geo.outer_corners)
                    q, _ = _in_order_of(out.quad_px, truth)
                    err = np.linalg.norm(q - truth, axis=1).max() / np.linalg.norm(truth[1] - truth[0])
                    placed += err < 0.02
                    wrong += err > 0.05
    assert wrong <= 1 and placed >= 18, (placed, wrong)


def _soft_views_with_a_strip(pad, beside_px: float, lens_px: float):
    """``(image, truth (4, 3) px, camera)`` of six views of a 36 px pad (blur_bias's, seed 5) with a
    strip of the border's colour 3 px wide ``beside_px`` beyond side 1 along it, under a lens blur
    of ``lens_px``."""
    from benchmarks.blur_bias import _views, defocused

    cam = Camera.from_hfov(1280, 720, math.radians(90.0))
    for G in _views(pad, cam, 36.0, 6, seed=5):
        img = warp_pad_view(pad, cam, G, (110, 105, 90))
        t = cam.project_from(G, pad.geometry.outer_corners)
        n = (t[1] + t[2]) / 2 - t.mean(axis=0)
        n /= np.linalg.norm(n)
        strip = np.array([t[1] + beside_px * n, t[2] + beside_px * n, t[2] + (beside_px + 3) * n,
                          t[1] + (beside_px + 3) * n])
        cv2.fillConvexPoly(img, np.round(strip).astype(np.int32), pad.geometry.border.color_rgb)
        yield defocused(img, lens_px), t, cam


def test_a_far_pad_under_a_soft_lens_is_not_fitted_as_sharp(pad):
    """A 36 px pad (a 4 px border) under a 2.5 px lens blur reads 10-12 px of smear; where one of its
    border's centroids cannot be read (something of the border's colour 16 px beside a side runs
    into the profile) nothing placed it, and its edges were fitted as sharp ones (the edge fit
    "holds to 10 px"): one of these six views 12.6 % of the half side out, "ok" (soft_gusty_deck: a
    34 px pad at 15 m read 11.3 % of the height low).  A border smeared over more than twice its
    width is not fitted as sharp: such a pad is refused."""
    geo = pad.geometry
    for img, t, cam in _soft_views_with_a_strip(pad, 16.0, 2.5):
        out, why = find_outline(img, geo, cam)
        if out is not None:
            q, _ = _in_order_of(out.quad_px, t)
            assert np.linalg.norm(q - t, axis=1).max() < 0.03 * np.linalg.norm(t[1] - t[0]), (why, q - t)


def test_the_border_profile_fit_finds_its_edge_and_its_kernel_together():
    """The banded border's blurred profile (a 1.7 px solid band, a checker to 6.85 px: a 56 px pad
    of 0.6 m with a 0.07 m border) under a box of 3-6 px (motion) on a Gaussian of 0.5-1.5 px (a
    lens), the checker's light 0.25-0.5 of the band's, noise-free: the fit finds the edge within
    0.2 px and the kernel's width within 20 %.  Searched one width at a time it stopped where a wrong
    box left the edge: 6 of these 200 profiles 0.3-0.59 px off (a 56 px pad's corner then 1-2.5 px
    out, its side drawn through two stretches 14 px apart).  A kernel wider than the border (9-10
    px) is read as such, which is how the outline knows its place is not told by the border's shape
    (:func:`hvloc.features.banded_profile_offsets`)."""
    from hvloc.features import _box_gauss_step, _fit_banded_profile

    rng = np.random.default_rng(0)
    edges = np.array([0.0, 1.7, 6.85])

    def profile(e, box, sig, ratio):
        r = np.arange(-12.0, 15.0, 1.0) + rng.uniform(0.0, 1.0)
        st = np.stack([_box_gauss_step(r - e - w, box, sig) for w in edges])
        ground, field = rng.uniform(-5.0, 5.0), rng.uniform(-10.0, 0.0)
        return r, ground + 100.0 * (st[0] - st[1]) + 100.0 * ratio * (st[1] - st[2]) + (field - ground) * st[2]

    worst, widths = 0.0, []
    for _ in range(200):
        e, box, sig, ratio = rng.uniform(-1, 1), rng.uniform(3, 6), rng.uniform(0.5, 1.5), rng.uniform(0.25, 0.5)
        found, width, _ = _fit_banded_profile(*profile(e, box, sig, ratio), edges, 1.8, 10.0)
        worst = max(worst, abs(found - e))
        widths.append(width / math.hypot(box, math.sqrt(12.0) * sig))
    assert worst < 0.2, worst
    assert 0.8 < min(widths) and max(widths) < 1.2, (min(widths), max(widths))
    _, wide, _ = _fit_banded_profile(*profile(0.3, 8.5, 1.3, 0.4), edges, 1.8, 16.0)
    assert wide > 1.3 * edges[-1], wide


def _narrow_border_views(seed: int, views: int, smear_px: float, lens_px: float, jpeg: int = 0,
                         in_light: bool = True) -> list:
    """``[(image, truth (4, 2) of the corners found), ...]``: a 0.6 m pad with a 0.07 m border (a
    1.7 px solid band, a checker to 6.85 px) 56 px across, nadir within 3 degrees, through a 50
    degree 1280x960 lens blurred by ``lens_px`` (a Gaussian), smeared ``smear_px`` in a random
    direction, then JPEG ``jpeg`` (4:2:0) when given; the corners found (outer or field) per view.
    ``in_light``: the view summed in light (else mixed in display values, :func:`warp_pad_view`)."""
    from benchmarks.blur_bias import defocused, smeared

    small = make_pad({"side_m": 0.6, "border_m": 0.07, "border_checker_m": 0.01, "marker_size_m": 0.085})
    geo = small.geometry
    cam = Camera.from_hfov(1280, 960, math.radians(50.0))
    rng = np.random.default_rng(seed)
    worst = []
    for _ in range(views):
        h = cam.fx * small.side_m / 56.0
        G = nadir_cam2pad(rng.uniform(-0.1, 0.1) * h, rng.uniform(-0.1, 0.1) * h, h, rng.uniform(0, 2 * math.pi))
        G[:3, :3] = G[:3, :3] @ so3_exp(np.radians(rng.uniform(-3, 3, 3)))
        img = defocused(warp_pad_view(small, cam, G, (110, 105, 90), in_light=in_light), lens_px)
        if smear_px:
            img = smeared(img, smear_px, rng.uniform(0, 180))
        if jpeg:
            img = cv2.imdecode(cv2.imencode(".jpg", np.ascontiguousarray(img[..., ::-1]),
                                            [cv2.IMWRITE_JPEG_QUALITY, jpeg])[1], cv2.IMREAD_COLOR)[..., ::-1]
        out, why = find_outline(np.ascontiguousarray(img), geo, cam)
        assert out is not None, why
        used, pts = (out.field_px, geo.field_corners) if out.field_px is not None else (out.quad_px, geo.outer_corners)
        t = cam.project_from(G, np.c_[pts[:, :2], np.zeros(4)])
        worst.append(max(np.linalg.norm(t - q, axis=1).min() for q in used))
    return worst


def test_a_small_pad_under_a_soft_lens_through_jpeg_is_placed_by_its_border_profile():
    """A 56 px pad with a narrow border (1.7 px solid band) under a 1.2 px lens blur through JPEG 75
    reads 3-5 px of smear, within an edge fit's reach; fitted there as an edge (in light), two of
    these eight views had a corner 2.1-2.3 px off (unseen47's Approaching poses at 8-12 m 4 % of
    the height off).  Where the smear is read past 3 px the border's blurred profile is fitted
    first, and kept where it agrees with the border's centroid and its kernel is no wider than the
    border: every corner within 1.1 px.  Drawn in display values (``in_light=False``), where this was
    measured; summed in light, one of the eight views is 3.1 px off, the others 0.55-0.96 px (open:
    JPEG smears the chroma in display values, README "Mixing in light")."""
    worst = _narrow_border_views(1, 8, 0.0, 1.2, jpeg=75, in_light=False)
    assert max(worst) < 1.1, np.round(worst, 2)


def test_a_narrow_border_under_short_motion_is_placed_by_its_profile():
    """The same small pad under 4.5 px of motion and a 1 px lens: the smear read in luma, where the
    field's edge merges with the checker's, is 8.2 px on half the views (4.9 on the others), more
    than the border's 6.85 px, and those views kept the centroid, a corner 0.6-0.8 px off (the edge
    fit in light, before that: 1.3-2.3 px).  The profile is fitted up to 1.5 border widths of luma
    smear and kept where the kernel it finds in the border's channel is no wider than the border:
    every corner within 0.5 px."""
    worst = _narrow_border_views(2, 8, 4.5, 1.0)
    assert max(worst) < 0.5, np.round(worst, 2)


@pytest.mark.parametrize("beside_px", [12.0, 16.0])
def test_a_strip_of_the_border_colour_beside_a_soft_pad_is_not_taken_for_its_border(pad, beside_px):
    """A 36 px pad under a 2 px lens blur with a strip of the border's colour ``beside_px`` from a side
    (a magenta object 0.3-0.4 m from the deck).  The border's centroid took the strip's bump, the
    brightest in the profile's window, for the border's: that side read 18 px out, nothing placed
    the pad, and the edge fit, in display values, left it 11 % of its half side large (the height
    7.5 % low, a square to 1.4 % of its side: no gate refuses that), on every view.  The bump is now
    the one over the border's place: every view within 2.5 % (the centroid's own bias on an
    unresolved border, +1-2 %)."""
    from benchmarks.blur_bias import radial_error_pct

    for img, t, cam in _soft_views_with_a_strip(pad, beside_px, 2.0):
        out, why = find_outline(img, pad.geometry, cam)
        assert out is not None, why
        assert abs(radial_error_pct(out.quad_px, t[:, :2])) < 2.5, radial_error_pct(out.quad_px, t[:, :2])


def test_an_outline_under_motion_smear_says_how_good_it_is():
    """Rendered gusty descents with a 40 ms exposure: a far pad's outline smeared by 5-8 px is placed
    by the border's centroid, ~0.5 px outward on rendered frames (conditions' gusty descent: height
    1 % low), while its corners were held to the 0.3 px a sharp edge gets: 11 of these 17 poses lay
    beyond their covariance's 99 % bound (NEES median 14-24 per descent).  Each corner's noise now grows with
    the smear measured on the image (0.1 px per px placed by the centroid, 0.04 by the border's
    fitted profile): at most one beyond, NEES median 0.7-4 (chi-square with 3 degrees of freedom:
    2.4; a covariance twice too wide would put it near 0.6).  (It was 1.7 with every such outline
    placed by the centroid; the 5 of these 17 whose border is smeared over no more than its width
    are now placed by its profile, four of them 8-52 mm off where the centroid put them 69-102 mm
    (the fifth 86 against 88), and the median was 1.0; since a side is placed by its fit whatever
    the other sides, six more poses came closer, NEES 0.34-3.07 where they were 1.29-3.6, and the
    median is 0.75: the covariance a little wide, not the errors larger.)  Those were frames mixed in
    display values.  Mixed in light, as since render revision 12, the smeared border's centroid and
    profile sit where the pad is: the same poses come out a tenth of that noise off (NEES median
    0.02, ``design_fit`` on or off), so the covariance is far too wide there, and the smear's noise
    per px awaits a new measure; never too sure, which is what is held here.  Since render revision
    14 (minimum-snap flights) these descents smear some far frames 19-24 px, a third of the pad's
    side, whose yaw cue a cold start cannot read: each localizer runs through its descent, as a run
    does, every smeared far frame must be posed, and the outline's poses are held to their
    covariance."""
    from hvloc.geometry import matrix_from_quat_xyzw
    from render.frames import SequenceRenderer
    from render.spec import DatasetSpec

    nees, fitted = [], []
    for seed in (21, 24):
        spec = DatasetSpec.model_validate({
            "name": "gusty", "seed": seed, "sequences": 1,
            "camera": {"width": 640, "height": 640, "hfov_deg": 60, "fps": 4, "exposure_s": 0.04, "supersample": 1},
            "trajectory": {"families": ["straight"], "start_height_m": 9.0, "duration_s": [6, 6],
                           "gust_accel_mps2": [1.5, 1.5]},
            "environment": {"distractors": {"boxes": [0, 0], "decoy_patches": [0, 0], "decoy_markers": [0, 0]}}})
        r = SequenceRenderer(spec, 0)
        try:
            locs = [(HierarchicalLocalizer(r.pad, r.camera, LocalizerConfig(use_markers=False, design_fit=design),
                                           T_B_C=r.T_B_C), design, out) for design, out in ((False, nees), (True, fitted))]
            for k in range(len(r)):
                fr = r.render(k)
                lab = fr.labels
                smeared = lab["phase_gt"] == "approaching" and lab["pad_fully_visible"] and lab["blur_px"] >= 5.0
                for loc, design, out in locs:
                    e = loc.process(fr.rgb, float(r.times[k]),
                                    matrix_from_quat_xyzw([lab[f"body2world_q{a}"] for a in "xyzw"]))
                    if not smeared:
                        continue
                    assert e.ok, (seed, k, design, e.status, e.reason)
                    if e.method == "outline":
                        d = e.cam2pad[:3, 3] - r.cam2pad(k)[:3, 3]
                        out.append(float(d @ np.linalg.solve(e.cov[:3, :3], d)))
        finally:
            r.close()
    nees, fitted = np.array(nees), np.array(fitted)
    assert len(nees) >= 12, len(nees)
    for n in (nees, fitted):
        assert np.sum(n > 11.34) <= 1 and np.median(n) <= 4.0, np.round(np.sort(n), 2)


@pytest.mark.parametrize("sides, smeared", [
    ([5.2, 2.5, 2.4, 3.3], False),   # pitched_jpeg_small, a sharp 33 px JPEG pad (blur 0.6 px): one side wide
    ([3.5, 5.9, 5.6, 2.5], False),   # a sharp glossy 31 px pad behind a barrel lens: two adjacent sides wide
    ([2.7, 9.8, 3.0, 9.0], True),    # gusty_blur, 9.7 px of blur: the pair across the motion
    ([3.4, 4.4, 2.5, 7.9], True),    # a 36 px pad under 9 px of blur, one side of the pair read short
    ([np.nan, 8.0, np.nan, np.nan], True),  # a cut pad: one side read
])
def test_motion_smear_is_read_on_a_pair_of_parallel_sides(pad, monkeypatch, sides, smeared):
    """Motion smears both sides of a parallel pair alike; a wide reading on one side (or two adjacent
    ones) is the pad's structure.  Read as the most over the sides, sharp 25-35 px pads under JPEG
    or glare read 5-6 px, went to the centroid placement meant for motion and were refused or
    placed worse (pitched_jpeg_small 95.8 %, an unseen glossy barrel scene 93.8 % of the frames in
    scope); read per pair (the pair's mean), 98.5 and 99.6 %.  The readings are those of real frames."""
    import hvloc.phases as ph

    monkeypatch.setattr(ph, "step_blur", lambda *a, **k: np.array(sides, np.float64))
    G = tilted(0.1, -0.1, 8.0, 0.4)
    img = warp_pad_view(pad, CAM, G, GROUND)
    smear = ph._smear_near(img, CAM.project_from(G, pad.geometry.outer_corners), pad.geometry, CAM, 12.0)[2]
    assert (smear > ph.SMEARED_PX) == smeared, smear


def _at_image_edge(G0, geo, axis, toward, inset_px):
    """``G0`` moved so that the pad's outermost corner toward an image edge (``axis`` 0: x, 1: y;
    ``toward`` +1 or -1) lies ``inset_px`` inside it."""
    G = G0.copy()
    target = (CAM.width - 1 - inset_px) if toward > 0 else inset_px
    for _ in range(3):
        def ext(T):
            c = CAM.project_from(T, geo.outer_corners)[:, axis]
            return c.max() if toward > 0 else c.min()
        step = np.zeros(3)
        step[axis] = 1e-3
        G2 = G.copy()
        G2[:3, 3] += G[:3, :3] @ step
        G[:3, 3] += G[:3, :3] @ (step * (target - ext(G)) / (ext(G2) - ext(G)))
    return G


def test_a_smeared_pad_at_the_image_edge_is_placed_from_the_stretches_in_view(pad):
    """Under 13 px of motion blur toward the image's edge, a pad whose corner lies 4 px inside it
    smears across the edge: read as cut, it was refused ("cut by the image's edge and smeared by
    motion"), or read whole with every corner 5 px out (the border's centroid needs cross-profiles
    that a side near the edge does not have; gusty_blur, 5 px at 7 m, rejected only by the tilt
    gate).  Each side is now placed by the border's centroid over the stretches whose profiles lie in
    view (two at least)."""
    geo = pad.geometry
    placed = tried = 0
    for h in (6.0, 9.0):
        for yaw in (0.3, 1.1, 2.0):
            for axis, toward in ((0, 1), (1, 1), (0, -1), (1, -1)):
                G = _at_image_edge(tilted(0.0, 0.0, h, yaw, 0.02, -0.03), geo, axis, toward, 4.0)
                truth = CAM.project_from(G, geo.outer_corners)
                d = np.zeros(3)
                d[axis] = toward
                img = _motion_blurred(pad, G, 13.0 * h / CAM.fx * (G[:3, :3] @ d), (120, 110, 90), n=16)
                out, why = find_outline(img, geo, CAM)
                tried += 1
                if out is None:
                    continue
                err = max(np.linalg.norm(out.quad_px - t, axis=1).min() for t in truth)
                placed += err < 1.5
                if out.sigma_scale is not None:  # read as cut: by the stretches in view
                    assert err < 2.0, (h, yaw, axis, toward, err)
    assert placed >= 0.5 * tried, (placed, tried)


def test_a_corner_at_the_image_edge_is_found(pad):
    """A pad whose corner lies a pixel or two inside or outside the image's edge, sharp or smeared
    8 px toward it: its colour hull runs along the edge for a few pixels or touches it at a point.
    Read whole, such a hull was refused (a hull squeezed against the edge has corners that are not
    the pad's); read as cut, the corner was not out of view, or the stretch toward it too short:
    "no pad-coloured quadrilateral" in a quarter of these views (conditions' gusty descent: 5.7 m,
    a corner 1.7 px out under 15 px of blur).  A hull that runs along the edge for under a quarter
    of a side is the pad's quadrilateral with a corner just cut off (tried as cut too when its
    outline is not found).  Every view is found, within 1.5 px."""
    geo = pad.geometry
    found, tried = 0, 0
    for h in (4.0, 7.0):
        for yaw in (0.3, 2.0):
            for axis, toward in ((0, 1), (1, 1), (0, -1), (1, -1)):
                for inset in (-1.5, 0.5):
                    for blur in (0.0, 8.0):
                        G = _at_image_edge(tilted(0.0, 0.0, h, yaw, 0.02, -0.03), geo, axis, toward, inset)
                        truth = CAM.project_from(G, geo.outer_corners)
                        d = np.zeros(3)
                        d[axis] = toward
                        img = _motion_blurred(pad, G, blur * h / CAM.fx * (G[:3, :3] @ d), (120, 110, 90), n=12) \
                            if blur else warp_pad_view(pad, CAM, G, (120, 110, 90))
                        out, why = find_outline(img, geo, CAM)
                        tried += 1
                        if out is None:
                            continue
                        err = min(np.linalg.norm(np.roll(out.quad_px, -s, 0) - truth, axis=1).max() for s in range(4))
                        assert err < 1.5, (h, yaw, axis, toward, inset, blur, err)
                        found += 1
    assert found == tried, (found, tried)


def test_a_pad_cut_by_the_image_edge_is_posed_from_what_is_seen(pad):
    """A pad running out of the image (one corner hidden) gave a hull squeezed against the image's
    edge: refused, or taken for the pad's corners (80 px off, "ok").  Now the seen stretches of the
    two sides toward the hidden corner meet where it is; the outline is refined on what is in view,
    and the hidden corner's pixel noise is scaled by how far it is extrapolated, so the pose's
    covariance says how good it is.  Over one-corner-hidden views at 5-12 m every outline found is
    within 2 px, most of those whose two sides toward the hidden corner are at least 40 % in view are
    found (the others may be refused), and every pose lies where its covariance says (chi-square,
    99.9 %)."""
    geo = pad.geometry
    clear, found_clear, found = 0, 0, 0
    for G, truth, seen, in_view in _one_corner_hidden_views(geo, (5.0, 8.0, 12.0), 7, (0.0, 1.57, 3.14, 4.71, 0.6, 2.4),
                                                             (0.1, 0.2)):
        clear += in_view >= 0.4
        out, why = find_outline(warp_pad_view(pad, CAM, G, (110, 90, 60)), geo, CAM)
        if out is None or out.hull_only:  # (a hull's corners, taken only as its design places them: below)
            continue
        found += 1
        found_clear += in_view >= 0.4
        q, s = _in_order_of(out.quad_px, truth)
        assert np.linalg.norm(q - truth, axis=1).max() < 2.0, (G, q - truth)
        scale = np.roll(out.sigma_scale, -s)
        assert np.all(scale[seen] == 1.0) and scale[~seen][0] > 1.0, scale
        pose = solve_planar_pose(CAM, geo.outer_corners, q, up_C=up_in_camera(G), sigma_px=0.3 * scale)
        err = pose.cam2pad[:3, 3] - G[:3, 3]
        assert err @ np.linalg.solve(pose.cov[:3, :3], err) < 16.3, (G, err)  # chi2(3), 99.9 %
    assert clear >= 20 and found_clear >= 0.8 * clear, (clear, found_clear, found)


def _in_order_of(quad_px, truth):
    """``(quad, shift)``: ``quad_px``'s corners in the order of ``truth`` (the same quad, found from
    another corner), rolled by ``shift``."""
    s = int(np.argmin([np.abs(np.roll(quad_px, -s, axis=0) - truth).max() for s in range(4)]))
    return np.roll(quad_px, -s, axis=0), s


def _one_corner_hidden_views(geo, heights, yaws: int, directions, insets):
    """``(T_P_C, corners px, which are in view, the shorter in-view share of the two sides toward
    the hidden corner)`` of slightly tilted views whose pad has exactly one corner out of the image:
    at each height, yaw and direction, the pad's centre ``inset`` sides inside the image's edge."""
    t = np.linspace(0, 1, 101)[:, None]
    for h in heights:
        for yaw in np.linspace(0.1, 2 * np.pi, yaws, endpoint=False):
            for ang in directions:
                for inset in insets:
                    G = tilted(*(0.577 * h - inset * geo.side_m) * np.array([np.cos(ang), np.sin(ang)]), h, yaw,
                               0.02, -0.03)
                    truth = CAM.project_from(G, geo.outer_corners)
                    seen = ((truth >= 0) & (truth <= 799)).all(axis=1)
                    if seen.sum() != 3:
                        continue
                    k = int(np.argmin(seen))
                    in_view = min(np.mean(((truth[j] + t * (truth[k] - truth[j]) >= 0)
                                           & (truth[j] + t * (truth[k] - truth[j]) <= 799)).all(axis=1))
                                  for j in ((k - 1) % 4, (k + 1) % 4))
                    yield G, truth, seen, in_view



def test_a_side_fit_started_pixels_off_a_large_pads_edge_settles_on_it(pad, monkeypatch):
    """A large pad's colour hull can lie pixels off its edge (fz355: a 257 px pad cut by the image's
    top edge on a platform whose grey rim lies beside the band: the hull's hidden corner 10 px out,
    the one beside it in view 5 px).  The wide side fit's window then holds the edge over a short
    stretch only, the line through it turned by degrees, and the narrow fit around that line kept
    the corner 5.5 px out along the next side: posed 11.9 % of the height off, "ok".  The wide fit
    is now made again from where it put the sides until they settle (``SIDE_FIT_PASSES``, where the
    solid band is wider than the window).  Over one-corner-hidden views at 1.9 m (300 px pads) whose
    hull is so made, every corner in view lies within 0.35 px; made once, some lay 3 px out."""
    from hvloc import phases as ph

    geo = pad.geometry
    worst, settled = {}, ph.SIDE_FIT_PASSES
    for passes in (1, settled):
        monkeypatch.setattr(ph, "SIDE_FIT_PASSES", passes)
        worst[passes] = []
        for G, truth, seen, _ in _one_corner_hidden_views(geo, (1.9,), 6, (0.0, 1.57, 3.14, 4.71, 0.8, 2.4),
                                                          (0.3, 0.5, 0.7, 0.9)):
            img = warp_pad_view(pad, CAM, G, GROUND)
            k = int(np.argmin(seen))  # the hidden corner; the one after it in view
            j = (k + 1) % 4
            hull = truth.copy()
            along = truth[j] - truth[(j + 1) % 4]
            hull[j] += 5.0 * along / np.linalg.norm(along)
            side = truth[k] - truth[j]
            hull[k] += 10.0 * np.array([side[1], -side[0]]) / np.linalg.norm(side)  # outward
            side_px = float(np.mean(np.linalg.norm(np.roll(truth, -1, axis=0) - truth, axis=1)))
            assert side_px * geo.border.solid_band_m / geo.side_m > 6.0  # (the band wider than the window)
            refined, _, _, _, origin = ph._fit_sides(img, hull, side_px, geo, CAM)
            if refined is not None:
                worst[passes].append(float(np.linalg.norm(refined + origin - truth, axis=1)[seen].max()))
    assert len(worst[settled]) >= 30, worst
    assert max(worst[settled]) < 0.35, worst
    assert sum(w > 2.0 for w in worst[1]) >= 2, worst  # (the premise: made once)

def test_a_side_mostly_cut_off_by_the_image_edge_is_read_on_what_is_in_view(pad):
    """Each side is read between a fifth and four fifths of its length (clear of the corners).  A
    side running out of the image with a third of it in view then kept only a few profiles, too few
    to fit: the pad was refused ("cut by the image's edge, and its sides there not found"; on
    conditions' gusty descent, two frames in a row at 4 m, 7 px of blur).  Such a side is read over
    its stretch in view instead, clear of the corner by a few pixels.  Over one-corner-hidden views
    at 4-9 m whose shorter side toward the hidden corner is 30-40 % in view, 24 of the 29 are found
    (21 before), every one within 2 px."""
    geo = pad.geometry
    views = found = 0
    for G, truth, seen, in_view in _one_corner_hidden_views(geo, (4.0, 6.0, 9.0), 9,
                                                             (0.0, 1.57, 3.14, 4.71, 0.6, 2.4, 3.9, 5.5),
                                                             (0.05, 0.1, 0.15, 0.2, 0.3)):
        if not 0.3 <= in_view < 0.4:
            continue
        views += 1
        out, _ = find_outline(warp_pad_view(pad, CAM, G, (110, 90, 60)), geo, CAM)
        if out is None or out.hull_only:  # (a hull's corners, taken only as its design places them)
            continue
        found += 1
        q, s = _in_order_of(out.quad_px, truth)
        assert np.linalg.norm(q[seen] - truth[seen], axis=1).max() < 2.0, (G, q - truth)
    assert views == 29 and found >= 24, (views, found)
    # sides along the image's edge have no stretch in view at all: no fit, and no error (a lens too)
    from hvloc.features import refine_quad

    img = np.zeros((120, 120), np.uint8)
    img[2:101, 2:101] = 200
    lens = Camera(120, 120, 100.0, 100.0, 59.5, 59.5, np.array([-0.1, 0.0, 0.0, 0.0, 0.0]))
    for cam in (None, lens):
        assert refine_quad(img, [[2, 2], [100, 2], [100, 100], [-1, 100]], half_width=2.5, camera=cam)[0] is None


def test_a_cut_pad_whose_side_toward_the_hidden_corner_is_too_short_to_fit_is_placed_by_its_design(pad):
    """A corner just out of view leaves the side toward it in view over a few pixels, too short a
    stretch to fit a line on: the pad was refused ("cut by the image's edge, and its sides there not
    found"; fz310, a 55 px pad at 5-6 m whose stretch was ~13 px: six frames lost as its descent
    began).  Its colour hull's three corners in view lie within a few pixels of the pad's, the
    hidden one where the hull's stretches meet: that outline (``hull_only``) is taken only where the
    pad's design, fitted over the pixels in view, places it, and is refused, saying so, where the
    design is not fitted.  Over one-corner-hidden views at 7 m with 25-38 % of the shorter side in
    view, most are found so, each within 0.2 % of the height and its covariance."""
    geo = pad.geometry
    hull = posed = 0
    for G, truth, seen, in_view in _one_corner_hidden_views(geo, (7.0,), 9, (0.0, 1.57, 3.14, 4.71, 0.6, 2.4, 3.9, 5.5),
                                                             (0.05, 0.1, 0.15, 0.2, 0.3)):
        if not 0.25 <= in_view < 0.38:
            continue
        img = warp_pad_view(pad, CAM, G, (110, 90, 60))
        out, _ = find_outline(img, geo, CAM)
        if out is None or not out.hull_only:
            continue
        hull += 1
        q, _ = _in_order_of(out.quad_px, truth)
        assert np.linalg.norm(q[seen] - truth[seen], axis=1).max() < 3.5, q - truth  # (a hull's pixels)
        for fit in (True, False):
            loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(design_fit=fit), T_B_C=np.eye(4))
            e = loc.process(img, 0.0, imu=G[:3, :3])  # the body is the camera; the pad lies level
            by_hull = e.status == "ok" and e.method == "outline" and e.extras.get("hull_only")
            if not fit:
                assert not by_hull and ("too short to fit" in e.reason or e.status == "ok"), e.reason
                continue
            if e.status != "ok" or e.method != "outline":
                continue  # (named by nothing: the cue corner out of view on a first frame)
            assert by_hull and isinstance(e.extras.get("design_fit"), dict), e.extras
            d = e.cam2pad[:3, 3] - G[:3, 3]
            assert np.linalg.norm(d) < 0.002 * G[2, 3] and d @ np.linalg.solve(e.cov[:3, :3], d) < 16.3, (d, e.cov)
            posed += 1
    assert hull >= 5 and posed >= 4, (hull, posed)


def test_a_cut_pad_smeared_along_a_side_is_read_on_what_is_in_view(pad):
    """Under motion smear past the edge fit's reach, a pad running out of the image is placed by the
    border's centroid over stretches of each side in view.  The stretches were fixed (five between
    a tenth and nine tenths of each side, two of them in view at least) and every profile reached as
    far as the widest smear: a side toward the hidden corner that is smeared little, its profiles
    running out of the image, or mostly cut off, showed fewer than two, and the pad was refused
    (gusty_blur, five frames in a row at 6-7 m, 15 px of smear across the top and bottom, 3-4 px
    across the side the image's right edge cuts).  Each side's profiles now reach as far as the
    smear across it (its pair's) and its stretches share what is in view of it; the hidden corner,
    carried out of view from stretches nearer together, is as much less sure.  Over one-corner-
    hidden views at 6 and 8 m smeared 14 px along a side of the pad, 10 of 56 were found before, 27
    now; every corner in view within 2 px, and every pose within its covariance."""
    from hvloc.phases import CENTROID_SIGMA_PER_SMEAR

    geo = pad.geometry
    views = found = 0
    for G, truth, seen, in_view in _one_corner_hidden_views(geo, (6.0, 8.0), 5, (0.0, 1.57, 3.14, 4.71, 0.6, 2.4),
                                                             (0.1, 0.2)):
        for axis in (0, 1):
            d = np.zeros(3)
            d[axis] = 1.0  # along a side of the pad, across the other two
            img = _motion_blurred(pad, G, 14.0 * G[2, 3] / CAM.fx * d, (110, 90, 60), n=16)
            views += 1
            out, _ = find_outline(img, geo, CAM)
            if out is None:
                continue
            found += 1
            q, s = _in_order_of(out.quad_px, truth)
            assert np.linalg.norm(q[seen] - truth[seen], axis=1).max() < 2.0, (G, axis, q - truth)
            assert out.sigma_scale is not None and out.smear_px > 10.0, (out.sigma_scale, out.smear_px)
            assert out.sigma_per_smear <= CENTROID_SIGMA_PER_SMEAR, out.sigma_per_smear  # (placed by the centroid)
            assert _nees_as_stated(out, geo, G) < 16.3, (G, axis)  # chi2(3), 99.9 %
    assert views == 56 and found >= 24, (views, found)


def _nees_as_stated(out, geo, G, camera=CAM, sigma_of=None) -> float:
    """The position NEES of the pose of a found outline ``out`` of the view at ``G``, named and weighed
    as the localizer names and weighs it (:func:`name_outline`, :func:`corner_sigma_px`; ``sigma_of``:
    the corners' noise from the detection's ``info`` instead)."""
    from hvloc.localizer import corner_sigma_px

    det, why = name_outline(out, geo, camera.project_from(G, geo.outer_corners)[0])
    assert det is not None, why
    pose = solve_planar_pose(camera, det.pts_P, det.px, up_C=up_in_camera(G),
                             sigma_px=(sigma_of or corner_sigma_px)(det.info))
    err = pose.cam2pad[:3, 3] - G[:3, 3]
    return float(err @ np.linalg.solve(pose.cov[:3, :3], err))


def test_a_cut_pad_edge_fitted_under_smear_states_the_fits_noise(pad):
    """Where the border's centroid cannot place a pad cut by the image's edge under more smear than
    :data:`SMEARED_PX`, its sides are edge-fitted in display values, in which a smeared edge's half
    level lies toward its dark side: every corner 1.5-3 px out under 9-10 px of smear, the hidden
    one further.  They were stated at the centroid's noise (0.1 px per px of smear), the hidden
    corner's scale on the 0.3 px floor alone: unseen51's cut pad at 1 m under 9.7 px of smear was
    posed 22 mm off stating 2 mm (NEES 24), and the flow anchored on it.  Over one-corner-hidden
    views at 1.8 and 2.6 m smeared 9 px two ways, where the edge fit places the pad each pose holds
    the truth within its 3 sigma as stated now; as stated before, most did not."""
    from hvloc.phases import CENTROID_SIGMA_PER_SMEAR, EDGE_SIGMA_PER_SMEAR, SMEARED_PX

    geo = pad.geometry
    nees = []  # (as stated, as stated before)
    for G, truth, seen, in_view in _one_corner_hidden_views(geo, (1.8, 2.6), 6, (0.0, 1.57, 3.14, 4.71, 0.8, 2.4),
                                                             (0.2,)):
        for ang in (0.0, 1.2):
            img = _motion_blurred(pad, G, 9.0 * G[2, 3] / CAM.fx * np.array([math.cos(ang), math.sin(ang), 0.0]),
                                  (120, 120, 125), n=16)
            out, _ = find_outline(img, geo, CAM)
            if out is None or out.sigma_per_smear != EDGE_SIGMA_PER_SMEAR:
                continue
            assert out.smear_px > SMEARED_PX and out.sigma_scale is not None, (out.smear_px, out.sigma_scale)
            def before(info):
                return np.hypot(0.3 * np.asarray(info["px_sigma_scale"]), CENTROID_SIGMA_PER_SMEAR * info["px_sigma_blur"]
                                / EDGE_SIGMA_PER_SMEAR)

            nees.append((_nees_as_stated(out, geo, G), _nees_as_stated(out, geo, G, sigma_of=before)))
    assert len(nees) >= 6, nees
    assert all(now < 14.16 for now, _ in nees), nees  # chi2(3), 3 sigma
    # (the premise: as stated before, some did not; 2 of them until the wide side fit was made again
    # until it settles, phases.SIDE_FIT_PASSES, which put their corners nearer)
    assert sum(old > 14.16 for _, old in nees) >= 1, nees


def test_an_outline_left_at_its_colour_hulls_corners_states_their_noise(pad):
    """Smeared so that no side is fitted and no centroid read, an outline keeps its colour hull's
    corners: the colour reaches past the pad along the motion, and through a fisheye the hull's
    straight sides cut the pad's bowed ones.  Those corners were stated at the centroid's noise (0.1 px
    per px of smear): unseen49's fisheye at 1.2 m put a pose 69 mm off stating 13 mm (NEES 21),
    and the flow's keyframe was made from it.  Here 10-20 px smears through a 120 degree fisheye at
    0.9 m: where the hull's corners are kept (their poses 8-9 % of the height off), each pose,
    weighed as the localizer weighs them, holds the truth within its 3 sigma; at the centroid's
    noise one did not."""
    from types import SimpleNamespace

    from hvloc.phases import CENTROID_SIGMA_PER_SMEAR, HULL_SIGMA_PER_SMEAR

    geo = pad.geometry
    cam = Camera(960, 720, 300.0, 300.0, 479.5, 359.5, np.array([0.03, -0.01, 0.002, -0.0002]), model="fisheye")
    lit = SimpleNamespace(texture_rgb=(_linear(pad.texture_rgb) * 4096).astype(np.float32), ppm=pad.ppm,
                          side_m=pad.side_m)
    stated = []  # each hull-cornered pose's NEES: at the hull's noise, at the centroid's
    for ang, smear_px in ((0.0, 20.0), (1.0, 10.0), (0.0, 10.0)):
        G = tilted(0.3, -0.2, 0.9, 0.4, 0.05, -0.03)
        shift = smear_px * 0.9 / cam.fx * np.array([math.cos(ang), math.sin(ang), 0.0])
        acc = 0.0
        for s in np.linspace(-0.5, 0.5, 16):
            T = G.copy()
            T[:3, 3] += s * shift
            acc = acc + warp_pad_view(lit, cam, T, tuple(_linear((110, 90, 60)) * 4096), supersample=1, in_light=False) / 4096.0
        out, why = find_outline(_srgb(np.nan_to_num(acc / 16)), geo, cam)  # (no light past the lens's field)
        if out is None or out.sigma_per_smear != HULL_SIGMA_PER_SMEAR:
            continue
        truth = cam.project_from(G, geo.outer_corners)
        q, _ = _in_order_of(out.quad_px, truth)
        nees = []
        for per in (HULL_SIGMA_PER_SMEAR, CENTROID_SIGMA_PER_SMEAR):
            pose = solve_planar_pose(cam, geo.outer_corners, q, up_C=up_in_camera(G),
                                     sigma_px=float(np.hypot(0.3, per * out.smear_px)))
            err = pose.cam2pad[:3, 3] - G[:3, 3]
            nees.append(float(err @ np.linalg.solve(pose.cov[:3, :3], err)))
        stated.append(nees)
    assert len(stated) >= 2, stated
    assert all(new < 14.16 for new, _ in stated) and any(old > 14.16 for _, old in stated), stated  # chi2(3), 3 sigma


def test_a_cut_pad_whose_ring_the_cue_splits_is_found(pad):
    """The cue square is left out of the border's mask, so a pad running out of the image with its
    cue corner in view is two pieces of ring: a stretch from the image's edge to the cue, and the
    rest.  The larger piece alone outlines no quadrilateral ("no pad-coloured quadrilateral"; on
    conditions' gusty descent, 4 frames in a row at 4 m).  Pieces a cue's width apart are read as
    one ring.  Over one-corner-hidden views at 1.6-4 m with the cue in view and both sides toward
    the hidden corner at least 40 % in view, every pad is found, within 2 px."""
    geo = pad.geometry
    t = np.linspace(0, 1, 101)[:, None]
    tried, found = 0, 0
    for h in (1.6, 2.2, 3.0, 4.0):
        for yaw in np.linspace(0.1, 2 * np.pi, 9, endpoint=False):
            for ang in np.linspace(0, 2 * np.pi, 8, endpoint=False):
                for inset in (0.1, 0.25):
                    r = h * math.tan(math.radians(30)) * min(1 / max(abs(math.cos(ang)), 1e-9),
                                                             1 / max(abs(math.sin(ang)), 1e-9), 1.41)
                    G = tilted(*(r - inset * geo.side_m) * np.array([np.cos(ang), np.sin(ang)]), h, yaw, 0.02, -0.03)
                    truth = CAM.project_from(G, geo.outer_corners)
                    seen = ((truth >= 0) & (truth <= 799)).all(axis=1)
                    if seen.sum() != 3 or not seen[2]:  # one corner hidden, the cue's (BR) in view
                        continue
                    k = int(np.argmin(seen))
                    if min(np.mean(((truth[j] + t * (truth[k] - truth[j]) >= 0)
                                    & (truth[j] + t * (truth[k] - truth[j]) <= 799)).all(axis=1))
                           for j in ((k - 1) % 4, (k + 1) % 4)) < 0.4:
                        continue
                    tried += 1
                    out, why = find_outline(warp_pad_view(pad, CAM, G, (110, 90, 60) if k % 2 else (120, 120, 125)),
                                            geo, CAM)
                    if out is None:
                        continue
                    err = min(np.linalg.norm(np.roll(out.quad_px, -s, axis=0) - truth, axis=1).max() for s in range(4))
                    assert err < 2.0, (h, yaw, ang, inset, err)
                    found += 1
    assert tried >= 30 and found == tried, (found, tried)


def test_an_outline_whose_cue_cannot_be_read_is_named_by_the_imus_heading(pad):
    """Under JPEG a far pad's yellow cue is a few smeared pixels, and with no recent pose to name the
    outline by it was lost ("yaw cue unreadable and there is no prior").  The pad's heading in the
    world, learnt from the last accepted pose, and the AHRS name it; without the IMU it stays lost."""
    geo = pad.geometry
    cfg = LocalizerConfig(use_markers=False)  # the outline alone, as far away
    first = tilted(0.4, -0.3, 9.0, 0.7, 0.02, -0.03)
    loc = HierarchicalLocalizer(pad, CAM, cfg)
    e = loc.process(warp_pad_view(pad, CAM, first, GROUND), 0.0, _imu_from(first))
    assert e.ok and e.extras.get("yaw_from") == "cue", (e.status, e.reason, e.extras)
    for k, yaw in enumerate((0.9, 2.4, -1.9)):
        G = tilted(-0.6, 0.5, 8.0, yaw, -0.03, 0.02)
        img = warp_pad_view(pad, CAM, G, GROUND)
        cv2.fillConvexPoly(img, np.round(CAM.project_from(G, geo.cue.corners)).astype(np.int32),
                           tuple(int(c) for c in geo.border.color_rgb))  # no cue to read
        t = 5.0 * (k + 1)  # long after the last pose: no prior
        found, why = find_outline(img, geo, CAM)
        assert found is not None, why
        det, why = name_outline(found, geo)  # the premise: the cue alone names nothing
        assert det is None and "cue is unreadable" in why, why
        e = loc.process(img, t, _imu_from(G, extra=so3_exp([0.0, 0.0, math.radians(2.0)])))  # 2 deg of AHRS yaw drift
        assert e.ok and e.extras.get("yaw_from") == "imu heading", (yaw, e.status, e.reason)
        assert pose_error(e.cam2pad, G)[0] < 0.02 * 8.0, pose_error(e.cam2pad, G)


def _no_cue(pad, G, img):
    cv2.fillConvexPoly(img, np.round(CAM.project_from(G, pad.geometry.cue.corners)).astype(np.int32),
                       tuple(int(c) for c in pad.geometry.border.color_rgb))
    return img


def test_a_far_pad_whose_cue_cannot_be_read_is_named_by_its_whole_design(pad):
    """A cold start on a 25-40 px pad whose cue is unreadable (its few pixels of yellow smeared by
    JPEG, or lost in glare) and no pose or IMU heading to name it by was lost, frame after frame.
    The design as a whole is not symmetric under a quarter turn (three finder markers, three
    corners): correlated with the image through each naming of the outline, it names the pad.
    No view is misnamed.  Drawn in display values (``in_light=False``), where the naming's bars were
    set: summed in light, a 26-32 px pad's dark markers wash out (light averaged over a pixel), the
    right naming leads the next by 0.02-0.10 (0.08-0.14 here) and 7 of these 12 views are named,
    none wrong (open: README, "Mixing in light")."""
    geo = pad.geometry
    cfg = LocalizerConfig(use_markers=False)
    rng = np.random.default_rng(11)
    named = 0
    views = [(side_px, yaw) for side_px in (26.0, 32.0, 40.0) for yaw in np.linspace(0.3, 2 * np.pi, 4, endpoint=False)]
    for side_px, yaw in views:
        h = CAM.fx * geo.side_m / side_px
        G = tilted(rng.uniform(-0.1, 0.1) * h, rng.uniform(-0.1, 0.1) * h, h, yaw, rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1))
        img = _no_cue(pad, G, warp_pad_view(pad, CAM, G, GROUND, in_light=False))
        img = _jpeg(np.clip(img + rng.normal(0, 3, img.shape), 0, 255).astype(np.uint8), 60)
        e = HierarchicalLocalizer(pad, CAM, cfg).process(img, 0.0, _imu_from(G))  # gravity, and no pose yet
        if not e.ok:
            continue
        assert e.extras.get("yaw_from") == "pad design", e.extras
        named += 1
        assert pose_error(e.cam2pad, G)[0] < 0.02 * h, (side_px, yaw, pose_error(e.cam2pad, G))
    assert named >= 0.8 * len(views), (named, len(views))


def test_a_far_pad_summed_in_light_is_named_by_its_design_fitted_from_each_naming(pad, monkeypatch):
    """Summed in light, a 26-40 px pad's dark markers wash out, and the design's correlation through
    the outline names only 8 of these 12 cue-less cold starts (leading by too little in the rest).
    The design fitted from each of the four namings (drawn, blurred and toned as the camera makes
    it) fits the right one with half the residual of the others: 11 named, none wrong."""
    import hvloc.localizer as L

    geo = pad.geometry
    cfg = LocalizerConfig(use_markers=False)
    views = [(side_px, yaw) for side_px in (26.0, 32.0, 40.0) for yaw in np.linspace(0.3, 2 * np.pi, 4, endpoint=False)]

    def named():
        rng = np.random.default_rng(11)
        hows = []
        for side_px, yaw in views:
            h = CAM.fx * geo.side_m / side_px
            G = tilted(rng.uniform(-0.1, 0.1) * h, rng.uniform(-0.1, 0.1) * h, h, yaw, rng.uniform(-0.1, 0.1),
                       rng.uniform(-0.1, 0.1))
            img = _no_cue(pad, G, warp_pad_view(pad, CAM, G, GROUND))  # (summed in light)
            img = _jpeg(np.clip(img + rng.normal(0, 3, img.shape), 0, 255).astype(np.uint8), 60)
            e = HierarchicalLocalizer(pad, CAM, cfg).process(img, 0.0, _imu_from(G))  # gravity, and no pose yet
            if e.ok:
                assert pose_error(e.cam2pad, G)[0] < 0.02 * h and pose_error(e.cam2pad, G)[1] < 3.0, \
                    (side_px, yaw, e.extras.get("yaw_from"), pose_error(e.cam2pad, G))
                hows.append(e.extras.get("yaw_from"))
        return hows

    hows = named()
    assert len(hows) >= 10 and "pad design fitted" in hows, hows
    monkeypatch.setattr(L.HierarchicalLocalizer, "_named_by_fit", lambda *a: None)  # the correlation alone
    assert len(named()) <= len(hows) - 2


def test_a_first_sight_named_by_a_misread_cue_is_not_taken_where_the_design_names_another_corner(pad):
    """A cold start whose cue is misread: something of the cue's colour (a leaf, a speck of sunlit
    ground under JPEG) on another corner of a 26-40 px pad.  With no pose before it, the cue's
    naming was taken; its pose a quarter turn off in yaw and metres off in position, and later
    frames read right were refused as jumps from it (65 false accepts on a cluttered JPEG 50
    descent).  On a first sight the cue's naming is taken only where the design's best naming is
    the same; here the design names the pad (sure of it) or nothing does, and no pose is wrong."""
    geo = pad.geometry
    cfg = LocalizerConfig(use_markers=False)
    rng = np.random.default_rng(5)
    c = geo.cue.corners[:, :2]
    named, views = 0, 0
    for side_px in (26.0, 32.0, 40.0):
        for yaw in np.linspace(0.5, 2 * np.pi, 3, endpoint=False):
            h = CAM.fx * geo.side_m / side_px
            G = tilted(rng.uniform(-0.1, 0.1) * h, rng.uniform(-0.1, 0.1) * h, h, yaw, rng.uniform(-0.05, 0.05),
                       rng.uniform(-0.05, 0.05))
            img = _no_cue(pad, G, warp_pad_view(pad, CAM, G, GROUND, in_light=False))
            turn = int(rng.integers(1, 4))  # the cue's square a quarter, half or three quarters round
            q = np.column_stack([c @ np.linalg.matrix_power(np.array([[0.0, -1.0], [1.0, 0.0]]), turn).T, np.zeros(4)])
            cv2.fillConvexPoly(img, np.round(CAM.project_from(G, q)).astype(np.int32), tuple(int(v) for v in geo.cue.color_rgb))
            img = _jpeg(np.clip(img + rng.normal(0, 2, img.shape), 0, 255).astype(np.uint8), 70)
            found, why = find_outline(img, geo, CAM)
            assert found is not None, why
            det, _ = name_outline(found, geo)  # the premise: the cue alone names it wrongly
            true_tl = CAM.project_from(G, geo.outer_corners[:1])[0]
            assert det is not None and np.linalg.norm(det.px[0] - true_tl) > 0.5 * side_px, (side_px, yaw, turn)
            views += 1
            e = HierarchicalLocalizer(pad, CAM, cfg).process(img, 0.0, _imu_from(G))  # gravity, and no pose yet
            if not e.ok:
                assert "its design corner" in e.reason, e.reason
                continue
            assert e.extras.get("yaw_from") == "pad design", e.extras
            assert pose_error(e.cam2pad, G)[0] < 0.02 * h and pose_error(e.cam2pad, G)[1] < 3.0, (side_px, yaw, pose_error(e.cam2pad, G))
            named += 1
    assert named >= 0.6 * views, (named, views)


def test_a_weak_design_naming_is_taken_only_where_frames_agree_on_the_pads_heading(pad, monkeypatch):
    """A cold start's naming by the pad's design, frame by frame.  One frame's naming was taken
    wherever it correlated 0.6 and led the next by 0.04; on unseen47 a quad swollen around an 18 px
    pad was named a quarter turn wrong so (0.64, leading by 0.067), and only the square's gate kept
    its pose out.  Now a naming is taken alone only where it is sure (0.75, leading by 0.06); a
    weaker one where the namings of other frames' like-sized outlines give the pad the same heading
    in the world (the AHRS carries the camera's turn between them), outweighing those that give it
    another.  Here the
    design's correlations are squeezed to weak ones (the right naming leading by ~0.02), or turned a
    quarter (a wrong naming leading), from views drawn in display values (``in_light=False``: summed
    in light, a 30 px pad's right naming leads by a third as much, and squeezed, by nothing)."""
    import hvloc.localizer as L

    geo = pad.geometry
    cfg = LocalizerConfig(use_markers=False)
    h = CAM.fx * geo.side_m / 30.0
    real = L.ph.name_by_design
    mode = {"turn": 0, "best": 0.72, "gain": 0.15}

    def squeezed(gray, quad_px, geo_, camera, design):
        _, s = real(gray, quad_px, geo_, camera, design)
        w = np.roll(mode["best"] + mode["gain"] * (s - s.max()), mode["turn"])
        return None, w

    monkeypatch.setattr(L.ph, "name_by_design", squeezed)
    # the votes alone: the design fitted from each naming (which names these 30 px views at once,
    # test_a_far_pad_summed_in_light_is_named_by_its_design_fitted_from_each_naming) left out
    monkeypatch.setattr(L.HierarchicalLocalizer, "_named_by_fit", lambda *a: None)

    def view(t, yaw_deg):  # the same pad from a drone drifting and turning (its AHRS turns with it)
        G = tilted(0.3 + 0.2 * t, -0.2, h, math.radians(yaw_deg), 0.02, -0.01)
        return G, _no_cue(pad, G, warp_pad_view(pad, CAM, G, GROUND, in_light=False))

    def run(loc, t, yaw_deg, **m):
        mode.update({"turn": 0, "best": 0.72, "gain": 0.15}, **m)
        G, img = view(t, yaw_deg)
        return G, loc.process(img, t, _imu_from(G))

    # weak and alone: lost; the next frame's weak naming agrees: named, and right
    loc = HierarchicalLocalizer(pad, CAM, cfg)
    _, e = run(loc, 0.0, 40.0)
    assert not e.ok and "nor does its design name it" in e.reason, (e.status, e.reason)
    G, e = run(loc, 0.1, 47.0)
    assert e.ok and e.extras.get("yaw_from") == "pad design over frames", (e.status, e.reason, e.extras)
    assert pose_error(e.cam2pad, G)[0] < 0.02 * h and pose_error(e.cam2pad, G)[1] < 3.0, pose_error(e.cam2pad, G)
    # a wrong naming that the single-frame bar took (0.64, leading by 0.067) is not taken alone ...
    loc = HierarchicalLocalizer(pad, CAM, cfg)
    _, e = run(loc, 0.0, 40.0, turn=1, best=0.644, gain=0.6)
    assert not e.ok and "nor does its design name it" in e.reason, (e.status, e.reason, e.extras)
    # ... and its heading, a quarter turn off, outweighs right weak namings while it is recent
    for t, yaw in ((1.0, 44.0), (1.5, 46.0)):
        _, e = run(loc, t, yaw)
        assert not e.ok and "nor does its design name it" in e.reason, (t, e.status, e.reason, e.extras)
    G, e = run(loc, 2.5, 50.0)  # the wrong vote 2.5 s old, the right ones 1.5 and 1 s: they agree
    assert e.ok and e.extras.get("yaw_from") == "pad design over frames", (e.status, e.reason, e.extras)
    assert pose_error(e.cam2pad, G)[1] < 3.0, pose_error(e.cam2pad, G)
    # a sure naming is taken alone, on its first frame
    loc = HierarchicalLocalizer(pad, CAM, cfg)
    G, e = run(loc, 0.0, 40.0, best=0.92, gain=1.0)
    assert e.ok and e.extras.get("yaw_from") == "pad design", (e.status, e.reason, e.extras)


def test_a_far_pads_design_fits_that_lead_a_little_name_it_where_frames_agree(pad, monkeypatch):
    """The design fitted from each of a cold start's four namings names the pad alone where the best
    fit's residual is 1.3 times below the next; at 18-28 px (a dusk deck, a wide cheap lens) the right
    naming led by 1.04-1.25, and the cold start waited seconds.  Such leads are votes for the pad's
    heading in the world (the AHRS carries the camera's turn between frames), summed in log as
    :class:`hvloc.localizer.DesignVotes` sums the correlation's: named where frames agree up to the
    single frame's 1.3; a lead under 1.04 (the wrong best fits led by 1.008-1.025) is no vote, and a
    vote for another heading counts against.  Here the fits' ratios are set, their namings real
    (or turned a quarter) and the correlation's votes silenced."""
    import hvloc.localizer as L

    geo = pad.geometry
    cfg = LocalizerConfig(use_markers=False)
    h = CAM.fx * geo.side_m / 30.0
    real_fit, real_design = L.HierarchicalLocalizer._named_by_fit, L.ph.name_by_design
    mode = {"ratio": 1.1, "turn": 0}

    def fit(self, found, rgb, up_C):
        got = real_fit(self, found, rgb, up_C)
        return None if got is None else ((got[0] + mode["turn"]) % 4, mode["ratio"])

    monkeypatch.setattr(L.HierarchicalLocalizer, "_named_by_fit", fit)
    monkeypatch.setattr(L.ph, "name_by_design", lambda *a: (None, np.full(4, 0.7)))  # no lead: no vote of its own

    def run(loc, t, yaw_deg, **m):
        mode.update({"ratio": 1.1, "turn": 0}, **m)
        G = tilted(0.3 + 0.2 * t, -0.2, h, math.radians(yaw_deg), 0.02, -0.01)
        return G, loc.process(_no_cue(pad, G, warp_pad_view(pad, CAM, G, GROUND, in_light=False)), t, _imu_from(G))

    # leading by 1.1: two frames are not enough (log 1.1 twice < log 1.3), the third names it, right
    loc = HierarchicalLocalizer(pad, CAM, cfg)
    for t, yaw in ((0.0, 40.0), (0.3, 44.0)):
        _, e = run(loc, t, yaw)
        assert not e.ok and "1.100 times lower" in e.reason, (t, e.status, e.reason)
    G, e = run(loc, 0.6, 47.0)
    assert e.ok and e.extras.get("yaw_from") == "pad design fitted over frames", (e.status, e.reason, e.extras)
    assert pose_error(e.cam2pad, G)[0] < 0.02 * h and pose_error(e.cam2pad, G)[1] < 3.0, pose_error(e.cam2pad, G)
    # leads under 1.04 are no votes, however many
    loc = HierarchicalLocalizer(pad, CAM, cfg)
    for k in range(5):
        _, e = run(loc, 0.2 * k, 40.0 + k, ratio=1.03)
        assert not e.ok, (k, e.status, e.extras)
    # a quarter turn's vote counts against the right ones while it is recent
    loc = HierarchicalLocalizer(pad, CAM, cfg)
    _, e = run(loc, 0.0, 40.0, ratio=1.2, turn=1)
    for t, yaw in ((0.3, 42.0), (0.6, 44.0), (0.9, 46.0), (1.2, 48.0)):  # (without it the third named it)
        _, e = run(loc, t, yaw)
        assert not e.ok, (t, e.status, e.extras)
    G, e = run(loc, 1.5, 50.0)  # 5 log 1.1 - log 1.2 > log 1.3
    assert e.ok and e.extras.get("yaw_from") == "pad design fitted over frames", (e.status, e.reason, e.extras)
    assert pose_error(e.cam2pad, G)[1] < 3.0, pose_error(e.cam2pad, G)
    # a sure fit names it alone, on its first frame
    loc = HierarchicalLocalizer(pad, CAM, cfg)
    _, e = run(loc, 0.0, 40.0, ratio=1.5)
    assert e.ok and e.extras.get("yaw_from") == "pad design fitted", (e.status, e.reason, e.extras)


def test_design_votes_weigh_only_like_sized_recent_outlines_and_never_need_a_clock_to_take_a_sure_one():
    """:class:`hvloc.localizer.DesignVotes` on its own: a sure naming is taken with no attitude or
    an odd timestamp (NaN, inf), a weak one is not; a weak vote agrees only with votes of outlines
    within a fifth of its size and at most 2 s old; a vote for a heading a quarter turn off,
    outweighing the agreeing ones, keeps it out."""
    from hvloc.localizer import DesignVotes

    for t, heading in ((float("nan"), 0.1), (float("inf"), 0.1), (1.0, None)):
        assert DesignVotes().cast(t, heading, 25.0, 0.8, 0.07) == "pad design"
        assert DesignVotes().cast(t, heading, 25.0, 0.7, 0.03) is None
    v = DesignVotes()
    assert v.cast(0.0, 0.10, 25.0, 0.7, 0.03) is None  # alone
    assert v.cast(0.1, 0.12, 16.0, 0.7, 0.03) is None  # another object's size: not weighed with it
    assert v.cast(2.5, 0.11, 25.0, 0.7, 0.03) is None  # the first 2.5 s old
    assert v.cast(2.6, 0.09, 24.0, 0.7, 0.02) == "pad design over frames"  # 0.02 + 0.03 >= 0.04
    v = DesignVotes()
    v.cast(0.0, 0.10 + math.pi / 2, 25.0, 0.7, 0.05)  # a quarter turn off, leading by 0.05
    v.cast(0.2, 0.10, 25.0, 0.7, 0.03)
    assert v.cast(0.4, 0.12, 26.0, 0.7, 0.03) is None  # 0.03 + 0.03 - 0.05 < 0.04
    assert v.cast(0.6, 0.11, 25.0, 0.7, 0.04) == "pad design over frames"  # 0.04 + 0.06 - 0.05


def test_the_design_naming_never_raises_on_a_degenerate_quad(pad):
    """The localizer never raises on an image: a quad with a corner at NaN or infinity, all corners
    at one pixel, or far outside the image names nothing (it raised on NaN: round(nan))."""
    from hvloc.phases import PadDesign, name_by_design

    design = PadDesign(pad.texture_rgb)
    gray = np.full((CAM.height, CAM.width), 90, np.uint8)
    good = np.array([[300.0, 300.0], [340.0, 300.0], [340.0, 340.0], [300.0, 340.0]])
    for q in (np.where(np.arange(8).reshape(4, 2) == 2, np.nan, good), np.where(np.arange(8).reshape(4, 2) == 5, np.inf, good),
              np.repeat(good[:1], 4, axis=0), good * 1e9, good - 5000.0):
        k, scores = name_by_design(gray, q, pad.geometry, CAM, design)
        assert k is None and scores.shape == (4,), (q, k, scores)


def test_an_outline_is_named_by_the_last_pose_even_when_it_has_moved_half_a_side(pad):
    """A far pad without a readable cue is named by the last pose.  Its predicted TL pixel alone named
    the nearest corner, and a pose 0.5 m off at 12 m (20 px, on a 25 px pad) put that nearest
    another corner: every following frame was named a quarter turn wrong (the fisheye scene:
    rejected as a 90 degree vision-IMU jump).  The four predicted corners, taken about their
    centre, name it whatever the shift."""
    geo = pad.geometry
    cfg = LocalizerConfig(use_markers=False)
    h = CAM.fx * geo.side_m / 30.0
    for yaw in (0.3, 1.4, 2.9, 4.4):
        first = tilted(0.0, 0.0, h, yaw, 0.02, -0.03)
        loc = HierarchicalLocalizer(pad, CAM, cfg)
        e = loc.process(warp_pad_view(pad, CAM, first, GROUND), 0.0, _imu_from(first))
        assert e.ok and e.extras.get("yaw_from") == "cue", (e.status, e.reason)
        for k, (dx, dy) in enumerate(((0.6, 0.0), (0.0, -0.7), (-0.5, 0.45))):  # metres in 0.1 s, along a side or not
            d = np.array([dx, dy]) * geo.side_m / 0.85
            G = tilted(first[0, 3] + d[0], first[1, 3] + d[1], h, yaw + 0.05, 0.02, -0.03)
            img = _no_cue(pad, G, warp_pad_view(pad, CAM, G, GROUND))
            e = loc.process(img, 0.1 * (k + 1), _imu_from(G))
            assert e.ok and e.extras.get("yaw_from") == "previous", (yaw, k, e.status, e.reason)
            assert pose_error(e.cam2pad, G)[1] < 3.0, (yaw, k, pose_error(e.cam2pad, G))
            first = G


def test_a_design_with_no_quarter_turn_asymmetry_names_nothing(pad):
    """The design names a pad only where one naming clearly leads: a pad printed with a plain border,
    a plain field and no cue looks the same at all four namings, and stays unnamed.  (With the
    border's own pattern kept, fits drawn from 2 x 2 points per pixel named 32 px views of it rightly,
    their RMS 1.3-1.8 times lower.)"""
    import dataclasses

    geo = pad.geometry
    tex = pad.texture_rgb.copy()
    o, b = geo.outer_corners[:, :2], geo.border_m
    inner = np.round(pad.to_texture_px(np.column_stack([o - np.sign(o) * b, np.zeros(4)]))).astype(np.int32)
    tex[:] = geo.border.color_rgb  # (the border's own pattern is not turned with the pad: it names it)
    cv2.fillConvexPoly(tex, inner, (245, 245, 245))
    plain = dataclasses.replace(pad, texture_rgb=tex)
    for yaw in (0.4, 2.0):
        h = CAM.fx * geo.side_m / 32.0
        G = tilted(0.3, -0.2, h, yaw, 0.03, -0.02)
        e = HierarchicalLocalizer(plain, CAM, LocalizerConfig(use_markers=False)).process(
            warp_pad_view(plain, CAM, G, GROUND), 0.0, _imu_from(G))
        assert not e.ok and "nor does its design name it" in e.reason, (e.status, e.reason)


def test_a_dark_patch_of_the_border_hue_beside_the_pad_does_not_swell_its_outline(pad):
    """The colour mask is grown into shadow: pixels whose chroma relative to their brightness says
    magenta, joined to the lit border.  A dark patch of that hue touching the pad (a shadowed
    magenta tarp; on JPEG frames the border's chroma bled onto a dark platform's side, as on
    pitched_jpeg_small's 25 px pads) joins it too, and the hull then has a side outside the pad:
    refused ("sides and hull disagree", "band missing"), frame after frame.  The outline is then
    read once more from the lit colour alone.  (On views summed in light a 26-34 px pad is still
    refused now and then, "band missing": 1 of 32 such views, by this localizer and the one before
    it; here at most one of the twelve, never a wrong one.)"""
    geo = pad.geometry
    o, s = geo.outer_corners, geo.side_m
    strip = np.array([o[1], o[1] + [0.35 * s, 0, 0], o[2] + [0.35 * s, 0, 0], o[2]]) + [0.004, 0.0, 0.0]
    refused = []
    for side_px in (30.0, 45.0, 70.0):
        for yaw in np.linspace(0.2, 2 * np.pi, 4, endpoint=False):
            h = CAM.fx * s / side_px
            G = tilted(0.05 * h, -0.04 * h, h, yaw, 0.03, -0.02)
            img = warp_pad_view(pad, CAM, G, (150, 140, 120))
            cv2.fillConvexPoly(img, np.round(CAM.project_from(G, strip)).astype(np.int32), (40, 22, 38))
            found, why = find_outline(img, geo, CAM)
            if found is None:
                refused.append((side_px, round(float(yaw), 2), why))
                continue
            truth = CAM.project_from(G, o)
            err = max(np.linalg.norm(found.quad_px - t, axis=1).min() for t in truth)
            assert err < 0.03 * side_px, (side_px, yaw, err)
    assert len(refused) <= 1, refused


def _bled_into_a_grey_deck(pad, G, glare=0.55, bleed_px=5, in_light=True):
    """The view at ``G`` on a grey deck, the pad's border washed toward white by glare and its
    colour's chroma at half resolution and spread ``bleed_px`` (a square) past the pad into the deck,
    as JPEG's 4:2:0 and a codec's smoothing do (unseen45: a glossy pad on a grey deck at JPEG 65).
    ``in_light``: the view summed in light (:func:`warp_pad_view`)."""
    geo = pad.geometry
    img = warp_pad_view(pad, CAM, G, (128, 128, 128), in_light=in_light).astype(np.float32)

    def mask(P):
        m = np.zeros(img.shape[:2], np.uint8)
        cv2.fillConvexPoly(m, np.round(CAM.project_from(G, P) * 8).astype(np.int32), 1, shift=3)
        return m > 0

    field = mask(np.c_[geo.field_corners[:, :2], np.zeros(4)])
    border = mask(geo.outer_corners) & ~field
    img[border] = (1 - glare) * img[border] + glare * 235
    ycc = cv2.cvtColor(np.clip(img, 0, 255).astype(np.uint8), cv2.COLOR_RGB2YCrCb).astype(np.float32)
    kernel = np.ones((bleed_px, bleed_px), np.uint8)
    for c, spread in ((1, cv2.dilate), (2, cv2.erode)):  # magenta: Cr above neutral, Cb below
        half = cv2.resize(ycc[..., c], None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)
        full = cv2.resize(half, ycc.shape[1::-1], interpolation=cv2.INTER_LINEAR)
        ycc[..., c] = np.where(field, ycc[..., c], 128 + spread(full - 128, kernel))
    return cv2.cvtColor(np.clip(ycc, 0, 255).astype(np.uint8), cv2.COLOR_YCrCb2RGB)


@pytest.mark.parametrize("side_px", [30.0, 40.0, 55.0])
def test_a_pads_colour_bled_into_a_grey_deck_is_refused_or_placed_by_its_field(pad, side_px):
    """Glare makes the border brighter than a grey deck, and the codec bleeds its magenta 2-3 px into
    the deck: the colour outline swells uniformly (every corner a few px out, so its four corners
    still fit a square), and the white field, searched for inward from the swollen prediction,
    fits loosely or on the border's bright outer edge.  These outlines were posed 6-9 % large
    (unseen45: 7.6 and 9.9 % of the height low at 13.6 m).  The field now counts against the
    colour: found outside where the colour puts it, or loosely fitted but swollen past by more than
    5 % of the side, the outline is refused; where the field fits cleanly it places the pad (40 px:
    two of four views, within 4 % of the side).  At 30 px the field's fit itself had landed on the
    border's outer edge on one side, whose rise peaks just beyond the search's outward reach, and two
    of four views were placed 15-19 % off; that side now starts a border's width in from where the
    outer edge peaks (rise_offsets' ``apart_px``): one view placed 3 % off, three refused.  Drawn in
    display values (``in_light=False``), where this was measured: summed in light one of the twelve
    is refused and the others placed within 3.1 % of the side (the premise fails), but with a 7 px
    bleed one of four 30 px views is placed 20 % off: open (README, "Mixing in light")."""
    geo = pad.geometry
    h = CAM.fx * geo.side_m / side_px
    refused = 0
    for yaw in np.linspace(0.2, 2 * np.pi, 4, endpoint=False):
        G = tilted(0.05 * h, -0.04 * h, h, yaw, 0.03, -0.02)
        found, why = find_outline(_bled_into_a_grey_deck(pad, G, in_light=False), geo, CAM)
        if found is None:  # (refused as swollen past its field, or for a band the bleed hides)
            refused += 1
            continue
        used, P = (found.field_px, geo.field_corners) if found.field_px is not None else (found.quad_px, geo.outer_corners)
        truth = CAM.project_from(G, np.c_[P[:, :2], np.zeros(4)])
        err = max(np.linalg.norm(used - t, axis=1).min() for t in truth)
        assert err < 0.05 * side_px, (yaw, err / side_px, found.field_px is not None)
    assert refused >= 2, refused  # (the premise: the bleed is as bad as the scene's)


def test_a_loosely_fitted_field_places_a_pad_whose_colour_swelled_past_it():
    """unseen64's frames at 13.3-13.8 m (kept losslessly in tests/data: a 0.6 m pad 33-37 px across
    on a grey platform under a high sun, JPEG 60).  The magenta's chroma bleeds into the grey and
    the colour outline swells: at frame 41 its corners lay 2.4-2.8 px out, and the white field,
    fitted on luma a little loosely (its lines' scatter 0.38 px, over the 0.35 a field must fit to
    replace the outline), lay 1.8 px inside it, short of the 2 px that refuses the outline: posed
    10.0 % of the height low with a sigma of 1.5 %, a false accept.  A field that loose, but inside
    the outline by more than three of its scatters, places the pad, its scatter added to its
    corners' noise: 4.0 % low, a sigma of 2.0 %.  Its neighbours are placed as before (a clean
    field, or an outline the field agrees with), 3.5-3.7 % low: the small pad's bias remains."""
    for fr, G, cam, det in _named_by_labels("loose_field_grey_platform", 96):
        pose = solve_planar_pose(cam, det.pts_P, det.px, up_in_camera(G), sigma_px=corner_sigma_px(det.info))
        dz = (pose.cam2pad[2, 3] - G[2, 3]) / G[2, 3]
        loose = det.info.get("px_sigma_field")
        assert (loose is not None) == (fr["frame"] == 41), (fr["frame"], det.info)
        assert abs(dz) < 0.05, (fr["frame"], dz)
        if loose:
            assert det.info["corners"] == "field" and 0.35 < loose <= 0.6
            assert abs(dz) < 2.5 * math.sqrt(pose.cov[2, 2]) / G[2, 3], (dz, pose.cov[2, 2])


def test_a_rise_a_borders_width_in_is_the_fields_edge_only_where_it_leads_into_brighter(pad):
    """unseen61's first frames at 12 m (kept losslessly in tests/data: a 0.6 m glossy pad 70 px
    across on a grey deck, JPEG 60, frame 0 under 6.6 px of smear).  The white field's edge rises
    just beyond the search's outward reach, and a border's width in from it a black shape in the
    field ends in a rise as well; that rise, into no brighter a level than the field already
    reached, was taken for the field's edge (rise_offsets' ``apart_px``, 2d854e1) and the outlines
    were refused ("its colour swells past its white field", "its border band is missing").  An
    inner rise is the field's edge only where it leads into an inside brighter than anything
    between: all three are found, posed within 2 % of the height."""
    from hvloc.phases import detect_outline

    doc, views = _crop_views("smeared_small_pad_field", 128)
    geo = make_pad(doc["pad_spec"]).geometry
    for crop, cam, fr in views:
        G = np.array(fr["cam2pad"])
        det, why = detect_outline(crop, geo, cam)
        assert det is not None, (fr["frame"], why)
        pose = solve_planar_pose(cam, det.pts_P, det.px, up_in_camera(G))
        assert pose_error(pose.cam2pad, G)[0] < 0.02 * fr["height_m"], fr["frame"]


def test_a_glossy_pad_washed_pale_by_glare_is_found(pad):
    """unseen61 at 11-12 m under a noon sun (kept losslessly in tests/data): the glossy pad mirrors
    the sky's white light over its colour, and its magenta border reads sRGB (236, 207, 229), its
    chroma 0.08-0.14 of its value, under both the segmentation's saturation and the shadow's
    chroma bar (0.15): "no pad-coloured quadrilateral", 22 frames lost from 12 m down.  Bright
    pixels are taken at half that bar where nothing saturated is found (``GLARE_MIN_CHROMA``).
    The cue's yellow is washed too, so the corners are named from the labels here (the localizer
    names them from the last pose or the whole design); each pose within 3 % of the height."""
    for fr, G, cam, det in _named_by_labels("glare_washed_pad", 128):
        pose = solve_planar_pose(cam, det.pts_P, det.px, up_in_camera(G))
        assert pose_error(pose.cam2pad, G)[0] < 0.03 * fr["height_m"], (fr["frame"], pose_error(pose.cam2pad, G))


def _box_over(img, G, geo, k, f1, f2, corners=1, soften_px=0.8):
    """``img`` (the view at ``G``) with a grey box's edge across the pad from ``f1`` of the way
    along one side to ``f2`` along another, hiding corner ``k`` (``corners=2``: corners ``k`` and
    ``k + 1``), and an optics' blur of ``soften_px`` over all; ``(image, the pad's corners px)``."""
    c = CAM.project_from(G, geo.outer_corners)
    j = (k + 1) % 4
    if corners == 1:
        p1, p2, far = c[k] + f1 * (c[j] - c[k]), c[k] + f2 * (c[k - 1] - c[k]), c[k]
    else:
        p1, p2, far = c[k] + f1 * (c[k - 1] - c[k]), c[j] + f2 * (c[(j + 1) % 4] - c[j]), (c[k] + c[j]) / 2
    away = 3.0 * (far - c.mean(axis=0))
    img = img.copy()
    cv2.fillConvexPoly(img, np.round(np.array([p1, p2, p2 + away, p1 + away])).astype(np.int32), (120, 122, 128))
    return (cv2.GaussianBlur(img, (0, 0), soften_px) if soften_px else img), c


@pytest.mark.parametrize("soften_px", [0.0, 1.0])
def test_a_pad_with_a_corner_hidden_by_a_box_is_posed_from_what_is_seen(pad, soften_px):
    """A box over a corner (a moving deck slid under it) cuts the ring: its hull then has a side
    along the box's edge, the outline was refused ("border band missing", "sides and hull
    disagree") or, worse, taken whole with a corner tens of pixels off.  Each hull side is now tried
    as the occluder's edge: the hidden corner is where the two cut sides meet, only what lies on
    this side of the edge is read, the border must be missing behind it and the field (not the
    border) lie just this side of it.  Nearly every such view is posed (an optics' blur of
    ``soften_px`` over the box's edge too), every one within its covariance.

    "Behind it" once meant "not a pixel and a half clear on this side": a stretch of the band
    along the box's edge, half in that strip, read a quarter of the band's colour and the pad was
    refused (a moving_deck frame at 9.7 m).  Of these 40 views 31-34 were found; now 40."""
    geo = pad.geometry
    tried = found = 0
    for h in (5.0, 9.0):
        for yaw in (0.2, 1.3, 2.4, 3.5, 4.6):
            for k in range(4):
                G = tilted(0.2, -0.1, h, yaw, 0.02, -0.03)
                img, c = _box_over(warp_pad_view(pad, CAM, G, (110, 90, 60)), G, geo, k, 0.4, 0.45, soften_px=soften_px)
                tried += 1
                out, why = find_outline(img, geo, CAM)
                if out is None:
                    continue
                found += 1
                q, s = _in_order_of(out.quad_px, c)
                if out.sigma_scale is None:  # read whole (the box hid little): then every corner is right
                    scale = np.ones(4)
                    assert np.linalg.norm(q - c, axis=1).max() < 1.5, (h, yaw, k, q - c)
                else:
                    scale = np.roll(out.sigma_scale, -s)
                    assert scale[k] > 1.0 and np.all(np.delete(scale, k) == 1.0), (h, yaw, k, scale)
                    assert np.linalg.norm(np.delete(q - c, k, axis=0), axis=1).max() < 1.5, (h, yaw, k, q - c)
                pose = solve_planar_pose(CAM, geo.outer_corners, q, up_C=up_in_camera(G), sigma_px=0.3 * scale)
                err = pose.cam2pad[:3, 3] - G[:3, 3]
                assert err @ np.linalg.solve(pose.cov[:3, :3], err) < 16.3, (h, yaw, k, err)  # chi2(3), 99.9 %
    assert found >= 0.9 * tried, (found, tried)



def test_a_box_edge_across_a_sharp_pad_is_not_taken_for_motion_smear(pad):
    """A box's edge across a corner, deep into two sides, widens the edge the smear is read on: a
    sharp pad read 4.4-5.0 px of smear (a moving_deck frame at 9.7 m: 5.04 px, blur 0.06), over
    the 5 px beyond which the border's centroid places the sides, and the centroid put a corner
    7-12 px out, read whole, "ok" (the pose gates then refused it, by 0.5 px).  The smear read
    again around where the centroid put the pad (2.3-3.1 px) now decides: under 5 px the pad is
    sharp, and is read as sharp (then as partly hidden).  Every outline found has its seen corners
    within 1.5 px."""
    geo = pad.geometry
    for h, yaw, k, f1, f2 in ((9.0, 1.3, 0, 0.55, 0.2), (9.0, 1.3, 1, 0.55, 0.2), (9.0, 2.4, 0, 0.55, 0.2),
                              (9.0, 3.5, 0, 0.55, 0.2), (6.0, 1.3, 1, 0.2, 0.6)):
        G = tilted(0.2, -0.1, h, yaw, 0.02, -0.03)
        img, c = _box_over(warp_pad_view(pad, CAM, G, (110, 90, 60)), G, geo, k, f1, f2)
        out, why = find_outline(img, geo, CAM)
        if out is None:
            continue
        q, s = _in_order_of(out.quad_px, c)
        seen = np.ones(4, bool) if out.sigma_scale is None else np.roll(out.sigma_scale, -s) == 1.0
        assert np.linalg.norm(q - c, axis=1)[seen].max() < 1.5, (h, yaw, k, q - c)


def test_a_pad_whose_side_a_box_hides_is_not_read_from_its_hull(pad):
    """Where no side can be fitted and motion smears nothing, something hides a side: the hull's
    corners were then taken as the pad's (a moving_deck frame at 9.4 m, a box over two corners: one
    35 px out, the pose refused by the reprojection gate alone; here 217 of 240 such views were
    read, every one 6-19 px out).  Such a pad is now refused as read whole (and looked for as
    partly hidden).  Boxes cutting a fifth of the side or more: no outline found is wrong."""
    geo = pad.geometry
    for h in (6.0, 12.0):
        for yaw in (0.2, 2.4, 4.6):
            for k in range(4):
                for f1, f2 in ((0.2, 0.3), (0.4, 0.4)):
                    G = tilted(0.2, -0.1, h, yaw, 0.02, -0.03)
                    img, c = _box_over(warp_pad_view(pad, CAM, G, (110, 90, 60)), G, geo, k, f1, f2, corners=2)
                    out, why = find_outline(img, geo, CAM)
                    if out is not None:
                        q, _ = _in_order_of(out.quad_px, c)
                        assert np.linalg.norm(q - c, axis=1).max() < 3.0, (h, yaw, k, f1, f2, q - c)


@pytest.mark.parametrize("ground", [(150, 130, 80), (90, 110, 60)])
def test_a_far_jpeg_pad_is_named_where_colour_and_brightness_agree(pad, ground):
    """A 25-35 px pad through JPEG 50: the cue square is 3-4 px and its colour smears into the
    ground (dry grass is yellowish), so colour alone named 1 of 12 such views in 20.  JPEG keeps luma
    whole, and the yellow cue is 2.3x as bright as the border: where colour and brightness point at
    the same corner, it is named.  No view is named wrongly."""
    rng = np.random.default_rng(5)
    named = found_n = 0
    for h in (20.0, 23.0):
        for yaw in np.linspace(0.1, 2 * np.pi, 6, endpoint=False):
            G = tilted(rng.uniform(-1, 1), rng.uniform(-1, 1), h, yaw, 0.05, 0.1)
            img = warp_pad_view(pad, CAM, G, ground)
            img = _jpeg(np.clip(img + rng.normal(0, 3, img.shape), 0, 255).astype(np.uint8), 50)
            found, why = find_outline(img, pad.geometry, CAM)
            if found is None:
                continue
            found_n += 1
            det, why = name_outline(found, pad.geometry)
            if det is None:
                assert "cue is unreadable" in why, why
                continue
            named += 1
            err = np.linalg.norm(det.px - CAM.project_from(G, det.pts_P), axis=1).max()
            assert err < 0.2 * found.side_px, (h, yaw, err, det.info["yaw_from"], found.cue.round(2))  # not misnamed
    assert found_n >= 8 and named >= 0.75 * found_n, (found_n, named)


def test_brightness_alone_never_names_a_corner(pad):
    """A shadow that leaves one border corner lit and its neighbours dark makes that corner stand out
    in brightness as the cue does; with no cue colour anywhere (the cue painted over) no corner may
    be named by it."""
    geo = pad.geometry
    H, W = CAM.height, CAM.width
    for yaw in (0.3, 1.9, 3.5, 5.0):
        G = tilted(0.2, -0.3, 6.0, yaw)
        img = warp_pad_view(pad, CAM, G, GROUND)
        cv2.fillConvexPoly(img, np.round(CAM.project_from(G, geo.cue.corners)).astype(np.int32),
                           tuple(int(c) for c in geo.border.color_rgb))
        o, b = geo.outer_corners[0], geo.border_m  # TL's border square (a marker corner, not the cue's)
        square = np.array([o, o + [b, 0, 0], o + [b, -b, 0], o + [0, -b, 0]])
        lit = np.zeros((H, W), np.uint8)
        cv2.fillConvexPoly(lit, np.round(CAM.project_from(G, square)).astype(np.int32), 1)
        lit = lit.astype(bool)
        lin = (img.astype(np.float32) / 255.0) ** 2.2
        lin = np.where(lit[..., None], lin, lin * 0.3)
        img = np.clip(lin ** (1 / 2.2) * 255 + 0.5, 0, 255).astype(np.uint8)
        found, why = find_outline(img, geo, CAM)
        assert found is not None, why
        assert found.cue[1].max() > 1.0, found.cue.round(2)  # the premise: brightness says "cue" there
        det, why = name_outline(found, geo)
        assert det is None and "cue is unreadable" in why, (yaw, why, found.cue.round(2))


def test_an_outline_pose_whose_corners_are_no_square_is_rejected(pad):
    """Four corners fix a pose with two checks to spare: on a 29 px pad one corner 6.6 px out (JPEG
    smear into a dark platform side) left a reprojection RMS of 1.7 px, under the 3 px gate, and a
    pose 14 % of the height off was accepted.  The RMS over the side (here 6 %) says it; a right
    outline, or one off by a pixel, stays under 2 %."""
    from hvloc.localizer import DEFAULT_T_B_C, Estimate, FalsePoseGates

    geo = pad.geometry
    gates = FalsePoseGates(LocalizerConfig(), DEFAULT_T_B_C)
    for h, yaw in ((24.0, 0.4), (18.0, 2.2), (12.0, 4.0)):
        G = tilted(0.5, -0.4, h, yaw, 0.03, -0.02)
        det, why = detect_outline(warp_pad_view(pad, CAM, G, GROUND), geo, CAM)
        assert det is not None, why
        side = det.info["side_px"]
        verdicts = {}
        for push in (0.0, 0.04, 0.22):  # one corner moved out along the diagonal by this share of the side
            px = det.px.copy()
            px[1] += (px[1] - px.mean(axis=0)) / np.linalg.norm(px[1] - px.mean(axis=0)) * push * side
            pose = solve_planar_pose(CAM, det.pts_P, px, up_in_camera(G))
            est = Estimate(0.0, "approaching", "ok", pose.cam2pad, 4, pose.rms_px, pose.cov, method="outline",
                           extras=dict(det.info))
            verdicts[push] = (gates.check(est, None, None), pose_error(pose.cam2pad, G)[0] / h)
            gates.reset()
        assert verdicts[0.0][0] == "" and verdicts[0.04][0] == "", verdicts
        assert "no square" in verdicts[0.22][0] and verdicts[0.22][1] > 0.03, verdicts
    # a fit that did not converge says so (it read "reprojection RMS nan px > 3.0", as if measured)
    for bad in (float("nan"), float("inf")):
        est = Estimate(0.0, "approaching", "ok", pose.cam2pad, 4, bad, None, method="outline", extras=dict(det.info))
        assert gates.check(est, None, None) == f"reprojection RMS not finite ({bad}): the fit failed"


def test_a_decks_pose_whose_tilt_steps_past_the_decks_swing_is_refused():
    """On a tilting deck the IMU's up is not the pad's normal, and the vision-IMU jump holds only the
    heading: a pose whose tilt stepped 8 degrees from the last one in 0.1 s, stating half a degree,
    passed every gate while its tilt stayed within the deck's 7 degrees and the gate's 3 (branch
    exp/glare-rings's fz445 frame 73: a smeared drawing's texture pose 11.3 degrees off, 21.7 % of the
    height, after an outline pose 1.1 off).  No deck swings its tilt that fast
    (:func:`hvloc.localizer.tilt_step_refusal`): refused; a step of 1 degree is not, nor is 8 degrees
    over 2 s, nor the camera turning 8 degrees over a level pad between two frames (the step is the
    pad's, in the world)."""
    from hvloc.localizer import DEFAULT_T_B_C, Estimate, FalsePoseGates

    cfg = LocalizerConfig(pad_tilt_deg=7.0)
    G = tilted(0.2, -0.1, 3.0, 0.5)
    cov = np.diag([1e-4, 1e-4, 1e-4] + [math.radians(0.5) ** 2] * 3)

    def pose(t, tilt_deg, turn_deg=0.0):
        """A pose at ``t`` tilted ``tilt_deg`` off the level pad about its x axis, taken by a camera turned
        ``turn_deg`` about its own x axis (the IMU's attitude turned with it)."""
        cam = G.copy()
        cam[:3, :3] = G[:3, :3] @ so3_exp([math.radians(turn_deg), 0.0, 0.0])
        est = cam.copy()
        est[:3, :3] = so3_exp([math.radians(tilt_deg), 0.0, 0.0]) @ cam[:3, :3]
        return Estimate(t, "adjustment", "ok", est, 36, 0.3, cov.copy(), method="markers"), _imu_from(cam)

    def verdict(first, second):
        gates = FalsePoseGates(cfg, DEFAULT_T_B_C)
        (e0, R0), (e1, R1) = first, second
        assert gates.check(e0, R0, None) == ""
        return gates.check(e1, R1, e0)

    assert "tilt stepped 8.0 deg in 0.10 s" in verdict(pose(0.0, -2.0), pose(0.1, 6.0))
    assert verdict(pose(0.0, -2.0), pose(0.1, -1.0)) == ""
    assert verdict(pose(0.0, -2.0), pose(2.0, 6.0)) == ""
    assert verdict(pose(0.0, -2.0), pose(0.1, -2.0, turn_deg=8.0)) == ""
    # on a level pad a step is left to the whole rotation's jump (imu_jump_deg), as before
    level = FalsePoseGates(LocalizerConfig(), DEFAULT_T_B_C)
    (e0, R0), (e1, R1) = pose(0.0, -2.5), pose(0.1, 2.5)
    assert level.check(e0, R0, None) == "" and "vision-IMU rotation jumped 5.0 deg" in level.check(e1, R1, e0)


@pytest.mark.parametrize("h", [0.25, 0.5, 0.9])
def test_the_pad_is_found_by_its_own_texture_near_the_ground(pad, h):
    """A few decimetres of the field fill the view: no marker or outline fits in it.  ORB matches to
    the texture the pad was printed from, with a RANSAC homography, place the camera within a
    millimetre or two; another pad's texture (same border and markers) is never taken for it."""
    from hvloc.texture import PadTexture

    tex = PadTexture(pad)
    other = PadTexture(make_pad({"texture_seed": 99}))
    rng = np.random.default_rng(int(h * 100))
    for _ in range(3):
        G = tilted(rng.uniform(-0.25, 0.25), rng.uniform(-0.25, 0.25), h, rng.uniform(0, 2 * np.pi),
                   rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1))
        gray = cv2.cvtColor(warp_pad_view(pad, CAM, G, GROUND), cv2.COLOR_RGB2GRAY)
        det, why = tex.locate(gray, CAM)
        assert det is not None, why
        pose = solve_planar_pose(CAM, det.pts_P, det.px, up_in_camera(G))
        dp, da = pose_error(pose.cam2pad, G)
        assert dp < 0.001 + 0.005 * h and da < 0.5, (dp, da, det.info)
        det, why = other.locate(gray, CAM)
        assert det is None and "agree on a homography" in why, why


def test_a_landed_drone_in_its_own_shadow_finds_the_pad_by_its_texture_magnified_fivefold():
    """At 0.12-0.2 m a 75 degree lens sees a pad printed at 1000 px/m magnified 3.3-5.6 times: the
    frame's shrunk ORB levels held 8-15 agreeing matches and the pad was never found again once the
    flow's chain had broken (unseen87: every touchdown frame lost).  The frame is shrunk for ORB
    (by the height where known, else tried at 4-fold too), and the drawing that refines the
    matches is lit as the frame is: in the drone's shadow (a third of the light) the white drawing
    drifted Lucas-Kanade 150 px, and the unrefined matches were 2-5 mm and 0.1-1.2 degrees off.
    Another pad's texture is still never taken for it."""
    from hvloc.texture import PadTexture

    pad = make_pad(ppm=1000.0)
    tex, other = PadTexture(pad), PadTexture(make_pad({"texture_seed": 99}, ppm=1000.0))
    cam = Camera.from_hfov(1024, 768, math.radians(75))
    rng = np.random.default_rng(11)
    for h in (0.12, 0.15, 0.2, 0.28):
        for light in (1.0, 0.35):
            G = tilted(rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2), h, rng.uniform(0, 2 * np.pi), 0.04, -0.03)
            gray = cv2.cvtColor((warp_pad_view(pad, cam, G, GROUND) * light).astype(np.uint8), cv2.COLOR_RGB2GRAY)
            for known in (h, None):
                det, why = tex.locate(gray, cam, known)
                assert det is not None and "refined" in det.info, (h, light, known, why)
                dp, da = pose_error(solve_planar_pose(cam, det.pts_P, det.px, up_in_camera(G)).cam2pad, G)
                assert dp < 0.0005 and da < 0.1, (h, light, known, dp, da)
                assert other.locate(gray, cam, known)[0] is None


def test_unrefined_texture_keypoints_are_as_noisy_as_their_fit_shows(pad):
    """ORB's keypoints that no drawing refined are each placed on a pyramid's grid and anywhere
    along a smear: unseen85's 26 at 0.2 m fitted at 2.2 px and were stated at the found corners'
    0.3 px (3.9 mm off, NEES 27).  Their pose's noise is their fit's residual: over 40 draws of 25
    keypoints 3 px off at 0.25 m the NEES is chi-square's (median 2.37 for 3 degrees of freedom,
    1 % beyond 11.34); stated at the corners' noise (the same points said to be refined), the
    median was 4.6 and 5 of 40 lay beyond."""
    from hvloc.phases import Detection

    rng = np.random.default_rng(4)
    G = tilted(0.05, -0.08, 0.25, 0.6, 0.03, -0.02)
    nees = {True: [], False: []}
    for _ in range(40):
        P = np.c_[rng.uniform(-0.12, 0.12, (25, 2)) + G[:2, 3], np.zeros(25)]
        px = CAM.project_from(G, P) + rng.normal(0.0, 3.0, (25, 2))
        for refined in (False, True):
            info = {"matches": 60, "inliers": 25, **({"refined": 25} if refined else {})}
            loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig())
            (pose, _, _), why = loc._posed(Detection(P, px, "texture", info), "ok", None, up_in_camera(G), False)
            e = pose.cam2pad[:3, 3] - G[:3, 3]
            nees[refined].append(float(e @ np.linalg.solve(pose.cov[:3, :3], e)))
    weighed, stated = np.array(nees[False]), np.array(nees[True])
    assert 1.2 < np.median(weighed) < 3.5 and np.sum(weighed > 11.34) <= 2, np.round(np.sort(weighed), 1)
    assert np.median(stated) > 3.5  # the scene is one the corners' noise does not state


def test_a_view_of_two_hundredths_of_the_pad_is_found_among_every_feature_of_its_square():
    """A 55 degree 1080p lens at 0.13-0.18 m sees 1.3-2.6 % of the default pad (0.85 m printed at
    2000 px/m): the texture's 6000 features spread over the whole pad left 20-25 agreeing matches
    in 3 of 8 such views and none in the others (unseen88: 13 of 14 landed frames lost), and the
    drawing those few put up to ~50 px off refined 0.5-1.3 mm and 0.5 degrees off.  Matched to
    every feature of each square of the pad a view fits in, and drawn again where the first
    tracks put it, 6 of the 8 are found (the other two see a few large shapes: 11-17 agreeing),
    each within 0.3 mm and 0.1 degrees; another pad's texture is never taken for it.  Drawn in
    display values (``in_light=False``), where this was measured: summed in light a found view was
    up to 0.55 mm and 0.22 degrees off (open: README, "Mixing in light")."""
    from hvloc.texture import PadTexture

    pad = make_pad()
    tex, other = PadTexture(pad), PadTexture(make_pad({"texture_seed": 99}))
    cam = Camera.from_hfov(1920, 1080, math.radians(55))
    rng = np.random.default_rng(8)
    found = 0
    for _ in range(8):
        h = rng.uniform(0.13, 0.18)
        G = tilted(rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), h, rng.uniform(0, 2 * np.pi), 0.04, -0.03)
        gray = cv2.cvtColor(warp_pad_view(pad, cam, G, GROUND, supersample=1, in_light=False), cv2.COLOR_RGB2GRAY)
        det, why = tex.locate(gray, cam, h)
        assert other.locate(gray, cam, h)[0] is None
        if det is None:
            continue
        found += 1
        dp, da = pose_error(solve_planar_pose(cam, det.pts_P, det.px, up_in_camera(G)).cam2pad, G)
        assert "refined" in det.info and dp < 0.0003 and da < 0.1, (h, det.info, dp, da)
    assert found >= 6, found


def test_a_drone_lost_near_the_ground_is_found_lower_than_its_last_pose_said():
    """After a loss near the ground the height the localizer knows is the last pose's, and the
    drone has come down since (unseen88: lost at 0.26 m, back in view at 0.17-0.19 m).  A 55 degree
    1080p lens at 0.15-0.18 m magnifies the default pad's texture 5-6 times: the frame must be
    shrunk 4-fold for ORB, and the squares of the pad cut for so small a view; at the last pose's
    height it was shrunk 2-fold, and 3 of 8 such views were found.  Tried also as low as half that
    height, those of the 8 that the true height finds are found (6), each within 0.3 mm.  The
    localizer asks for it once a frame has gone without a pose: lost for two frames after a pose
    at 0.26 m, it poses such a view by the texture."""
    from hvloc.texture import PadTexture

    pad = make_pad()
    tex = PadTexture(pad)
    cam = Camera.from_hfov(1920, 1080, math.radians(55))
    rng = np.random.default_rng(11)
    stale = lowest = true = 0
    views = []
    for _ in range(8):
        h = rng.uniform(0.15, 0.18)
        G = tilted(rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), h, rng.uniform(0, 2 * np.pi), 0.04, -0.03)
        view = warp_pad_view(pad, cam, G, GROUND, supersample=1)
        gray = cv2.cvtColor(view, cv2.COLOR_RGB2GRAY)
        stale += tex.locate(gray, cam, 0.26)[0] is not None
        true += tex.locate(gray, cam, h)[0] is not None
        det, why = tex.locate(gray, cam, 0.26, lowest=0.13)
        if det is None:
            continue
        lowest += 1
        views.append((G, view))
        dp, da = pose_error(solve_planar_pose(cam, det.pts_P, det.px, up_in_camera(G)).cam2pad, G)
        assert dp < 0.0003 and da < 0.1, (h, dp, da)
    assert stale <= 4 and lowest == true >= 6, (stale, lowest, true)

    # the localizer: posed at 0.26 m, two frames lost (the ground alone), then a view at 0.15-0.18 m
    G0 = tilted(0.0, 0.0, 0.26, 0.3, 0.02, -0.01)
    first = warp_pad_view(pad, cam, G0, GROUND, supersample=1)
    blank = np.full((cam.height, cam.width, 3), GROUND, np.uint8)
    posed = 0
    for G, view in views[:3]:
        loc = HierarchicalLocalizer(pad, cam, LocalizerConfig())
        assert loc.process(first, 0.0, _imu_from(G0)).ok
        for k in (1, 2):
            assert not loc.process(blank, 0.1 * k, _imu_from(G0)).ok
        e = loc.process(view, 0.3, _imu_from(G))
        assert e.ok and e.method == "texture", e.reason
        posed += 1
        assert pose_error(e.cam2pad, G)[0] < 0.001
    assert posed == 3


def test_a_smeared_view_in_a_shadow_is_refined_against_the_texture_drawn_smeared_alike():
    """Under a gust's smear (23-28 px at 0.18-0.3 m: 0.4 m/s sideways in a 25 ms exposure, a 90
    degree lens over a pad printed at 1000 px/m) with the drone's shadow across two thirds of the
    view, ORB's matches refined against the sharp drawing were 0.3-2.5 mm and up to 0.44 degrees
    off (unseen85: 3.9 mm off at 0.2 m, stating 1 % of it in scale).  Drawn smeared as the motion
    smears it, and lit as the frame is square by square, the texture's corners track into the frame
    and the pose is within 0.3 mm and 0.05 degrees."""
    from hvloc.shutter import Twist
    from hvloc.texture import PadTexture

    pad = make_pad(ppm=1000.0)
    tex = PadTexture(pad)
    cam = Camera.from_hfov(1280, 720, math.radians(90))
    rng = np.random.default_rng(5)
    exposure = 0.025
    yy, xx = np.mgrid[0:cam.height, 0:cam.width]
    shadow = np.where(yy > 200 + 0.3 * xx, 0.3, 1.0)[..., None]  # a third of the light below a slanted edge
    sharp_worst = 0.0
    for _ in range(4):
        h = rng.uniform(0.18, 0.3)
        G = tilted(rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2), h, rng.uniform(0, 2 * np.pi), 0.05, -0.03)
        a = rng.uniform(0, 2 * np.pi)
        v = np.array([0.4 * math.cos(a), 0.4 * math.sin(a), -0.13])
        view = _motion_blurred(pad, G, v * exposure, GROUND, n=16, cam=cam, supersample=1)
        gray = cv2.cvtColor(_srgb(_linear(view) * shadow), cv2.COLOR_RGB2GRAY)
        det, why = tex.locate(gray, cam, h)
        assert det is not None, why
        start = solve_planar_pose(cam, det.pts_P, det.px, up_C=up_in_camera(G))
        sharp_worst = max(sharp_worst, pose_error(start.cam2pad, G)[0])
        smear = cam.fx * 0.4 * exposure / h
        found, why = tex.refined_under(gray, cam, start.cam2pad, Twist(v, None), exposure, 6.0 + 0.5 * smear)
        assert found is not None and found.info["refined"] >= 20 and found.info["smeared_px"] > 20, why
        dp, da = pose_error(solve_planar_pose(cam, found.pts_P, found.px, up_C=up_in_camera(G)).cam2pad, G)
        assert dp < 0.0003 and da < 0.05, (h, dp, da)
    assert sharp_worst > 0.001  # the scene is one the sharp drawing does not refine


def test_a_smeared_drawing_through_a_lens_is_its_instants_drawn_pixel_by_pixel():
    """Through a lens, each instant of a smeared drawing had every pixel carried to the texture
    (12 ms an instant at 1280x720, 190 ms a refinement of 8 instants drawn twice).  The instants
    are now drawn in the texture's own plane and the sum taken through the lens once: the same
    drawing as every instant carried pixel by pixel (a 100 degree barrel lens at 0.22 m, 0.5 m/s
    and a turn over a 25 ms exposure, 31 px of smear), to a small fraction of its contrast, and
    the same pixels counted on the pad."""
    from hvloc.features import srgb_to_linear
    from hvloc.geometry import pad_plane_homography
    from hvloc.shutter import Twist
    from hvloc.texture import PadTexture
    from pad_design.texture import texture_to_pad

    pad = make_pad(ppm=1000.0)
    tex = PadTexture(pad)
    cam = Camera.from_hfov(1280, 720, math.radians(100), dist=(-0.22, 0.04, 0, 0, 0))
    G = tilted(0.1, -0.05, 0.22, 0.7, 0.06, -0.04)
    motion = Twist(np.array([0.4, -0.3, -0.1]), np.array([0.2, -0.1, 0.3]))
    taus = np.linspace(0.0, 0.025, 8)  # (not centred on the frame's pose: a motion drawn backwards would not pass)
    Hs = [pad_plane_homography(cam, motion.moved(G, tau)) for tau in taus]
    ends = [cv2.perspectiveTransform(np.array([[[0.0, 0.0]]]), Hk)[0, 0] for Hk in (Hs[0], Hs[-1])]
    smear = float(np.linalg.norm(ends[1] - ends[0]))  # the pad's centre's, px (ideal)
    assert smear > 25, smear
    level = 0
    lin = srgb_to_linear(tex.levels[level])
    A = texture_to_pad(pad.side_m, pad.ppm / 2**level)
    edge = np.ones(lin.shape, np.uint8)
    edge[:2], edge[-2:], edge[:, :2], edge[:, -2:] = 0, 0, 0, 0
    acc, inside = tex._through_lens(cam, lin, edge, [Hk @ A for Hk in Hs], pad_plane_homography(cam, G) @ A)
    grid = cam.ideal_pixel_grid()
    ref, ref_in = np.zeros(acc.shape, np.float32), np.ones(acc.shape, np.uint8)
    for Hk in Hs:
        uv = cv2.perspectiveTransform(grid.reshape(-1, 1, 2), np.linalg.inv(Hk @ A)).reshape(*acc.shape, 2).astype(np.float32)
        ref += cv2.remap(lin, uv[..., 0], uv[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        ref_in &= cv2.remap(edge, uv[..., 0], uv[..., 1], cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT)
    assert ref_in.mean() > 0.5 and np.mean(inside != ref_in) < 0.002, (ref_in.mean(), np.mean(inside != ref_in))
    both = cv2.erode(inside & ref_in, np.ones((5, 5), np.uint8)) > 0
    diff = np.abs(acc - ref)[both] / len(Hs)
    contrast = float(np.std(ref[both] / len(Hs)))
    assert np.mean(diff) < 0.02 * contrast and np.percentile(diff, 99) < 0.15 * contrast, (
        np.mean(diff), np.percentile(diff, 99), contrast)


def test_a_start_near_the_ground_is_posed_by_the_texture_and_tracked_on(pad):
    """A localizer that starts (or is reset by a gap in time) at 0.35 m sees neither markers nor an
    outline; it stayed lost in Approaching for good.  The texture poses the first frame, the phases
    follow the height, and the flow tracker carries on from it.  With no pad in view and no height
    known, the texture is tried on every 4th frame only."""
    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig())
    blank = np.full((CAM.height, CAM.width, 3), GROUND, np.uint8)
    tried = []
    for k in range(8):
        e = loc.process(blank, 0.1 * k, None)
        assert e.status == "lost"
        tried.append("texture:" in e.reason)
    assert tried == [True, False, False, False, True, False, False, False], tried
    methods = []
    for k in range(10):
        G = tilted(0.05 + 0.004 * k, -0.1, 0.35 - 0.01 * k, 0.8 + 0.01 * k, 0.02, -0.01)
        e = loc.process(warp_pad_view(pad, CAM, G, GROUND), 1.0 + 0.1 * k, _imu_from(G))
        assert e.ok, (k, e.reason)
        dp, da = pose_error(e.cam2pad, G)
        assert dp < 0.004 and da < 0.5, (k, e.method, dp, da)
        methods.append(e.method)
    assert methods[0] == "texture" and "flow" in methods[1:], methods


def _tilting_deck_touchdown(loc, view_pad, cam, n=24):
    """A touchdown from 0.95 m on a deck that rolls 7 and pitches 4 degrees (periods 5 and 6 s), 10
    frames a second, each 7 % nearer: ``[(estimate, truth), ...]``; the IMU's up is the world's."""
    out = []
    for k in range(n):
        t = 0.1 * k
        G = tilted(0.05 + 0.01 * k, -0.04 + 0.004 * k, 0.95 * 0.93**k, 0.6 + 0.02 * k, 0.03 * math.sin(k / 3), -0.02)
        deck = so3_exp([math.radians(7.0) * math.sin(2 * math.pi * t / 5), math.radians(4.0) * math.cos(2 * math.pi * t / 6), 0.0])
        out.append((loc.process(warp_pad_view(view_pad, cam, G, GROUND), t, _imu_from(G, extra=deck)), G))
    return out


def test_a_chained_keyframe_on_a_tilting_deck_is_anchored_again_by_the_texture_placed_at_the_flows_pose(pad):
    """Near the ground the flow renews its keyframe from its own pose every two or three frames, and
    each renewal adds that pose's error to the chain: on a tilting deck the IMU's up holds nothing,
    and on the smoke deck a chain of 12 renewals from 0.77 m drifted 0.7-1.2 degrees, 5-9 mm
    sideways at 0.3-0.45 m.  The first flow pose of a chained keyframe now has the pad's texture
    drawn where it puts the pad and tracked into the frame (no ORB); where that pose agrees with
    the flow's and is surer than the keyframe, it is the frame's pose and anchors the next keyframe.
    Here: every third frame from the first renewal on, each keyframe after it anchored; below 0.4 m
    every pose within 0.3 mm (the chain alone, the texture off: 0.8-1.2 mm, 0.1-0.2 degrees).  Another
    pad's texture (the same border and markers) is never taken: there the chain carries on alone."""
    cam = Camera.from_hfov(480, 480, math.radians(60))
    cfg = LocalizerConfig(pad_tilt_deg=10.0)
    runs = {}
    for name, c, view_pad in (("texture", cfg, pad), ("chain", cfg.model_copy(update={"use_texture": False}), pad),
                              ("other", cfg, make_pad({"texture_seed": 11}))):
        loc = HierarchicalLocalizer(pad, cam, c)
        runs[name] = _tilting_deck_touchdown(loc, view_pad, cam)
        assert all(e.ok for e, _ in runs[name]), (name, [(k, e.reason) for k, (e, _) in enumerate(runs[name]) if not e.ok])
    methods = [e.method for e, _ in runs["texture"]]
    assert methods[:3] == ["markers", "markers", "flow"] and methods[3::3] == ["texture"] * 7, methods
    assert all(e.extras.get("over_flow") for e, _ in runs["texture"][3::3])
    near = {name: np.array([pose_error(e.cam2pad, G)[0] for e, G in run if G[2, 3] < 0.4]) for name, run in runs.items()}
    assert near["texture"].max() < 0.0003, near["texture"]
    assert np.median(near["chain"]) > 3.0 * np.median(near["texture"]), (near["chain"], near["texture"])
    assert {e.method for e, _ in runs["other"][2:]} == {"flow"}
    assert near["other"].max() < 0.003, near["other"]  # (1.3-2.1 mm: the chain's, on that texture)


def test_the_ahrs_roll_pitch_error_is_learnt_and_taken_out(pad):
    """An AHRS whose gravity is 0.4 degrees off (body frame, constant over the run): the gravity
    prior pulls marker poses with it (35 mm sideways at 5 m when the prior outweighed the markers;
    ~11 mm now that it is weighed against their own noise).  The image-only tilts of the marker
    poses, averaged, find that error and it is taken out of the attitude: the last poses are
    closer still, and the learnt error is the injected one to a tenth of a degree.  (Opt-in:
    ``ahrs_bias_time_s`` is 0 by default.)"""
    err = np.radians([0.4, -0.25, 0.0])
    lateral = {}
    for tau in (0.0, 5.0):
        loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(ahrs_bias_time_s=tau))
        errs = []
        for k in range(30):
            G = tilted(0.2 + 0.01 * k, -0.1, 5.0 - 0.03 * k, 0.3 + 0.02 * k, 0.04 * math.sin(k / 4), 0.03)
            R_W_B = _imu_from(G) @ so3_exp(err)  # the AHRS: true attitude times its error
            e = loc.process(warp_pad_view(pad, CAM, G, GROUND), 0.1 * k, R_W_B)
            assert e.ok and (k == 0 or e.method == "markers"), (k, e.method, e.reason)
            errs.append(np.linalg.norm((e.cam2pad[:3, 3] - G[:3, 3])[:2]))
        lateral[tau] = float(np.mean(errs[-10:]))
        if tau:
            assert np.degrees(np.abs(loc.ahrs.estimate[:2] - err[:2])).max() < 0.1, np.degrees(loc.ahrs.estimate)
    assert lateral[0.0] > 0.008 and lateral[5.0] < lateral[0.0] / 1.5, lateral


def test_the_ahrs_tilt_filter_follows_a_drifting_error_and_says_how_well_it_knows_it():
    """The AHRS's error drifts (here 0.35 degrees turning over tens of seconds) while the image's
    view of the pad's normal sharpens as the camera descends (1 degree a frame, then 0.5, then
    0.05, independent from frame to frame).  The filter's estimate follows the drift: over the
    last two thirds it is several times closer than the raw AHRS, and its stated sigma is honest
    (errors over sigma neither far above nor far below 1).  A normal 5 degrees off is a bad fit
    and is not taken."""
    from hvloc.localizer import AHRSTiltBias

    rng = np.random.default_rng(3)
    f = AHRSTiltBias(10.0)
    z = np.array([0.0, 0.0, 1.0])
    raw, left, ratio = [], [], []
    for k in range(900):  # 30 s at 30 Hz
        t = k / 30.0
        e = np.radians(0.35) * np.array([math.cos(t / 9.0), math.sin(t / 13.0 + 0.5), 0.0])
        s = 1.0 if t < 10 else 0.5 if t < 20 else 0.05
        n = so3_exp(np.radians(s) * np.append(rng.normal(size=2), 0.0)) @ z  # the image's normal, camera = body
        f.update(so3_exp(e), np.eye(3), n, s, t)  # AHRS = true (level) @ exp(e)
        if t >= 10:
            raw.append(np.degrees(np.abs(e[:2])))
            left.append(np.degrees(np.abs(f.estimate[:2] - e[:2])))
            ratio.append(left[-1] / math.hypot(f.sigma_deg, f.white_deg))
    raw, left, ratio = np.array(raw), np.array(left), np.array(ratio)
    assert np.sqrt(np.mean(left**2)) < np.sqrt(np.mean(raw**2)) / 3.0, (np.sqrt(np.mean(left**2)), np.sqrt(np.mean(raw**2)))
    assert np.sqrt(np.mean(left[-150:] ** 2)) < 0.03, np.sqrt(np.mean(left[-150:] ** 2))
    assert 0.3 < np.sqrt(np.mean(ratio**2)) < 1.5, np.sqrt(np.mean(ratio**2))
    before = f.estimate.copy()
    f.update(so3_exp(np.zeros(3)), np.eye(3), so3_exp(np.radians([5.0, 0.0, 0.0])) @ z, 0.05, t)  # at the same time: no drift
    assert np.allclose(f.estimate, before), np.degrees(f.estimate - before)


def test_the_ahrs_tilt_filter_weighs_both_planar_solutions_where_the_image_cannot_tell_them_apart():
    """A pad seen nearly along its normal: the image knows the normal's part across the line of
    sight only up to its sign, and the AHRS's up picks one of the two.  The picked normal is then
    pushed away from the line of sight by the noise's magnitude, the same way every frame.  Taken
    as the measurement, the filter learns that push (here it ends further off than the raw AHRS);
    with the mirror and its fit given, the two are weighed as a Gaussian sum and the filter ends
    closer than the raw AHRS, its sigma covering what is left.  A mirror the image rules out (the
    pad 10 degrees off the line of sight, its mirror 20 degrees away fitting far worse) changes
    nothing; one that fits as well that far away makes the normal count as flat as that, and the
    filter is not misled."""
    from hvloc.localizer import AHRSTiltBias

    z = np.array([0.0, 0.0, 1.0])
    e = np.radians([0.3, -0.2, 0.0])  # the AHRS's error
    R_ahrs = so3_exp(e)  # AHRS = true (level) @ exp(e); camera = body
    up = R_ahrs.T @ z

    def learn(off_deg, with_mirror, seed, gap=0.0):
        rng = np.random.default_rng(seed)
        v = so3_exp(np.radians([off_deg, 0.0, 0.0])) @ z  # the line of sight to the pad
        f = AHRSTiltBias(10.0)
        left = []
        for k in range(600):  # 60 s at 10 Hz, 1 degree of noise per frame (markers at 6-10 m)
            n = so3_exp(np.radians(1.0) * np.append(rng.normal(size=2), 0.0)) @ z
            m = 2.0 * (n @ v) * v - n  # the mirror about the line of sight
            pick, other = (n, m) if n @ up >= m @ up else (m, n)
            f.update(R_ahrs, np.eye(3), pick, 1.0, k / 10.0, *((other, gap) if with_mirror else ()))
            if k >= 300:
                left.append(np.degrees(f.estimate[:2] - e[:2]))
        return float(np.sqrt(np.mean(np.square(left)))), f.sigma_deg

    raw = float(np.sqrt(np.mean(np.degrees(e[:2]) ** 2)))  # 0.25 degrees per axis
    for seed in (1, 2, 3):
        picked, _ = learn(0.0, False, seed)
        both, sigma = learn(0.0, True, seed)
        assert picked > raw, (seed, picked, raw)
        assert both < 0.8 * raw and both < 1.5 * math.hypot(sigma, AHRSTiltBias(10.0).white_deg), (seed, both, sigma, raw)
        assert learn(10.0, True, seed, gap=1e4) == learn(10.0, False, seed)
        assert learn(10.0, True, seed)[0] < raw


def test_clean_markers_outweigh_an_ahrs_a_few_tenths_off(pad):
    """Three markers' corners fit to ~0.1 px on a clean image, and the image alone knows the pad's
    tilt to a few hundredths of a degree; the gravity prior (0.5 degrees) was weighed against the
    0.3 px floor every found corner gets, and carried an AHRS 0.47 degrees off into the position
    almost whole (lateral error 0.8 x height x tan(error) in the median).  Weighed against three
    times the markers' own residual, the image's tilt counts: ~0.5 of it is left."""
    err = np.radians([0.4, -0.25, 0.0])
    pulled = []
    for k in range(12):
        G = tilted(0.2 + 0.01 * k, -0.1, 5.0 - 0.1 * k, 0.3 + 0.2 * k, 0.04 * math.sin(k), 0.03)
        loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig())
        loc.phase = "adjustment"
        e = loc.process(warp_pad_view(pad, CAM, G, GROUND), 0.0, _imu_from(G) @ so3_exp(err))
        assert e.ok and e.method == "markers", (k, e.method, e.reason)
        pulled.append(np.linalg.norm((e.cam2pad[:3, 3] - G[:3, 3])[:2]) / (G[2, 3] * math.tan(np.linalg.norm(err))))
    assert np.median(pulled) < 0.65, np.round(pulled, 2)


def test_an_ahrs_stated_as_good_is_trusted_as_good_and_the_covariance_says_so(pad):
    """At 6.5-9 m three markers or the outline's corners know the pad's tilt to about a degree; an
    AHRS 0.1 degrees off is better than that, and a localizer told so (``ahrs_tilt_sigma_deg``) keeps
    its tilt: the lateral error is then the AHRS's, the same on every view, and the covariance states
    about that much.  Told the default 0.5 degrees, the image's noise leaks into the tilt and the
    stated sigma is several times the error made (bench_v1 with its AHRS's error scaled to a third:
    field1080 Adjustment 16.1 mm told 0.5)."""
    err = np.radians([0.08, -0.06, 0.0])
    tan_err = math.tan(float(np.linalg.norm(err)))
    got = {}
    for s in (0.5, 0.1):
        lat, stated = [], []
        for k in range(8):
            G = tilted(0.3 - 0.05 * k, 0.2, 6.5 + 0.3 * k, 0.4 + 0.5 * k, 0.03 * math.sin(k), 0.02)
            img = warp_pad_view(pad, CAM, G, GROUND).astype(np.float32)
            img = np.clip(img + np.random.default_rng(k).normal(0.0, 6.0, img.shape), 0, 255).astype(np.uint8)
            loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(ahrs_tilt_sigma_deg=s))
            loc.phase = "adjustment"
            e = loc.process(img, 0.0, _imu_from(G) @ so3_exp(err))
            assert e.ok, (s, k, e.reason)
            lat.append(np.linalg.norm((e.cam2pad[:3, 3] - G[:3, 3])[:2]) / G[2, 3])
            stated.append(math.sqrt(e.cov[0, 0] + e.cov[1, 1]) / G[2, 3])
        got[s] = np.array(lat), np.array(stated)
    (lat5, st5), (lat1, st1) = got[0.5], got[0.1]
    # the AHRS's tilt, every view (within a fifth: a 64-100 px pad's design fitted with its tilt,
    # hvloc.texfit.GLOBAL_MAX_SIDE_PX, weighs its own view of it against the AHRS's 0.1 degrees)
    assert np.abs(lat1 / tan_err - 1.0).max() < 0.25, lat1 / tan_err
    assert np.std(lat1) < 0.5 * np.std(lat5), (np.std(lat1), np.std(lat5))
    assert 0.4 < np.median(lat1 / st1) < 1.5 and np.median(lat5 / st5) < 0.3, (lat1 / st1, lat5 / st5)


def test_markers_noise_is_weighed_within_one_solve(pad, monkeypatch):
    """The gravity prior of a markers pose is weighed against k x the image-only fit's residual.
    That fit is made inside every solve anyway, so the weighing is done there (``sigma_from_fit``),
    and gives exactly what solving again with that noise gives; a clean three-marker frame then
    costs two pose solves (the joint one and the markers alone, which judges the outer corners),
    not three."""
    import hvloc.localizer as L

    G = tilted(0.2, -0.1, 3.0, 0.7, 0.03, -0.02)
    img = warp_pad_view(pad, CAM, G, GROUND)
    up = up_in_camera(G) + np.array([0.004, -0.003, 0.0])  # an AHRS ~0.3 degrees off
    det, why = detect_markers(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), pad.geometry, CAM, rgb=img)
    assert det is not None, why
    one = solve_planar_pose(CAM, det.pts_P, det.px, up_C=up, sigma_from_fit=(3.0, 0.1))
    s = max(3.0 * one.image_rms_px, 0.1)
    two = solve_planar_pose(CAM, det.pts_P, det.px, up_C=up, sigma_px=s)
    assert one.sigma_px == s and abs(s - 0.3) > 0.05, (s, one.sigma_px)
    assert np.allclose(one.cam2pad, two.cam2pad, atol=1e-12) and np.allclose(one.cov, two.cov, rtol=1e-9)
    assert one.tilt_sigma_deg == two.tilt_sigma_deg
    calls = []
    real = L.solve_planar_pose
    monkeypatch.setattr(L, "solve_planar_pose", lambda *a, **k: calls.append(k.get("sigma_from_fit")) or real(*a, **k))
    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig())
    loc.phase = "adjustment"
    e = loc.process(img, 0.0, _imu_from(G))
    assert e.ok and e.method == "markers" and "outer_dropped_px" not in e.extras, (e.method, e.reason, e.extras)
    assert calls == [(3.0, 0.1), None], calls
    assert e.extras["px_sigma"] == round(s, 3)  # the image-only fit does not depend on the IMU


def _markers_with_shared_errors(pad, names, rng, own_px, shared_px):
    """A view's marker corners (markers ``names``) with each point's own noise and, per marker, a
    shift and a swell its corners share; the true pose and the AHRS's up (0.5 degrees off per axis)."""
    ms = [m for m in pad.geometry.markers if m.name in names]
    pts = np.concatenate([m.points for m in ms])
    group = np.repeat(np.arange(len(ms)), [len(m.points) for m in ms])
    G = tilted(rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2), rng.uniform(1.0, 2.0), rng.uniform(0, 2 * math.pi),
               0.05, -0.03)
    px = CAM.project_from(G, pts) + rng.normal(0.0, own_px, (len(pts), 2))
    for g in range(len(ms)):
        d = px[group == g] - px[group == g].mean(axis=0)
        px[group == g] += rng.normal(0.0, shared_px, 2) + rng.normal(0.0, shared_px) * d / np.sqrt(np.mean(np.sum(d * d, 1)))
    up = so3_exp(np.append(rng.normal(0.0, math.radians(0.5), 2), 0.0)) @ up_in_camera(G)
    return G, pts, px, group, up


def _nees(pose, G):
    e = pose.cam2pad[:3, 3] - G[:3, 3]
    return float(e @ np.linalg.solve(pose.cov[:3, :3], e))


def test_shared_marker_errors_are_in_the_pose_covariance():
    """A marker's corners share errors (blur across it, JPEG's blocks, a threshold a little off move
    or swell them together), and two markers' relative size is what fixes the tilt between them.
    With each corner's noise alone the covariance read that tilt ~3x too sure: 28 % of such poses
    lay beyond its 3 sigma (NEES median 9).  With the shared shift and swell in the noise model the
    poses are as far off as their covariance says (NEES is chi-square with 3 dof: median 2.4)."""
    from hvloc.pose import SharedNoise

    rng = np.random.default_rng(7)
    pad = make_pad()
    nees = {False: [], True: []}
    for _ in range(150):
        G, pts, px, group, up = _markers_with_shared_errors(pad, ("Top", "Right"), rng, 0.3, 0.3)
        for shared in nees:
            res = solve_planar_pose(CAM, pts, px, up_C=up, sigma_px=0.3,
                                    shared=SharedNoise(group, 0.3, 0.3) if shared else None)
            nees[shared].append(_nees(res, G))
    assert np.median(nees[False]) > 5.0, np.median(nees[False])
    assert 1.5 < np.median(nees[True]) < 3.5 and np.mean(np.array(nees[True]) > 14.16) < 0.03, np.median(nees[True])


@pytest.mark.parametrize("names, shared_px, pull_px", [(("Top", "Right"), 0.3, 0.0), (("Top", "Right", "Bottom"), 1.0, 4.0)])
def test_a_pose_of_two_markers_says_how_good_it_is(pad, names, shared_px, pull_px):
    """Two markers' pose is not weighed by its residual (too few markers to show the noise): its
    corners get the 0.3 px floor and the errors they share (``MARKER_SHARED_PER_SIGMA`` of it).  When a third
    marker is left out for being off (here 4 px: blur or a lens moved it), the errors that moved
    it reached the other two as well: in the blurred 1080p scenes the markers kept were 1-2 px
    off, and their poses' tilt 1-2.4 degrees out with an AHRS 0.2-0.6 degrees out (NEES 30-200).
    The pose then takes as much shared error as that marker shows, and leans on the AHRS."""
    rng = np.random.default_rng(3)
    nees, lateral, dropped = [], [], []
    for _ in range(120):
        G, pts, px, group, up = _markers_with_shared_errors(pad, names, rng, 0.15, shared_px)
        px[group == 2] += pull_px * np.array([0.8, 0.6])
        loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig())
        (pose, _, info), why = loc._posed(Detection(pts, px, "markers", {}), "ok", None, up, None)
        dropped.append("marker_dropped" in info)
        nees.append(_nees(pose, G))
        lateral.append(np.linalg.norm((pose.cam2pad[:3, 3] - G[:3, 3])[:2]))
    assert np.mean(dropped) > 0.7 if pull_px else not any(dropped), np.mean(dropped)  # (some pulls look like a tilt)
    two = np.array(dropped) if pull_px else np.ones(len(nees), bool)  # the poses of two markers
    nees, lateral = np.array(nees)[two], np.array(lateral)[two]
    assert np.median(nees) < 3.5 and np.mean(nees > 14.16) < 0.05, (np.median(nees), np.mean(nees > 14.16))
    assert np.median(lateral) < 0.016, np.median(lateral)


def test_markers_inner_squares_are_predicted_through_the_lens(pad):
    """A marker's inner squares are predicted from its outer corners by a homography and refined
    within a few pixels.  The homography holds on the ideal pinhole's pixels, not the lens's: under
    a 110 degree lens (k1 -0.25) a close, oblique view put them up to 14 px off on bench_v2's wide
    oblique dusk scene, further than the refinement reaches, and it settled on the wrong edges
    (poses 6-15 mm off at 0.5 m, stated 3 mm).  Predicted through the lens, every corner found
    (the pad's outer ones too, predicted the same way) is within a fraction of a pixel of its label."""
    import dataclasses

    cam = dataclasses.replace(Camera.from_hfov(1280, 720, math.radians(110)), dist=(-0.25, 0.05, 0, 0, 0))
    rng = np.random.default_rng(1)
    worst, found = [], []
    for _ in range(10):
        h, a = rng.uniform(0.45, 0.7), rng.uniform(0, 2 * math.pi)
        d = h * math.tan(rng.uniform(0.5, 0.7))  # seen 29-40 degrees off its normal
        G = look_at_cam2world([d * math.cos(a), d * math.sin(a), h], np.append(rng.uniform(-0.1, 0.1, 2), 0.0), (0, 0, 1))
        img = warp_pad_view(pad, cam, G, GROUND)
        det, why = detect_markers(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), pad.geometry, cam, rgb=img, up_C=up_in_camera(G))
        if det is None:
            continue
        worst.append(float(np.linalg.norm(det.px - cam.project_from(G, det.pts_P), axis=1).max()))
        found.append(len(det.px))
    assert len(worst) >= 8, len(worst)
    assert max(worst) < 0.8 and min(found) >= 36, (np.round(worst, 2), found)


def test_outer_corners_smeared_by_jpeg_chroma_leave_the_markers_pose(pad):
    """JPEG keeps chroma at half resolution: the pad's outer corners, fitted on the border's colour,
    come out ~0.5 px outward while the markers' corners, on luma, stay at ~0.1 px.  Joined to the
    markers they tilted the pose (conditions' wide_jpeg at 1.5-6 m: 0.39 degrees off in the median
    with them, 0.14 without; lateral RMS 37.5 -> 16.3 mm).  Judged by the markers' own fit they
    are dropped where they disagree with it, and kept on clean frames (they double the baseline).
    (Since they are predicted through the lens, JPEG's outer corners are 0.39 px RMS off, not 0.66,
    and fewer of them disagree past 0.45 px: 2 of these 12 frames, not 7.  Since they are predicted
    by the markers' refined corners and placed in light, on views summed in light, JPEG 55 leaves
    them 0.35-0.65 px off at worst and none disagrees (lateral median 0.25 % of the height; 0.31 %
    as they were, 2 dropped): so here JPEG 25, where 2 of the 12 do.)"""
    import dataclasses

    cam = dataclasses.replace(Camera.from_hfov(1280, 720, math.radians(100)), dist=(-0.22, 0.04, 0, 0, 0))
    rng = np.random.default_rng(5)
    lateral, dropped, clean_dropped, kept = [], 0, 0, 0
    for k in range(12):
        G = tilted(rng.uniform(-0.8, 0.8), rng.uniform(-0.5, 0.5), rng.uniform(2.2, 3.5), rng.uniform(0, 6.28),
                   rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1))
        view = warp_pad_view(pad, cam, G, GROUND)
        for img in (_jpeg(view, 25), view):
            loc = HierarchicalLocalizer(pad, cam, LocalizerConfig())
            loc.phase = "adjustment"
            e = loc.process(img, 0.0, _imu_from(G))
            assert e.ok and e.method == "markers", (k, e.method, e.reason)
            if img is view:
                clean_dropped += "outer_dropped_px" in e.extras
                kept += e.n_corr % 12 == 4  # 12 corners a marker, and the 4 outer ones
            else:
                dropped += "outer_dropped_px" in e.extras
                lateral.append(np.linalg.norm((e.cam2pad[:3, 3] - G[:3, 3])[:2]) / G[2, 3])
    assert dropped >= 2 and clean_dropped == 0 and kept >= 9, (dropped, clean_dropped, kept)
    assert np.median(lateral) < 0.0042, np.round(100 * np.array(lateral), 2)


def test_a_stated_pad_relief_is_in_every_pose(pad, monkeypatch):
    """A paper pad sags and wrinkles: its surface stands up to some height above the plane it lies on
    (the labels' plane), and every pose is measured to that surface (the realism suite's wrinkled
    pad, 5-15 mm: touchdown poses 3-4 mm low with a 1 mm sigma, 81 % beyond their 3 sigma).  Stated
    (``pad_relief_m``), each pose from the pad carries half of it per axis, and the tracker's poses
    inherit it once, from their keyframe."""
    import hvloc.phases as phases

    real, relief, half = phases.detect_markers, 0.012, pad.geometry.side_m / 2
    now = {}

    def on_a_dome(*a, **k):  # the markers seen on a pad domed by ``relief`` (same detection noise)
        det, why = real(*a, **k)
        if det is not None and now.get("lost"):
            return None, "hidden"
        if det is not None:
            lifted = det.pts_P.copy()
            lifted[:, 2] = relief * (1.0 - np.sum(lifted[:, :2] ** 2, axis=1) / (2 * half**2))
            det.px = det.px + CAM.project_from(now["G"], lifted) - CAM.project_from(now["G"], det.pts_P)
        return det, why

    monkeypatch.setattr(phases, "detect_markers", on_a_dome)
    nees = {0.0: [], relief: []}
    for k in range(6):
        G = tilted(0.02 * k - 0.05, 0.02, 0.8 + 0.15 * k, 0.5 * k, 0.02, -0.01)
        now.update(G=G, lost=False)
        img = warp_pad_view(pad, CAM, G, GROUND)
        for stated in nees:
            loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(pad_relief_m=stated))
            loc.phase = "touchdown" if G[2, 3] < 1.0 else "adjustment"
            e = loc.process(img, 0.0, _imu_from(G))
            assert e.ok and e.method == "markers", (k, e.method, e.reason)
            nees[stated].append(_nees(e, G))
    assert np.mean(np.array(nees[0.0]) > 14.16) > 0.5, np.round(nees[0.0], 1)  # the surface's height, not noise
    assert max(nees[relief]) < 14.16, np.round(nees[relief], 1)
    # the tracker: a markers pose anchors it, the next frame (markers hidden) is tracked
    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(pad_relief_m=relief))
    loc.phase = "touchdown"
    for k, (h, lost) in enumerate(((0.8, False), (0.77, True))):
        G = tilted(0.02, 0.01, h, 0.3, 0.02, -0.01)
        now.update(G=G, lost=lost)
        e = loc.process(warp_pad_view(pad, CAM, G, GROUND), 0.1 * k, _imu_from(G))
        assert e.ok and e.method == ("flow" if lost else "markers"), (k, e.method, e.reason)
        var_z = e.cov[2, 2]
    assert (relief / 2) ** 2 < var_z < 1.5 * (relief / 2) ** 2, (var_z, (relief / 2) ** 2)


def test_a_wrinkles_tilt_is_as_large_as_drawn_reliefs_give():
    """The plane through points of a wrinkled pad tilts with the wrinkles under them: how far, one
    sigma, :func:`hvloc.pose.relief_tilt_rad` states from the relief and where the points lie.  Over
    reliefs drawn as the renderer draws them (render.relief.PadRelief), the RMS tilt of the plane
    through a marker's corners, two or three markers', the outer corners' and texture points spread
    over 0.2 or 0.7 m is what it states, or up to twice less (never more than 1.3 times): not the
    few tenths of a degree an image of 36 corners fixes, and not a marker's tilt for points spread
    over several wrinkles, which average out."""
    from hvloc.pose import relief_tilt_rad
    from render.relief import PadRelief

    rng = np.random.default_rng(5)

    def grid(cx, cy, size, n=6):
        g = np.linspace(-size / 2, size / 2, n)
        X, Y = np.meshgrid(g, g)
        return np.column_stack([X.ravel() + cx, Y.ravel() + cy, np.zeros(n * n)])

    def spread(cx, cy, size, n=150):
        return np.column_stack([rng.uniform(-size / 2, size / 2, (n, 2)) + [cx, cy], np.zeros(n)])

    sets = {"marker": lambda: grid(*rng.uniform(-0.3, 0.3, 2), 0.1),
            "two markers": lambda: np.vstack([grid(0, 0.3, 0.1), grid(0.3, 0, 0.1)]),
            "three markers": lambda: np.vstack([grid(0, 0.3, 0.1), grid(0.3, 0, 0.1), grid(0, -0.3, 0.1)]),
            "outer corners": lambda: np.array([[-0.42, -0.42, 0], [0.42, -0.42, 0], [0.42, 0.42, 0], [-0.42, 0.42, 0]]),
            "texture, 0.2 m": lambda: spread(*rng.uniform(-0.25, 0.25, 2), 0.2),
            "texture, 0.7 m": lambda: spread(0, 0, 0.7)}
    ratios = {k: [] for k in sets}
    for _ in range(120):
        relief = rng.uniform(0.003, 0.02)
        surface = PadRelief.draw(relief, tuple(sorted(rng.uniform(0.15, 0.5, 2))), 0.85, rng)
        for name, draw in sets.items():
            P = draw()
            A = np.column_stack([P[:, :2], np.ones(len(P))])
            a, b, _ = np.linalg.lstsq(A, surface.height(P[:, :2]), rcond=None)[0]
            ratios[name].append(math.atan(math.hypot(a, b)) / math.sqrt(2) / relief_tilt_rad(P, relief))
    rms = {k: round(float(np.sqrt(np.mean(np.square(v)))), 2) for k, v in ratios.items()}
    assert all(0.45 < r < 1.3 for r in rms.values()), rms
    assert relief_tilt_rad(grid(0, 0, 0.1), 0.0) == 0.0


def _marker_on_a_wrinkle(tilt_deg: float, lift: float, h: float):
    """36 corners of a 0.08 m marker under a camera ``h`` above it, lying on a patch tilted
    ``tilt_deg`` about the pad's x axis through their centre and lifted ``lift``: the true pose, the
    corners' pad points and their pixels (0.1 px of noise)."""
    g = np.linspace(-0.04, 0.04, 6)
    X, Y = np.meshgrid(g, g)
    P = np.column_stack([X.ravel() + 0.02, Y.ravel() - 0.01, np.zeros(36)])
    c = P.mean(axis=0)
    on = c + (P - c) @ so3_exp([math.radians(tilt_deg), 0.0, 0.0]).T + [0.0, 0.0, lift]
    G = tilted(0.05, 0.03, h, 0.3, 0.03, -0.02)
    px = CAM.project_from(G, on) + np.random.default_rng(2).normal(0, 0.1, (36, 2))
    return G, P, px


def test_a_patch_a_wrinkle_tilts_is_not_taken_for_the_pads_tilt():
    """Near touchdown one small marker may be all that is seen, on a wrinkle that tilts it a few
    degrees from the pad's plane.  Its image fixes that patch's tilt to a few tenths of a degree,
    and fitted with the IMU's gravity the pose leaned toward the patch (a variant of `hvloc bench
    fuzz` seed 143's scene, a 2 cm relief stated: 23 poses 10-11 % of the height off, "ok", after
    three such patches were taken for a tilting deck).  With the relief stated the patch's tilt is
    solved for beside the pose: the pose keeps gravity's tilt and its place, the patch fits the
    pixels as well as before, and the image-only tilt's sigma says how far a wrinkle may tilt it."""
    G, P, px = _marker_on_a_wrinkle(4.0, 0.01, 0.4)
    up = up_in_camera(G)
    flat = solve_planar_pose(CAM, P, px, up_C=up, sigma_px=0.1)
    wrinkled = solve_planar_pose(CAM, P, px, up_C=up, sigma_px=0.1, relief_m=0.02)

    def tilt_off(T):
        return math.degrees(math.acos(min(1.0, float(up_in_camera(T) @ up))))

    def sideways(T):
        return float(np.hypot(*(T[:3, 3] - G[:3, 3])[:2]))

    # the premise: told nothing, the image's sure tilt pulls the pose toward the patch
    assert flat.tilt_err_deg > 3.0 and flat.tilt_sigma_deg < 1.0, (flat.tilt_err_deg, flat.tilt_sigma_deg)
    assert sideways(flat.cam2pad) > 0.006, sideways(flat.cam2pad)
    assert sideways(wrinkled.cam2pad) < 0.002 and tilt_off(wrinkled.cam2pad) < 0.3, \
        (sideways(wrinkled.cam2pad), tilt_off(wrinkled.cam2pad))
    assert abs(wrinkled.patch_tilt_deg - 4.0) < 0.5, wrinkled.patch_tilt_deg
    assert wrinkled.rms_px < 0.2, wrinkled.rms_px  # the patch fits its pixels
    assert wrinkled.tilt_sigma_deg > 2.0 and wrinkled.relief_tilt_deg > 2.0, wrinkled.tilt_sigma_deg
    # stated: the pose's tilt doubt is the IMU's, its position's as large as what stays unknown
    assert float(np.sqrt(np.trace(wrinkled.cov[:2, :2]))) > sideways(wrinkled.cam2pad)
    # a flat pad (no relief stated, or 0) is solved as before
    same = solve_planar_pose(CAM, P, px, up_C=up, sigma_px=0.1, relief_m=0.0)
    assert np.array_equal(same.cam2pad, flat.cam2pad) and np.array_equal(same.cov, flat.cov)


def _wrinkled_view(pad, camera, G, height):
    """The pad's view from ``G`` with its surface ``height(xy)`` metres off its plane: each pixel's
    ray met on the surface (fixed-point iterations from the plane), the flat view's pixel of that
    pad point taken (a pinhole camera)."""
    flat = warp_pad_view(pad, camera, G, GROUND)
    u, v = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
    K = camera.K
    ray = np.column_stack([(u.ravel() - K[0, 2]) / K[0, 0], (v.ravel() - K[1, 2]) / K[1, 1], np.ones(u.size)]) @ G[:3, :3].T
    o = G[:3, 3]
    t = -o[2] / ray[:, 2]
    for _ in range(8):
        t = (height(o[:2] + t[:, None] * ray[:, :2]) - o[2]) / ray[:, 2]
    xy = o[:2] + t[:, None] * ray[:, :2]
    q = camera.project_from(G, np.column_stack([xy, np.zeros(len(xy))])).astype(np.float32)
    return cv2.remap(flat, q[:, 0].reshape(u.shape), q[:, 1].reshape(u.shape), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)


def test_a_wrinkled_pad_is_posed_with_the_imus_tilt_down_to_touchdown():
    """A nested pad wrinkled 2 cm (a 0.8 m wave, 4.5 degrees steep under its centre marker), its
    relief stated, seen from 0.6 m down to 0.33 m: every frame posed, with gravity's tilt and the
    right place (the poses had leaned toward the patch, 1.6 degrees and 9 mm sideways at 0.33 m),
    each within its stated 3 sigma, and the pad never taken for a tilting deck."""
    nested = make_pad({"variant": "nested"}, ppm=2000)
    half, k = nested.geometry.side_m / 2, 2 * math.pi / 0.8 * np.array([math.cos(0.5), math.sin(0.5)])

    def height(xy):
        return np.where((np.abs(xy) <= half).all(axis=1), 0.01 * (1.0 + np.sin(xy @ k)), 0.0)

    loc = HierarchicalLocalizer(nested, CAM, LocalizerConfig(pad_relief_m=0.02))
    loc.phase = "adjustment"
    for i, h in enumerate(np.linspace(0.6, 0.33, 8)):
        G = tilted(0.0, 0.0, h, 0.4, 0.02, -0.01)
        e = loc.process(_wrinkled_view(nested, CAM, G, height), 0.2 * i, _imu_from(G))
        assert e.ok, (h, e.reason)
        d = e.cam2pad[:3, 3] - G[:3, 3]
        tilt = math.degrees(math.acos(min(1.0, float(up_in_camera(e.cam2pad) @ up_in_camera(G)))))
        assert np.hypot(d[0], d[1]) < 0.003 and tilt < 0.5, (h, e.method, d, tilt)
        assert _nees(e, G) < 14.16, (h, e.method, _nees(e, G))
    assert loc.deck is None and not loc.deck_seen


def test_mislocated_marker_corners_are_dropped_from_the_pose(pad, monkeypatch):
    """A few of many correspondences far off (JPEG and a wide lens pulled marker corners 6-10 px at
    0.8 m on conditions' wide_jpeg, and the pose was 5.9 % of the height off with a 1.8 px RMS, under
    the 3 px gate): they stand out against the rest's residuals and are dropped, and the pose is
    fitted again on the rest."""
    import hvloc.phases as phases

    real = phases.detect_markers

    def pulled(*a, **k):
        det, why = real(*a, **k)
        if det is not None:
            det.px = det.px.copy()
            det.px[[1, 2, 5, 6]] += [4.0, -3.0]  # four corners of the first marker's squares
        return det, why

    G = tilted(0.1, -0.2, 2.5, 0.7, 0.03, -0.02)
    img = warp_pad_view(pad, CAM, G, GROUND)
    errs = {}
    for trim in (False, True):
        monkeypatch.setattr(phases, "detect_markers", pulled)
        if not trim:
            import hvloc.localizer as L
            monkeypatch.setattr(L, "outlying_points", lambda *a, **k: None)
            monkeypatch.setattr(L.HierarchicalLocalizer, "_marker_of", lambda self, P: np.full(len(P), -1))
        loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(use_outline=False))
        e = loc.process(img, 0.0, _imu_from(G))
        assert e.ok and e.method == "markers", e.reason
        errs[trim] = pose_error(e.cam2pad, G)[0]
        if trim:
            assert e.extras.get("outliers_dropped", 0) >= 4 or e.extras.get("marker_dropped") == "Top", e.extras
        monkeypatch.undo()
    assert errs[False] > 0.01 and errs[True] < 0.003, errs


def test_jpeg_field_corners_are_placed_in_linear_light():
    """The renderer blurs light, then encodes sRGB and JPEG: the white field's 50 % crossing in sRGB
    lies on the dark side of its edge, so the field corners (used under JPEG) came out too far
    out: 0.39 px in the median on these 30-40 px pads behind a 100 degree lens at JPEG 55, the
    height ~1 % low (conditions' wide_jpeg: 0.29 px, -1.2 %).  Fitted on linear luma: 0.22 px here
    (0.005 px on wide_jpeg).  On frames the renderer mixed in display values (``mix_in_light:
    false``), where this was measured; mixed in light, as since render revision 12, the same fit's
    field is 0.34-0.42 px large (median 0.38): its single edge is pulled out by the field's bright
    rim and the ring beside it, which awaits the field placed by the border's whole profile."""
    import yaml

    from hvloc.geometry import invert, make_transform, transform_points
    from render.frames import SequenceRenderer
    from render.spec import DatasetSpec
    from benchmarks.suite import REPO

    d = yaml.safe_load((REPO / "data_specs" / "sim800.yaml").read_text())
    d.update(seed=3, sequences=1)
    d["camera"].update(width=960, height=540, hfov_deg=100.0, dist=[-0.22, 0.05, 0.0, 0.0, -0.004], supersample=1,
                       mix_in_light=False)
    d.setdefault("degradations", {}).update(jpeg_quality=55, motion_blur=False)
    d.setdefault("environment", {}).update(distractors={"boxes": [0, 0], "decoy_patches": [0, 0], "decoy_markers": [0, 0]})
    radial = []
    with SequenceRenderer(DatasetSpec.model_validate(d), 0) as r:
        geo, cam, T_W_P = r.pad.geometry, r.camera, r.pad2world[0]
        down = np.array([[1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]])
        for i, (h, yaw) in enumerate([(9, 0.3), (10, 1.2), (11, 2.0), (12, 2.9), (9.5, 3.7), (10.5, 4.6), (11.5, 5.4)]):
            cam2world = make_transform(so3_exp([0.0, 0.0, yaw]) @ down, (0.3, -0.2, h + 0.5))
            layers = r.render_at(i, 0.0, cam2world @ np.linalg.inv(r.T_B_C), T_W_P)
            found, why = find_outline(layers.rgb, geo, cam)
            if found is None or found.field_px is None:
                continue
            truth = cam.project(transform_points(invert(invert(T_W_P) @ cam2world), geo.field_corners))
            q = min((np.roll(found.field_px, k, axis=0) for k in range(4)), key=lambda x: np.abs(x - truth).max())
            out = (truth - truth.mean(axis=0)) / np.linalg.norm(truth - truth.mean(axis=0), axis=1)[:, None]
            radial.append(float(np.mean(np.sum((q - truth) * out, axis=1))))
    assert len(radial) >= 5, radial
    assert np.median(radial) < 0.3, np.round(radial, 3)


def _chroma_spill(img, G, geo, side, width_m, strength):
    """``img`` with the border's chroma (not its luma) spread ``width_m`` past pad side ``side``, as
    JPEG's half-resolution chroma smears a magenta border onto a light platform beside it."""
    o = geo.outer_corners
    a, b = o[side], o[(side + 1) % 4]
    n = np.cross([0.0, 0.0, 1.0], b - a)
    n = (n if n @ (a + b) > 0 else -n) / np.linalg.norm(n)  # outward
    strip = np.array([a, b, b + width_m * n, a + width_m * n])
    m = np.zeros(img.shape[:2], np.uint8)
    cv2.fillConvexPoly(m, np.round(CAM.project_from(G, strip) * 16).astype(np.int32), 1, cv2.LINE_AA, shift=4)
    y = cv2.cvtColor(img, cv2.COLOR_RGB2YCrCb).astype(np.float32)
    c = cv2.cvtColor(np.array([[geo.border.color_rgb]], np.uint8), cv2.COLOR_RGB2YCrCb)[0, 0].astype(np.float32)
    y[..., 1:] = np.where(m[..., None] > 0, y[..., 1:] + strength * (c[1:] - y[..., 1:]), y[..., 1:])
    return cv2.cvtColor(np.clip(y + 0.5, 0, 255).astype(np.uint8), cv2.COLOR_YCrCb2RGB)


@pytest.mark.parametrize("h", [10.0, 13.0])
def test_border_colour_spilled_past_a_side_is_not_taken_for_the_pad(pad, h):
    """JPEG smears the border's chroma several pixels onto a light platform beside the pad while
    luma stays put.  With the colour spread 0.12 m past one side, the colour hull and the sides
    fitted to it lay 6-10 px out, and half such views of a 45-60 px pad were accepted that far off;
    the band check caught only some (most refusals of pad-visible JPEG frames in the conditions
    suite).  The white field's luma edge, found further in than a corner's move, now says where
    the pad is: every view is found within a pixel, or refused."""
    rng = np.random.default_rng(3)
    found = 0
    for i, yaw in enumerate(np.linspace(0.1, 2 * np.pi, 8, endpoint=False)):
        G = tilted(rng.uniform(-1, 1), rng.uniform(-1, 1), h, yaw, 0.05, 0.1)
        img = warp_pad_view(pad, CAM, G, (185, 185, 188))
        img = _jpeg(_chroma_spill(img, G, pad.geometry, i % 4, 0.12, 0.7), 60)
        det, why = detect_outline(img, pad.geometry, CAM)
        if det is None:
            continue
        found += 1
        err = np.linalg.norm(det.px - CAM.project_from(G, det.pts_P), axis=1).max()
        assert err < 1.0, (i, err, det.info)
    assert found >= 6, found


def test_two_markers_are_named_by_a_recent_pose(pad):
    """With one finder marker out of view (and the outline cut), two nests are no right-angle
    triangle: any two of Top, Right, Bottom, either way round, and every such frame was "no marker
    layout".  A recent pose says where each marker should be, give or take the drone's motion since
    (here ~10 cm and 6 degrees): the two are named by it and posed from their own squares' corners,
    as exact as three.  Without a prior they are still refused."""
    geo = pad.geometry
    ms = {m.name: m for m in geo.markers_in(kind="finder") if m.set == "corner"}
    rng = np.random.default_rng(1)
    views = posed = 0
    while views < 8:
        h = rng.uniform(1.5, 3.5)
        G = tilted(rng.uniform(-1.2, 1.2), rng.uniform(-1.2, 1.2), h, rng.uniform(0, 2 * np.pi), 0.05, -0.04)
        seen = [n for n, m in ms.items() if CAM.in_image(CAM.project_from(G, m.outer_corners)).all()]
        near = [n for n, m in ms.items() if CAM.in_image(CAM.project_from(G, m.center[None])).all()]
        if len(seen) != 2 or len(near) != 2:  # the third wholly out of view
            continue
        views += 1
        gray = cv2.cvtColor(warp_pad_view(pad, CAM, G, GROUND), cv2.COLOR_RGB2GRAY)
        det, why = detect_markers(gray, geo, CAM, up_C=up_in_camera(G))
        assert det is None and "no marker layout" in why, why
        prior = G.copy()  # the last accepted pose: the drone has since moved ~10 cm and turned ~6 degrees
        prior[:3, 3] += rng.normal(0, 0.07, 3)
        prior[:3, :3] = prior[:3, :3] @ so3_exp([*rng.normal(0, 0.01, 2), rng.choice([-1, 1]) * 0.1])
        det, why = detect_markers(gray, geo, CAM, up_C=up_in_camera(G), prior=prior)
        if det is None:
            continue
        assert det.info["named_by"] == "prior" and sorted(det.info["markers_seen"]) == sorted(seen)
        pose = solve_planar_pose(CAM, det.pts_P, det.px, up_C=up_in_camera(G))
        e, r = pose_error(pose.cam2pad, G)
        assert e < 0.005 * h and r < 0.3, (h, seen, e, r)
        posed += 1
    assert posed >= 6, posed


def _two_marker_views(pad, n, seed, heights=(1.2, 3.5), tilt=0.1, reach=1.2):
    """``n`` views ``heights`` m up (1.2-3.5), up to ``reach`` m off the pad's centre either way and
    tilted up to ``tilt`` radians, in which exactly two of the pad's finder markers are in view (the
    third wholly out): ``(G, names seen)``."""
    ms = {m.name: m for m in pad.geometry.markers_in(kind="finder") if m.set == "corner"}
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        h = rng.uniform(*heights)
        G = tilted(rng.uniform(-reach, reach), rng.uniform(-reach, reach), h, rng.uniform(0, 2 * np.pi),
                   rng.uniform(-tilt, tilt), rng.uniform(-tilt, tilt))
        seen = [k for k, m in ms.items() if CAM.in_image(CAM.project_from(G, m.outer_corners)).all()]
        near = [k for k, m in ms.items() if CAM.in_image(CAM.project_from(G, m.center[None])).all()]
        if len(seen) == 2 and len(near) == 2:
            out.append((G, seen))
    return out


def _lone_markers(pad):
    """A copy of ``pad`` whose drawing is its finder markers' squares alone on plain ground."""
    geo = pad.geometry
    lone = copy.copy(pad)
    tex = np.empty_like(pad.texture_rgb)
    tex[:] = GROUND
    n, s = tex.shape[0], geo.side_m
    for m in geo.markers_in(kind="finder"):
        half = m.size_m / 2 + 0.01
        rows = slice(int((s / 2 - m.center[1] - half) / s * n), int((s / 2 - m.center[1] + half) / s * n))
        cols = slice(int((m.center[0] - half + s / 2) / s * n), int((m.center[0] + half + s / 2) / s * n))
        tex[rows, cols] = pad.texture_rgb[rows, cols]
    lone.texture_rgb = tex
    return lone


def test_a_cold_starts_two_markers_are_named_by_the_pads_design(pad):
    """A cold start low over the pad, the outline cut by the image's edge and the third marker out
    of view: no pose names the two nests (any two of Top, Right, Bottom, either way round), and every
    such frame was lost ("no marker layout").  With the IMU's gravity the view is made head-on, each
    reading of the two nests placed, and the image where each puts the rest of the pad correlated
    with the pad's printed design: the right one is taken, here under blur, JPEG 45 and dim light
    too (on 80 such views of two seeds, all 80 named right; the right reading correlates 0.73-0.94,
    leading the next by 0.21-0.33).  Without the IMU the view is taken for head-on (near nadir here;
    an oblique camera's skewed readings fail their sizes or the design).  Two lone finder squares on
    plain ground are never taken for a pair.  A fresh localizer poses such frames by them."""
    geo = pad.geometry
    design = PadDesign(pad.texture_rgb)
    lone = _lone_markers(pad)  # the same two markers and nothing else of the pad
    by_markers = 0
    for i, (G, seen) in enumerate(_two_marker_views(pad, 10, 1)):
        h, up = G[2, 3], up_in_camera(G)
        img = warp_pad_view(pad, CAM, G, GROUND)
        if i % 2:  # blurred, JPEG 45, dim
            img = _jpeg((cv2.GaussianBlur(img, (0, 0), 1.2) * 0.3).astype(np.uint8), 45)
        gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
        assert detect_markers(gray, geo, CAM, up_C=up)[0] is None  # (as before: no prior, no design)
        decoy = warp_pad_view(lone, CAM, G, GROUND)
        for u in (up, None):  # with the IMU's gravity, and without it (the view taken for head-on)
            det, why = detect_markers(gray, geo, CAM, up_C=u, design=design)
            assert det is not None, (i, why)
            assert det.info["named_by"] == "design" and sorted(det.info["markers_seen"]) == sorted(seen), det.info
            if u is not None:
                pose = solve_planar_pose(CAM, det.pts_P, det.px, up_C=up)
                e, r = pose_error(pose.cam2pad, G)
                assert e < (0.01 if i % 2 else 0.005) * h and r < 0.5, (i, h, e, r)
            det, why = detect_markers(cv2.cvtColor(decoy, cv2.COLOR_RGB2GRAY), geo, CAM, up_C=u, design=design)
            assert det is None, (i, det.info)
        # the localizer, started cold on the frame with the IMU (before: 8 of 40 such views posed, by
        # the cut outline or the texture; now 40, 32 of them by the markers, none 1 % of the height off)
        e = HierarchicalLocalizer(pad, CAM, LocalizerConfig()).process(img, 0.0, _imu_from(G))
        assert e.ok, (i, e.reason)
        assert pose_error(e.cam2pad, G)[0] < (0.01 if i % 2 else 0.005) * h
        by_markers += e.method == "markers"
        if i < 4:  # without the IMU too: posed, its stated covariance honest (two markers fix the tilt less)
            e = HierarchicalLocalizer(pad, CAM, LocalizerConfig()).process(img, 0.0, None)
            assert e.ok, (i, e.reason)
            d = e.cam2pad[:3, 3] - G[:3, 3]
            assert np.linalg.norm(d) < 0.03 * h and d @ np.linalg.solve(e.cov[:3, :3], d) < 14.16, (i, d, e.cov[:3, :3])
        if i == 0:  # the lone squares are tried and refused; plain ground (no nests) is not searched twice
            e = HierarchicalLocalizer(pad, CAM, LocalizerConfig()).process(decoy, 0.0, _imu_from(G))
            assert not e.ok and "none named by the pad's design either" in e.reason, e.reason
            plain = np.ascontiguousarray(np.broadcast_to(np.array(GROUND, np.uint8), img.shape))
            e = HierarchicalLocalizer(pad, CAM, LocalizerConfig()).process(plain, 0.0, _imu_from(G))
            assert not e.ok and e.reason.count("markers:") == 1, e.reason
    assert by_markers >= 6, by_markers


def test_two_markers_on_a_finely_textured_pad_are_named_by_what_a_turn_changes():
    """Two nests of a pad whose texture is fine (5-29 mm blobs, as fuzz seed 161's) seen from 2-6 m:
    at one sample per pixel the texture is an even grey, and what every turn of the design shares (the
    ring, the white field) made the readings that put the pad on the same square (a diagonal pair
    either way round, an adjacent pair's quarter turns) correlate alike: 0.80-0.86 against the right
    one's 0.87-0.92, a lead under 0.15, and no such view was named (fuzz seeds 131 and 161 lost 26
    frames so).  Readings on one square are now compared by what a turn changes alone: most views are
    named, none wrongly; lone finder squares on plain ground still not."""
    fine = make_pad({"texture_seed": 36, "texture_min_feature_m": 0.005, "texture_max_feature_m": 0.029,
                     "texture_density": 0.16, "marker_size_m": 0.136}, 1000.0)
    geo, design = fine.geometry, PadDesign(fine.texture_rgb)
    lone = _lone_markers(fine)  # its markers' squares alone, on plain ground
    named = 0
    kinds = set()
    views = _two_marker_views(fine, 16, 3, heights=(2.0, 6.0), tilt=0.3, reach=3.6)
    for i, (G, seen) in enumerate(views):
        img = warp_pad_view(fine, CAM, G, GROUND)
        if i % 2:  # blurred, JPEG 45, dim
            img = _jpeg((cv2.GaussianBlur(img, (0, 0), 1.2) * 0.5).astype(np.uint8), 45)
        det, why = detect_markers(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), geo, CAM, up_C=up_in_camera(G), design=design)
        if det is not None:
            assert sorted(det.info["markers_seen"]) == sorted(seen), (i, seen, det.info)
            pose = solve_planar_pose(CAM, det.pts_P, det.px, up_C=up_in_camera(G))
            assert pose_error(pose.cam2pad, G)[0] < 0.02 * G[2, 3], i  # (0.5 % clean at worst, 1.5 % blurred)
            named += 1
            kinds.add("diagonal" if sorted(seen) == ["Bottom", "Top"] else "adjacent")
        decoy = cv2.cvtColor(warp_pad_view(lone, CAM, G, GROUND), cv2.COLOR_RGB2GRAY)
        assert detect_markers(decoy, geo, CAM, up_C=up_in_camera(G), design=design)[0] is None, i
    assert named >= 12 and kinds == {"diagonal", "adjacent"}, (named, kinds)


def test_markers_are_tried_as_high_as_this_pad_and_camera_resolve_them():
    """Markers were never tried above the adjustment height (8.3 m), whatever the pad and camera: a
    1.5 m pad's 0.2 m markers at 1080p resolve to 16 m, and on an oblique dusk descent (unseen8)
    frames at 9-10 m with all three markers seen and the outline lost were lost.  The limit is now
    also where this pad's marker modules span 2 px; the default pad and 800 px camera keep 8.3 m."""
    from pad_design import make_pad

    big = make_pad({"side_m": 1.5, "border_m": 0.15, "marker_size_m": 0.2}, ppm=1000)
    cam = Camera.from_hfov(1920, 1080, math.radians(80))
    loc = HierarchicalLocalizer(big, cam, LocalizerConfig(use_outline=False, use_flow=False))
    G = tilted(0.2, -0.1, 9.5, 0.6, 0.02, -0.03)
    loc.last = type("E", (), {"height": 9.5, "t": 0.0, "cam2pad": G, "method": "outline"})()  # a recent far pose
    e = loc.process(warp_pad_view(big, cam, G, GROUND), 0.1, _imu_from(G))
    assert e.ok and e.method == "markers", e.reason
    assert pose_error(e.cam2pad, G)[0] < 0.01 * 9.5
    default = HierarchicalLocalizer(make_pad(), CAM, LocalizerConfig())
    assert default.markers_seen_below_m < LocalizerConfig().adjust_height_m  # unchanged there


def test_markers_with_too_few_squares_refined_give_no_pose(pad, monkeypatch):
    """Three finder nests found, but most of their nested squares' corners refused (moved over half
    a module: blur, JPEG, a marker cut by the image's edge): the one square left posed a pad at
    0.4 m 3.6 degrees off the IMU and 10 % of the height sideways, and anchored the touchdown
    tracker, which carried it to the ground.  Fewer than two squares a marker is no markers pose."""
    import hvloc.phases as phases

    G = tilted(0.05, -0.03, 1.6, 0.4)
    img = warp_pad_view(pad, CAM, G, GROUND)
    gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    det, why = detect_markers(gray, pad.geometry, CAM)
    assert det is not None and len(det.pts_P) == 36, why
    real = phases._marker_corners
    for keep in (5, 6):
        def only(*args, keep=keep):
            got = real(*args)
            return None if got is None else (got[0][:keep], got[1][:keep], got[2])
        monkeypatch.setattr(phases, "_marker_corners", only)
        det, why = detect_markers(gray, pad.geometry, CAM)
        if keep < 2 * 3:
            assert det is None and f"{keep} of 9 squares" in why, why
        else:
            assert det is not None and len(det.pts_P) == 4 * keep, why
    monkeypatch.setattr(phases, "_marker_corners", lambda *a: (lambda g: (g[0][:1], g[1][:1], g[2]))(real(*a)))
    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig())
    loc.phase = "adjustment"
    e = loc.process(img, 0.0, _imu_from(G))
    assert not (e.ok and e.method == "markers"), (e.method, e.n_corr)


def _smeared(pad, G, vel_P, rate_C, exposure_s, shadow=None, seed=0, instants=24, ground=GROUND):
    """A frame of the pad from ``G`` smeared by the camera's motion over the exposure (the views of
    many instants averaged in linear light, gamma 2.2 as the renderer encodes), with the drone's
    shadow over the image region ``shadow`` (a slice) and sensor noise."""
    acc = np.zeros((CAM.height, CAM.width, 3), np.float64)
    for tau in np.linspace(-exposure_s / 2, exposure_s / 2, instants):
        T = G.copy()
        T[:3, 3] = G[:3, 3] + np.asarray(vel_P) * tau
        T[:3, :3] = G[:3, :3] @ so3_exp(np.asarray(rate_C) * tau)
        acc += (warp_pad_view(pad, CAM, T, ground, supersample=1) / 255.0) ** 2.2
    lin = acc / instants
    if shadow is not None:
        lin[shadow] *= 0.12
    lin += np.random.default_rng(seed).normal(0.0, 0.004, lin.shape)
    return np.clip(255.0 * np.clip(lin, 0, 1) ** (1 / 2.2) + 0.5, 0, 255).astype(np.uint8)


def _smeared_touchdown(pad, vx: float, frames: int, drawing_from: int | None = None) -> list:
    """``[(G, Estimate)]`` of a gusty touchdown from 1 m at 15 Hz: three sharp frames, then frames
    smeared by a turn of 2.3 rad/s and a descent of 0.9 m/s (30-40 px in a 30 ms exposure), the
    camera drifting ``vx`` m/s sideways; from frame ``drawing_from`` on the pad's drawing is refused
    (as where the pad runs out of the frame)."""
    from hvloc.geometry import quat_xyzw_from_matrix

    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), exposure_s=0.03)
    w, v, out = np.array([1.5, -1.0, 1.5]), np.array([vx, -0.2, -0.9]), []
    for k in range(frames):
        t = k / 15.0
        G = tilted(0.15 + vx * t, -0.1 - 0.2 * t, 1.0 - 0.9 * t, 0.4 + 1.5 * t, 0.02, -0.01)
        img = warp_pad_view(pad, CAM, G, GROUND) if k < 3 else _smeared(pad, G, v, w, 0.03, seed=k)
        imu = np.concatenate([[t], DEFAULT_T_B_C[:3, :3] @ w, [0, 0, 9.81], quat_xyzw_from_matrix(_imu_from(G))])
        if drawing_from is not None and k >= drawing_from:
            loc._synthesized = lambda *a, **kw: (None, "the drawing refused (the test)")
        out.append((G, loc.process(img, t, imu), loc.flow.kf))
    return out


def _nees3(e, G) -> float:
    d = e.cam2pad[:3, 3] - G[:3, 3]
    return float(d @ np.linalg.solve(e.cov[:3, :3], d))


@pytest.mark.parametrize("vx", [0.3, 0.9])
def test_a_smeared_touchdown_is_never_posed_on_a_few_surviving_tracks(pad, vx):
    """Under 30-40 px of smear and a zoom past the flow's reach Lucas-Kanade loses most of its
    keyframe's features; the 8-14 that survive had slid along their smear alike, a homography fitted
    them, and frames were posed 20-95 mm off stating a tenth of it (NEES 24-400).  A flow pose now
    needs 20 agreeing tracks: every flow pose of these descents lies within its 3 sigma, and most
    frames are still posed (by the flow, the texture or the pad's drawing).  (ORB's texture poses
    under 75-95 px of smear are 0.1-0.17 smears off, beyond the tenth their covariance holds: not
    asserted here.)"""
    out = _smeared_touchdown(pad, vx, 13)
    posed = [(G, e) for G, e, _ in out if e.ok]
    assert len(posed) >= 7, [(e.status, e.method, e.reason[-120:]) for _, e, _ in out]
    flow = [(G, e) for G, e in posed if e.method == "flow"]
    assert flow and all(_nees3(e, G) < 14.16 for G, e in flow), [(e.method, round(_nees3(e, G), 1)) for G, e in posed]


@pytest.mark.parametrize("v, h", [((-0.12, 0.12, -0.1), 0.35), ((-0.15, -0.1, -0.1), 0.45)])
def test_a_first_pose_under_a_smear_no_velocity_predicts_lies_within_its_covariance(pad, v, h):
    """The first pose of a track (or the first after a loss nothing carried the motion through) is
    smeared by a velocity no pose has told.  Its tracks' doubt for their smear was that of the
    gyro's turn alone: a texture pose at 0.35 m under 0.2 m/s was 2.2 mm off with 0.6 mm stated
    (NEES 25; unseen83, a gale over a deck: the first texture poses at 0.3 m after 2 s lost, NEES
    18-99, and the flow chains from them, 20 % of touchdown's poses beyond 3 sigma).  Now it counts
    what a speed of UNKNOWN_SPEED_MPS along each pad axis would smear, as the shutter's correction
    does; a still camera's first pose states 1.8 mm at 0.3 m where it is within 0.1 mm (the cost)."""
    from hvloc.geometry import quat_xyzw_from_matrix

    G = tilted(0.05, -0.08, h, 1.3)
    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), exposure_s=0.035)
    R = _imu_from(G)
    e = loc.process(_smeared(pad, G, np.array(v), np.zeros(3), 0.035, seed=1),
                    0.0, np.r_[0.0, 0.0, 0.0, 0.0, R.T @ [0.0, 0.0, 9.80665], quat_xyzw_from_matrix(R)])
    assert e.ok and e.method == "texture", (e.status, e.reason[-200:])
    assert _nees3(e, G) < 14.16, (_nees3(e, G), e.cam2pad[:3, 3] - G[:3, 3], np.sqrt(np.diag(e.cov[:3, :3])))
    assert np.sqrt(np.trace(e.cov[:3, :3])) < 0.015 * h  # doubted, not given up on


def test_the_flow_falls_back_on_a_keyframe_of_the_drawn_frame(pad):
    """A frame posed by the pad's smeared drawing anchors the flow (its keyframe the frame, renewed
    at every drawn frame), tried only after the drawing: tracks from a smeared keyframe were 5-11
    mm off at 0.5-0.8 m where the drawing was within a millimetre.  Where the drawing is refused
    (unseen57: the pad running out of the frame at 1 m, 15 frames lost to 0.5 m) the flow poses
    the next frames, within its 3 sigma; before, no keyframe was made from a drawn frame, and the
    tracks from the last sharp one were lost."""
    out = _smeared_touchdown(pad, 0.3, 7, drawing_from=5)
    for k in (3, 4):  # the drawing poses while it can, and the flow keeps a keyframe of its frame
        G, e, kf = out[k]
        assert e.ok and e.extras.get("by") == "synthesis" and kf.drawn and kf.anchored, (k, e.method, e.reason)
        assert kf.serial > out[k - 1][2].serial
    G, e, _ = out[5]
    assert e.ok and e.method == "flow" and _nees3(e, G) < 14.16, (e.method, e.reason[-200:])
    G, e, _ = out[6]  # (from there the zoom runs past the tracks' reach: a pose within its 3 sigma, or none)
    assert not e.ok or _nees3(e, G) < 14.16


def test_a_drawn_keyframe_gives_way_to_the_next_pose_of_another_method(pad):
    """A keyframe of a drawn frame is a fallback: the flow is tried after the drawing while it is
    the keyframe.  The first pose of another method (markers here) replaces it, so the flow comes
    first again; kept (the rule for anchored keyframes: renewed only when out of reach or less sure),
    a slow descent was drawn for 45 frames where the flow would have tracked (unseen59)."""
    from hvloc.localizer import Estimate

    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), exposure_s=0.03)
    G = tilted(0.1, -0.05, 0.9, 0.4, 0.01, -0.01)
    gray = cv2.cvtColor(warp_pad_view(pad, CAM, G, GROUND), cv2.COLOR_RGB2GRAY)
    cov = np.diag([1e-4, 1e-4, 1e-4, 1e-6, 1e-6, 1e-6])
    loc._after_accept("texture", Estimate(0.0, "touchdown", "ok", G, 20, 0.3, 4 * cov, extras={"by": "synthesis"}), gray)
    assert loc.flow.kf is not None and loc.flow.kf.drawn
    drawn = loc.flow.kf.serial
    G2 = tilted(0.1, -0.05, 0.89, 0.4, 0.01, -0.01)  # the next frame, a little lower, posed by the markers
    gray2 = cv2.cvtColor(warp_pad_view(pad, CAM, G2, GROUND), cv2.COLOR_RGB2GRAY)
    loc._after_accept("markers", Estimate(0.033, "touchdown", "ok", G2, 40, 0.3, 9 * cov), gray2)
    assert loc.flow.kf.serial > drawn and not loc.flow.kf.drawn and loc.flow.kf.anchored


@pytest.mark.parametrize("h", [0.45, 0.8])
def test_a_pad_smeared_past_every_feature_is_posed_by_its_drawing(pad, h):
    """A gust at touchdown: 50-70 px of smear (a 30 ms exposure, turning at 1.5 rad/s), the drone's
    shadow over a quarter of the view.  Corners, ORB and the markers' contours all fail.  The
    texture drawn at a pose predicted 2-3 cm and half a degree off, smeared by the predicted
    motion and aligned to the frame, places the camera within a few millimetres; another pad's
    texture is never taken for it, and a pad too little of which is in view is not tried."""
    from hvloc.synthesis import PadSynthesis
    from hvloc.texture import PadTexture

    syn, other = PadSynthesis(pad), PadSynthesis(make_pad({"texture_seed": 99}))
    rng = np.random.default_rng(int(100 * h))
    for trial in range(2):
        G = tilted(rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), h, rng.uniform(0, 2 * np.pi), 0.02, -0.015)
        v, w = rng.uniform(-0.4, 0.4, 3), rng.uniform(-1.2, 1.2, 3)
        w[2] = 1.5 * np.sign(w[2])
        gray = cv2.cvtColor(_smeared(pad, G, v, w, 0.03, np.s_[:400, :400], seed=trial), cv2.COLOR_RGB2GRAY)
        assert PadTexture(pad).locate(gray, CAM)[0] is None  # ORB finds too little
        pred = G.copy()
        pred[:3, 3] += rng.uniform(-0.02, 0.02, 3)
        pred[:3, :3] = pred[:3, :3] @ so3_exp(np.radians(rng.uniform(-0.4, 0.4, 3)))
        det, why = syn.locate(gray, CAM, pred, 1.1 * v, w, 0.03)
        assert det is not None, why
        assert det.info["by"] == "synthesis" and det.info["smear_px"] > 40, det.info
        up = (G[:3, :3]).T @ np.array([0.0, 0.0, 1.0])
        pose = solve_planar_pose(CAM, det.pts_P, det.px, up)
        dp, da = pose_error(pose.cam2pad, G)
        was = float(np.linalg.norm(pred[:3, 3] - G[:3, 3]))
        assert dp < 0.006 and dp < 0.5 * was, (h, trial, dp, was, da, det.info)
        det, why = other.locate(gray, CAM, pred, 1.1 * v, w, 0.03)
        assert det is None and "correlation" in why, why
    # the predicted pad mostly out of view: nothing drawn, nothing aligned
    far = tilted(1.2, 0.0, h, 0.3)
    det, why = syn.locate(gray, CAM, far, None, None, 0.03)
    assert det is None and ("part in view" in why or "out of view" in why), why


def test_a_wide_border_over_snow_does_not_pull_the_pads_drawing():
    """The drawing is read relative to its local white, and nothing is drawn beyond the pad: on a
    border wider than that white's reach its white is the border's own, where the frame's is the
    ground's beside it.  A 1 m pad with a 0.15 m border over snow at 1.5 m (the border 60 px wide),
    smeared 13-16 px, drawn at a prediction 1-2 cm off: aligned over the whole border, two of four
    views were posed 14-19 mm off (1.2 % of the height) and two refused.  Compared on the field and
    the border near it, every view is posed within 0.2 % of the height."""
    from hvloc.synthesis import PadSynthesis

    wide = make_pad({"side_m": 1.0, "border_m": 0.15})
    syn = PadSynthesis(wide)
    rng = np.random.default_rng(3)
    h = 1.5
    for trial in range(4):
        G = tilted(rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), h, rng.uniform(0, 2 * np.pi), 0.02, -0.015)
        v, w = rng.uniform(-0.4, 0.4, 3), rng.uniform(-0.5, 0.5, 3)
        gray = cv2.cvtColor(_smeared(wide, G, v, w, 0.03, seed=trial, ground=(235, 235, 235)), cv2.COLOR_RGB2GRAY)
        pred = G.copy()
        pred[:3, 3] += rng.uniform(-0.015, 0.015, 3)
        det, why = syn.locate(gray, CAM, pred, v, w, 0.03)
        assert det is not None, (trial, why)
        up = G[:3, :3].T @ np.array([0.0, 0.0, 1.0])
        dp = pose_error(solve_planar_pose(CAM, det.pts_P, det.px, up).cam2pad, G)[0]
        assert dp < 0.002 * h, (trial, dp, det.info)


def test_a_far_pad_cut_by_the_edge_and_smeared_is_posed_by_its_drawing(pad):
    """A gust carries a far pad (9 m, 60 px) past the image's edge: two of its corners out of view,
    10 px of smear, one marker left.  No outline or marker method poses that (gusty_blur lost such
    frames); the pad drawn where the last pose predicts it, smeared by the gyro's rate and the
    velocity of the last poses over the 30 ms exposure, is.  Without the exposure it is drawn sharp
    and the same frames are refused rather than posed wrong; without an IMU (no attitude to turn
    the drawing by) nothing is drawn."""
    results = {}
    for exposure, with_imu in ((0.03, True), (0.0, True), (None, False)):
        loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), exposure_s=0.03 if exposure is None else exposure)
        out = []
        for k in range(9):
            x = -4.0 - 0.14 * k  # the camera moves away: the pad slides toward the image's right edge
            G = tilted(x, 0.3, 9.0 - 0.05 * k, 0.2, 0.0, 0.0)
            w = np.array([0.0, 0.0, 0.5])  # turning at 0.5 rad/s
            v = np.array([-1.4, 0.0, -0.5])
            img = warp_pad_view(pad, CAM, G, GROUND) if k < 5 else _smeared(pad, G, v, w, 0.03, seed=k)
            imu = np.concatenate([[0.1 * k], DEFAULT_T_B_C[:3, :3] @ w, [0, 0, 9.81], [0, 0, 0, 1]])
            R = _imu_from(G)
            from hvloc.geometry import quat_xyzw_from_matrix

            imu[7:] = quat_xyzw_from_matrix(R)
            e = loc.process(img, 0.1 * k, imu if with_imu else None)
            out.append((k, e))
        results[exposure] = out
    assert not any(e.extras.get("by") == "synthesis" for _, e in results[None])
    assert any("no attitude to draw the pad at" in e.reason for k, e in results[None] if k >= 6 and not e.ok), \
        [(k, e.status, e.reason[-160:]) for k, e in results[None]]
    cut = [(k, e) for k, e in results[0.03] if k >= 6]
    posed = [(k, e) for k, e in cut if e.ok]
    assert len(posed) >= 2 and all(e.method == "texture" and e.extras.get("by") == "synthesis" for _, e in posed), \
        [(k, e.status, e.method, e.reason[-160:]) for k, e in cut]
    assert all(e.phase == "approaching" for _, e in posed)  # at 9 m: the phase it was tried in, not touchdown's
    for k, e in posed:
        x = -4.0 - 0.14 * k
        dp, da = pose_error(e.cam2pad, tilted(x, 0.3, 9.0 - 0.05 * k, 0.2))
        assert dp < 0.02 * 9.0, (k, dp, e.extras)
    for k, e in results[0.0]:
        if k >= 6 and e.ok:
            x = -4.0 - 0.14 * k
            assert pose_error(e.cam2pad, tilted(x, 0.3, 9.0 - 0.05 * k, 0.2))[0] < 0.02 * 9.0


def _gust_through_a_blackout(pad, rows_per_frame: int) -> list:
    """``[(k, G, Estimate)]``: a gust near the ground at 10 Hz (0.8 m/s^2 across, 1 m to 0.8 m, the
    drone yawing at 1 rad/s, 30 ms exposures), from frame 5 rocking 3 degrees at 5 Hz (level at
    each frame's time but turning at 1.6 rad/s there: smeared 40-50 px); frames 5-9 show nothing
    (the stream blanked, or the pad out of view), the IMU's blocks of ``rows_per_frame`` rows
    (200 Hz; 1: the attitude alone) carrying the motion through them."""
    from hvloc.geometry import quat_xyzw_from_matrix

    p0, v0, a = np.array([0.05, -0.05, 1.0]), np.array([0.3, 0.0, -0.3]), np.array([-0.8, 0.6, 0.1])
    yaw_rate, rock, rock_hz = 1.0, math.radians(3.0), 5.0
    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), exposure_s=0.03)
    f_P = a + np.array([0.0, 0.0, 9.80665])  # the specific force in the pad's frame (level: the world's)

    def attitude(t):  # the camera's, and its own rate (it looks down: yawing is turning about -z)
        A = rock if t > 0.45 else 0.0  # the gust's rocking begins as the pad leaves the frame
        r = A * math.sin(2 * math.pi * rock_hz * t)
        R = tilted(0.0, 0.0, 1.0, 0.4 + yaw_rate * t, r)[:3, :3]
        return R, so3_exp([0.0, -r, 0.0]) @ np.array([0.0, 0.0, -yaw_rate]) + \
            np.array([0.0, A * 2 * math.pi * rock_hz * math.cos(2 * math.pi * rock_hz * t), 0.0])

    out = []
    for k in range(12):
        t = 0.1 * k
        G = np.eye(4)
        G[:3, :3], rate_C = attitude(t)
        G[:3, 3] = p0 + v0 * t + 0.5 * a * t * t
        img = np.zeros((CAM.height, CAM.width, 3), np.uint8) if 5 <= k <= 9 else \
            _smeared(pad, G, v0 + a * t, rate_C, 0.03, seed=k)
        imu = []
        for ti in t - 0.005 * np.arange(rows_per_frame)[::-1]:
            R_W_C, w_C = attitude(ti)
            R_W_B = R_W_C @ DEFAULT_T_B_C[:3, :3].T
            imu.append(np.r_[ti, DEFAULT_T_B_C[:3, :3] @ w_C, R_W_B.T @ f_P, quat_xyzw_from_matrix(R_W_B)])
        out.append((k, G, loc.process(img, t, np.array(imu))))
    return out


def test_a_pad_lost_for_half_a_second_is_drawn_where_the_imu_carried_it(pad):
    """A gust swings the pad out of the frame near the ground and back, smeared: the flow's chain is
    broken, and no feature holds under the smear.  The pad's drawing places it, but was tried only
    within 0.35 s of the last pose, moved on at the last two poses' velocity (gusty_blur: 8 frames
    lost in a row at 0.67-0.41 m).  The velocity filter's position, carried by the IMU's rows (each
    block's first row too), is drawn at up to a second later while its doubt lies within the
    alignment's reach: the first frame back is posed.  With the attitude alone (no rows to carry
    the motion) nothing is drawn there, and nothing posed wrong."""
    out = _gust_through_a_blackout(pad, 20)
    assert all(e.ok for k, G, e in out[:5]), [(k, e.status, e.reason[-120:]) for k, G, e in out[:5]]
    assert not any(e.ok for k, G, e in out[5:10])
    k, G, e = out[10]  # 0.6 s after the last pose, 0.1 m across from where the last velocity puts it
    assert e.ok and e.extras.get("by") == "synthesis", (e.status, e.method, e.reason[-300:])
    assert np.linalg.norm(e.cam2pad[:3, 3] - G[:3, 3]) < 0.005 * G[2, 3]
    # the next: the filter starts again from the drawn pose, its velocity not known yet
    assert all(e.ok and np.linalg.norm(e.cam2pad[:3, 3] - G[:3, 3]) < 0.01 * G[2, 3] for k, G, e in out[10:])
    alone = _gust_through_a_blackout(pad, 1)
    k, G, e = alone[10]
    assert not e.ok and "drawn" not in e.reason, (e.status, e.method, e.reason[-300:])
    assert all(not e.ok or np.linalg.norm(e.cam2pad[:3, 3] - G[:3, 3]) < 0.01 * G[2, 3] for k, G, e in alone[5:])


@pytest.mark.parametrize("h", [2.0, 5.0, 12.0])
def test_the_pads_drawing_from_a_coarser_level_sits_where_the_finest_one_does(pad, h):
    """The smear's drawing reads the pad's texture from a level whose texels are about a pixel.  A
    Gaussian pyramid's levels sit half a texel off a box's centre each, and the drawing moved by
    0.24-0.75 px (pads 50-300 px across): a bias in every pose the drawing gives.  Drawn from the
    box-filtered levels, it lies within 0.08 px of the finest level drawn 4 x 4 per pixel and
    averaged, as a sensor's pixel averages."""
    from hvloc.synthesis import PadSynthesis

    syn = PadSynthesis(pad)
    T = tilted(0.05, -0.03, h, 0.3, 0.03, -0.02)
    c = CAM.project_from(T, np.zeros((1, 3)))[0]
    m = int(0.75 * CAM.fx * pad.side_m / h) + 8
    box = (int(c[0]) - m, int(c[1]) - m, int(c[0]) + m, int(c[1]) + m)
    drawn = syn.draw(CAM, syn.window(CAM, box, 1.0), 1.0, lambda tau: T, [0.0])[0]
    finest = PadSynthesis(pad)
    finest.levels = finest.levels[:1]
    ref = finest.draw(CAM, finest.window(CAM, box, 4.0), 4.0, lambda tau: T, [0.0])[0]
    ref = cv2.resize(ref, drawn.shape[::-1], interpolation=cv2.INTER_AREA)
    assert len(syn.levels) > 1 and syn.levels[1][0].shape[0] < pad.texture_rgb.shape[0]
    (dx, dy), response = cv2.phaseCorrelate(ref.astype(np.float64), drawn.astype(np.float64),
                                            cv2.createHanningWindow(drawn.shape[::-1], cv2.CV_64F))
    assert response > 0.9 and math.hypot(dx, dy) < 0.08, (h, dx, dy, response)


def test_a_coarse_alignment_that_does_not_converge_leaves_the_fine_one_to_try(pad, monkeypatch):
    """The smear's drawing is aligned at half size first, as a start for the full size.  A 25-30 px
    pad halved is a few features, and there ECC can fail to converge, or converge where the drawing
    does not match (bench_v2's x_field_rs_oblique at 13 m: correlation 0.17, and the frame was lost).
    Such a start is dropped: the full-size pass starts from the prediction and still places the pad."""
    from hvloc.synthesis import PadSynthesis

    G = tilted(0.03, -0.02, 0.8, 0.4)
    v, w = np.array([0.2, -0.1, -0.2]), np.array([0.3, -0.2, 1.0])
    gray = cv2.cvtColor(_smeared(pad, G, v, w, 0.02), cv2.COLOR_RGB2GRAY)
    pred = G.copy()
    pred[:3, 3] += [0.01, -0.008, 0.006]
    up = G[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    real = cv2.findTransformECC
    sizes = []

    def coarse_fails(a, b, warp, *args):
        sizes.append(a.shape)
        if len(sizes) == 1:
            raise cv2.error("The algorithm stopped before its convergence")
        return real(a, b, warp, *args)

    monkeypatch.setattr(cv2, "findTransformECC", coarse_fails)
    det, why = PadSynthesis(pad).locate(gray, CAM, pred, v, w, 0.02)
    # the coarse pass was tried, then the fine one (and after it the scale's probes)
    assert len(sizes) >= 2 and sizes[0][0] < sizes[1][0], sizes
    assert det is not None, why
    dp = pose_error(solve_planar_pose(CAM, det.pts_P, det.px, up).cam2pad, G)[0]
    assert dp < 0.004, dp

    def coarse_wanders(a, b, warp, *args):  # converges, but somewhere the drawing does not match
        sizes.append(a.shape)
        cc, wk = real(a, b, warp, *args)
        if len(sizes) == 1:
            wk = wk.copy()
            wk[:, 2] += 0.15 * a.shape[1]
            return 0.2, wk
        return cc, wk

    sizes.clear()
    monkeypatch.setattr(cv2, "findTransformECC", coarse_wanders)
    det, why = PadSynthesis(pad).locate(gray, CAM, pred, v, w, 0.02)
    assert len(sizes) >= 2 and sizes[0][0] < sizes[1][0] and det is not None, (sizes, why)
    assert pose_error(solve_planar_pose(CAM, det.pts_P, det.px, up).cam2pad, G)[0] < 0.004


def _drawn_scale(det, G) -> float:
    """How much larger than at the true pose ``G`` the detection's points lie (spread about their centre)."""
    from benchmarks.blur_bias import drawn_scale

    return drawn_scale(det, CAM, G)


def _soft_jpeg(pad, G, sigma, quality=65):
    img = cv2.GaussianBlur(warp_pad_view(pad, CAM, G, (120, 120, 120)), (0, 0), sigma)
    ok, enc = cv2.imencode(".jpg", cv2.cvtColor(img, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, quality])
    return cv2.cvtColor(cv2.imdecode(enc, cv2.IMREAD_COLOR), cv2.COLOR_BGR2GRAY)


@pytest.mark.parametrize("side_px", [38.0, 60.0])
def test_the_pads_drawing_takes_its_scale_from_the_frame_or_gives_nothing(pad, side_px):
    """The drawing is aligned by an affine warp, whose scale the frame must hold.  A far pad's
    interior is a few pixels per feature, and a frame softer than the drawing is matched by shrinking
    it: unseen45 posed a 39 px pad 7.7 % off from a prediction 7.6 % off, and with the outline
    before it refused, 10.9 % off (a false accept).  So a pad predicted under 45 px is not drawn; a
    softer frame is met by blurring the drawing as much, and refused when that blur is over 3 % of
    the side; and the alignment, restarted 5 % larger and smaller, must come back to where it ended.
    Predictions 7 % off either way, JPEG 65: every pose given is within 2 % of the true scale."""
    from hvloc.synthesis import PadSynthesis

    syn = PadSynthesis(pad)
    h = CAM.fx * pad.side_m / side_px
    rng = np.random.default_rng(int(side_px))
    outcomes = []
    for sigma in (0.6, 2.0, 3.0):
        G = tilted(rng.uniform(-0.1, 0.1) * h, rng.uniform(-0.1, 0.1) * h, h, rng.uniform(0, 2 * np.pi), 0.03, -0.02)
        gray = _soft_jpeg(pad, G, sigma)
        for s in (0.93, 1.07):
            pred = G.copy()
            pred[:3, 3] *= s
            det, why = syn.locate(gray, CAM, pred, None, None, 0.0)
            outcomes.append((sigma, s, why if det is None else round(_drawn_scale(det, G), 3)))
            if det is not None:
                assert abs(_drawn_scale(det, G) - 1) < 0.02, outcomes
            elif side_px < 45:
                assert "predicted pad spans" in why, outcomes
            elif sigma >= 3:
                assert "softer than the smeared drawing" in why, outcomes
    if side_px >= 45:  # a pad large enough, under a camera's ordinary softness, is posed
        assert all(isinstance(o[2], float) for o in outcomes if o[0] < 1), outcomes


def test_an_alignment_whose_scale_the_frame_does_not_hold_gives_nothing(pad, monkeypatch):
    """The scale's probe: where ECC, restarted from its own end 5 % larger or smaller, stays where it
    was put (a flat correlation in scale, as on a far pad's interior), the drawing gives no pose;
    where it comes back, it does."""
    from hvloc.synthesis import PadSynthesis

    G = tilted(0.3, -0.2, 8.0, 0.5, 0.02, 0.03)
    gray = _soft_jpeg(pad, G, 0.6)
    det, why = PadSynthesis(pad).locate(gray, CAM, G, None, None, 0.0)
    assert det is not None and abs(_drawn_scale(det, G) - 1) < 0.01, why
    real, calls = cv2.findTransformECC, []

    def flat_in_scale(a, b, warp, *args):  # the first alignment as it is; every later one stays at its start
        calls.append(1)
        return real(a, b, warp, *args) if len(calls) == 1 else (0.9, warp.copy())

    monkeypatch.setattr(cv2, "findTransformECC", flat_in_scale)
    det, why = PadSynthesis(pad).locate(gray, CAM, G, None, None, 0.0)
    assert det is None and "scale is not settled" in why, why



def test_a_drawing_stretched_to_align_gives_nothing(pad):
    """An affine warp that stretches the drawing along one axis tilts the pose its carried points
    give: seen at an angle a from its normal, a stretch s is a tilt of about s / tan(a).  Aligned under
    glare on a glossy pad (branch exp/glare-rings, fuzz seed 445's frame 73), a warp stretched 9.4 %
    gave a pose 11.3 degrees off in tilt stating 1.3.  Right predictions' warps stretched 0.2-2.4 %;
    past :data:`hvloc.synthesis.MAX_STRETCH` the drawing gives nothing.  Here a view stretched about
    the pad's centre by 0, 2 and 8 % along a slanted axis, drawn at the unstretched pose."""
    import hvloc.synthesis as sy

    G = tilted(0.1, -0.1, 1.2, 0.4, 0.0, 0.5)
    view = cv2.cvtColor(warp_pad_view(pad, CAM, G, GROUND), cv2.COLOR_RGB2GRAY)
    c = CAM.project_from(G, np.zeros((1, 3)))[0]
    axis = np.array([math.cos(0.5), math.sin(0.5)])
    got = {}
    for s in (0.0, 0.02, 0.08):
        A = np.eye(2) + s * np.outer(axis, axis)
        M = np.column_stack([A, c - A @ c])
        gray = cv2.warpAffine(view, M, (CAM.width, CAM.height), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        got[s] = sy.PadSynthesis(pad).locate(gray, CAM, G, None, None, 0.0)
    assert got[0.0][0] is not None and got[0.0][0].info["stretch"] < 0.01, got[0.0]
    assert got[0.02][0] is not None and 0.01 < got[0.02][0].info["stretch"] < sy.MAX_STRETCH, got[0.02]
    det, why = got[0.08]
    assert det is None and "stretched" in why, why

def _rolled_smeared(pad, G, v, w, e, line_s):
    """A frame of CAM read row by row ``line_s`` apart (the middle row at the frame's time) and
    exposed ``e`` s, the camera at ``G`` moving at ``v`` (pad frame) and turning at ``w`` (its own)."""
    ref = (CAM.height - 1) / 2
    acc = np.zeros((CAM.height, CAM.width, 3))
    bands = np.linspace(0, CAM.height, 41).round().astype(int)
    for tau in np.linspace(-e / 2, e / 2, 10):
        for a, b in zip(bands, bands[1:]):
            dt = ((a + b - 1) / 2 - ref) * line_s
            T = G.copy()
            T[:3, 3] = G[:3, 3] + v * (tau + dt)
            T[:3, :3] = G[:3, :3] @ so3_exp(w * (tau + dt))
            acc[a:b] += (warp_pad_view(pad, CAM, T, GROUND, supersample=1)[a:b] / 255.0) ** 2.2
    return cv2.cvtColor(np.clip(255 * (acc / 10) ** (1 / 2.2) + 0.5, 0, 255).astype(np.uint8), cv2.COLOR_RGB2GRAY)


def test_a_smeared_rolling_shutter_frame_is_drawn_band_by_band(pad):
    """A rolling shutter read in 25 ms exposes the frame's rows a frame's smear apart: drawn as one
    instant the pad's drawing is skewed against it.  Told the line time, the drawing is made in
    bands of rows, each at its own time, and the pose (at the middle row's time) comes out as close
    as a global shutter's."""
    from hvloc.synthesis import PadSynthesis

    line_s, e = 0.025 / CAM.height, 0.02
    G = tilted(0.04, -0.06, 0.6, 0.9, 0.02, -0.01)
    v, w = np.array([0.35, -0.2, -0.3]), np.array([0.5, -0.7, 1.2])
    ref = (CAM.height - 1) / 2
    gray = _rolled_smeared(pad, G, v, w, e, line_s)
    pred = G.copy()
    pred[:3, 3] += [0.012, -0.008, 0.01]
    up = G[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    syn = PadSynthesis(pad)
    told, why = syn.locate(gray, CAM, pred, v, w, e, line_s, ref)
    assert told is not None, why
    dp = pose_error(solve_planar_pose(CAM, told.pts_P, told.px, up).cam2pad, G)[0]
    blind, why = syn.locate(gray, CAM, pred, v, w, e)  # the shutter not told
    dp_blind = np.inf if blind is None else pose_error(solve_planar_pose(CAM, blind.pts_P, blind.px, up).cam2pad, G)[0]
    assert dp < 0.004 and dp < 0.5 * dp_blind, (dp, dp_blind, told.info, why)


def test_the_localizer_does_not_unroll_the_smeared_drawings_points_again(pad):
    """The smeared drawing draws each band of rows at its own time and gives each pad point where
    the reference row's projection lands: its points are unrolled already.  The localizer unrolled
    them once more with the shutter's velocity; on an unseen 1080p scene a spiral's turn at 0.35 m
    under 50-260 px of smear then fitted at 3-5 px and was refused (0.3-0.8 px, within 2 mm, once)."""
    from hvloc.shutter import Twist
    from hvloc.synthesis import PadSynthesis

    line_s, e = 0.025 / CAM.height, 0.02
    G = tilted(0.04, -0.06, 0.6, 0.9, 0.02, -0.01)
    v, w = np.array([0.6, -0.4, -0.3]), np.array([0.5, -0.7, 1.2])
    gray = _rolled_smeared(pad, G, v, w, e, line_s)
    pred = G.copy()
    pred[:3, 3] += [0.012, -0.008, 0.01]
    up = G[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    det, why = PadSynthesis(pad).locate(gray, CAM, pred, v, w, e, line_s, (CAM.height - 1) / 2)
    assert det is not None and det.info["by"] == "synthesis", why
    loc = HierarchicalLocalizer(pad, CAM, line_s=line_s)
    loc.twist = Twist(v, w)  # the shutter's motion known, as after a few frames
    res, why = loc._posed(det, "", pred, up, False)
    assert res is not None, why
    pose, _, _ = res
    assert pose_error(pose.cam2pad, G)[0] < 0.004 and pose.rms_px < 1.0, (pose_error(pose.cam2pad, G), pose.rms_px)


def test_a_far_pad_under_jpeg_over_detailed_ground_is_posed(pad):
    """Three frames of bench_v2's v2_wide_jpeg55 at 20 m (a 23 px pad through a 100 degree lens,
    JPEG 55, revision 7's ground; crops kept losslessly in tests/data): the colour hull, made from
    chroma JPEG keeps at half resolution, lies 3-5 px off a corner of the sides fitted to the
    border.  The outline is found (it was refused as "its sides and its colour hull disagree": 18
    of the dataset's 239 frames lost), and with the AHRS's up its pose is within 2.5 % of the
    height (the dataset's accepted poses at 16-20 m: 1.55 % median)."""
    import json
    from pathlib import Path

    from hvloc.phases import detect_outline

    data = Path(__file__).parent / "data"
    doc = json.loads((data / "far_pad_jpeg55.json").read_text())
    strip = cv2.cvtColor(cv2.imread(str(data / "far_pad_jpeg55.png")), cv2.COLOR_BGR2RGB)
    for i, fr in enumerate(doc["frames"]):
        crop = np.ascontiguousarray(strip[:, 96 * i:96 * (i + 1)])
        cam = Camera(96, 96, doc["camera"]["fx"], doc["camera"]["fy"], fr["cx"], fr["cy"], tuple(doc["camera"]["dist"]))
        G = np.array(fr["cam2pad"])
        det, why = detect_outline(crop, pad.geometry, cam, yaw_hint_corner0=np.array(fr["corners_px"][0]))
        assert det is not None, (fr["frame"], why)
        pose = solve_planar_pose(cam, det.pts_P, det.px, up_in_camera(G))
        dp = pose_error(pose.cam2pad, G)[0]
        assert dp < 0.025 * fr["height_m"], (fr["frame"], dp / fr["height_m"], det.info)


def test_a_far_pad_seen_from_the_side_without_an_imu_is_refused_when_its_mirror_fits_as_well(pad):
    """A far pad seen obliquely (16-20 m, 30-35 degrees off the vertical) fits its pose and that
    pose's mirror (IPPE's other solution) to within a few tenths of a pixel.  The IMU's gravity
    tells them apart; without one the fit alone chose, and in one of these three views chose the
    mirror, 97 % of the height off (bench_v2's x_wide_oblique_dusk without an IMU: the first
    pose was a mirror, and the 125 that followed it were too).  Now such a pose is refused and
    says why; with the IMU all three are posed; so they are without one when the camera's mount
    says the view is oblique and the drone level (the pad level for the mount, its mirror 60-70
    degrees off); and near, where the mirror fits far worse, the pad is posed without either."""
    for h, off, far in ((20.0, 14.0, True), (20.0, 10.0, True), (16.0, 12.0, True), (4.0, 2.0, False), (6.0, 3.0, False)):
        G = look_at_cam2world((-off, 0.3, h), (0.0, 0.0, 0.0), up=(0.0, 0.0, -1.0))
        img = warp_pad_view(pad, CAM, G, GROUND)
        alone = HierarchicalLocalizer(pad, CAM, LocalizerConfig()).process(img, 0.0, None)
        if far:
            assert not alone.ok and "fit alike" in alone.reason, (h, off, alone.reason)
        else:
            # (on views summed in light, a sharp outline's sides placed in display values: 2.2 and 2.6 %
            # of the height at 4 and 6 m, under 2 % placed in light; the mirror is a fifth and more off)
            assert alone.ok and pose_error(alone.cam2pad, G)[0] < 0.03 * h, (h, off, alone.status, alone.reason)
        R_W_B = G[:3, :3] @ DEFAULT_T_B_C[:3, :3].T
        told = HierarchicalLocalizer(pad, CAM, LocalizerConfig()).process(img, 0.0, R_W_B)
        assert told.ok and pose_error(told.cam2pad, G)[0] < 0.03 * h, (h, off, told.status, told.reason)
        mount = G.copy()  # the camera mounted looking that way on a level body
        mount[:3, 3] = 0.0
        level = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), T_B_C=mount).process(img, 0.0, None)
        # on the pad's side, not the mirror's 19-28 m away; four corners without gravity are 2-10 % off
        # here: posed, or refused where its covariance says it may be a tenth of the height off
        # (loose_tilt_refusal), the pose kept in the row
        assert level.ok or "fixes the pad's tilt too loosely" in level.reason, (h, off, level.status, level.reason)
        # (on views summed in light, a sharp outline's sides placed in display values: 12.8 % at 20 m)
        assert pose_error(level.cam2pad, G)[0] < 0.15 * h, (h, off, level.status, level.reason)


def test_without_an_imu_the_previous_pose_tells_a_pose_from_its_mirror_by_position(pad):
    """Without an IMU the previous pose chooses between a planar pose and its mirror.  Far and
    oblique, the two lie a fifth of the height and more apart, and a previous pose (a far outline's,
    whose tilt the image hardly fixes) knows its position far better than its tilt.  Given a
    previous pose where the camera is but turned as the mirror is, the right pose is taken (by
    rotation alone the mirror was: conditions' snow_airframe_offnadir, 54 % of the height off).
    Near, a previous pose a frame's motion away (5 % of the height, 3 degrees) chooses right too."""
    geo = pad.geometry
    pts = np.concatenate([geo.outer_corners] + [m.points for m in geo.markers_in("corner")])
    for eye, far in (((-14.0, 0.3, 20.0), True), ((-6.0, 2.0, 12.0), True), ((0.05, 0.0, 1.0), False)):
        G = look_at_cam2world(eye, (0.0, 0.0, 0.0), up=(0.0, 0.0, -1.0))
        px = CAM.project_from(G, pts)
        free = solve_planar_pose(CAM, pts, px)
        mirror = max((free.cam2pad, free.other_cam2pad), key=lambda c: rotation_angle(c[:3, :3], G[:3, :3]))
        assert np.linalg.norm(mirror[:3, 3] - G[:3, 3]) > 0.1 * eye[2]
        prev = G.copy()
        if far:
            prev[:3, :3] = mirror[:3, :3]
        else:
            prev[:3, :3] = G[:3, :3] @ so3_exp(np.radians([2.0, -2.0, 1.0]))
            prev[:3, 3] += np.array([0.03, -0.03, 0.02]) * eye[2]
        chosen = solve_planar_pose(CAM, pts, px, prev_cam2pad=prev)
        assert chosen.flip_choice == "previous"
        assert pose_error(chosen.cam2pad, G)[0] < 0.01 * eye[2], (eye, pose_error(chosen.cam2pad, G))


def test_without_an_imu_a_level_body_is_a_soft_prior_on_the_tilt(pad_fine, monkeypatch):
    """Without an IMU the body's up seen through the mount is where a drone flying nearly level has
    the world's: a prior of LEVEL_SIGMA_DEG on the pad's normal.  A far pad's four corners fix its
    tilt to ~5 degrees, and the pose moves sideways by the height times the tilt error (bench_v2's
    no_imu ablation: 145 false accepts, 101 with the prior).  Over 60 far views of a nearly level
    drone the prior lowers the RMS position error; a near view of the markers, whose many corners
    fix the tilt, on a drone tilted 12 degrees is moved by under a millimetre; and the covariance
    holds the prior."""
    import hvloc.pose as hp

    geo = pad_fine.geometry
    level = DEFAULT_T_B_C[:3, :3].T @ np.array([0.0, 0.0, 1.0])

    def far_rms(sigma_deg):
        monkeypatch.setattr(hp, "LEVEL_SIGMA_DEG", sigma_deg)
        rng, errs = np.random.default_rng(7), []
        for _ in range(60):
            h, ang = rng.uniform(14, 20), rng.uniform(0, 2 * math.pi)
            off = rng.uniform(0, 0.3 * h)
            G = tilted(off * math.cos(ang), off * math.sin(ang), h, rng.uniform(0, 2 * math.pi),
                       *np.radians(rng.normal(0.0, 2.0, 2)))
            px = CAM.project_from(G, geo.outer_corners) + rng.normal(0.0, 0.3, (4, 2))
            r = solve_planar_pose(CAM, geo.outer_corners, px, level_up_C=level)
            if r.flip_choice == "ambiguous":  # (the mirror is another test's: told here by the truth)
                r = solve_planar_pose(CAM, geo.outer_corners, px, prev_cam2pad=G, level_up_C=level)
            errs.append(pose_error(r.cam2pad, G)[0] / h)
        return float(np.sqrt(np.mean(np.square(errs))))

    with_prior, without = far_rms(10.0), far_rms(0.0)
    assert with_prior < 0.92 * without, (with_prior, without)
    G = tilted(0.2, -0.1, 3.0, 0.6, math.radians(9.0), math.radians(-8.0))
    img = warp_pad_view(pad_fine, CAM, G, GROUND)
    det, why = detect_markers(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), pad_fine.geometry, CAM, rgb=img)
    assert det is not None, why
    # (with the errors the markers' corners share, as the localizer passes them: the prior refines
    # the image's own least-squares pose, which that weighting does not make)
    shared = hp.SharedNoise(np.arange(len(det.pts_P)) // 12, 0.2, 0.2)
    poses = {}
    for s in (0.0, 10.0):
        monkeypatch.setattr(hp, "LEVEL_SIGMA_DEG", s)
        poses[s] = solve_planar_pose(CAM, det.pts_P, det.px, level_up_C=level, shared=shared)
    assert pose_error(poses[10.0].cam2pad, poses[0.0].cam2pad)[0] < 0.001
    assert pose_error(poses[10.0].cam2pad, G)[0] < 0.005
    # far: the prior is information the covariance holds (a tighter tilt than the corners' alone)
    px = CAM.project_from(tilted(3.0, 2.0, 18.0, 0.4), geo.outer_corners)
    tilt_sd = {}
    for s in (0.0, 2.0):
        monkeypatch.setattr(hp, "LEVEL_SIGMA_DEG", s)
        cov = solve_planar_pose(CAM, geo.outer_corners, px, level_up_C=level).cov
        tilt_sd[s] = math.degrees(math.sqrt(cov[3, 3] + cov[4, 4]))
    assert tilt_sd[2.0] < 0.6 * tilt_sd[0.0], tilt_sd


def _crop_views(name: str, size: int):
    """Views kept losslessly in tests/data as ``name``.png (a strip of ``size`` x ``size`` crops) and
    ``name``.json (each crop's camera, pose and pad): ``(doc, [(crop, camera, frame), ...])``."""
    import json
    from pathlib import Path

    data = Path(__file__).parent / "data"
    doc = json.loads((data / f"{name}.json").read_text())
    strip = cv2.cvtColor(cv2.imread(str(data / f"{name}.png")), cv2.COLOR_BGR2RGB)
    views = []
    for i, fr in enumerate(doc["frames"]):
        c = fr["camera"]
        views.append((np.ascontiguousarray(strip[:, size * i:size * (i + 1)]),
                      Camera(size, size, c["fx"], c["fy"], c["cx"], c["cy"], tuple(c["dist"])), fr))
    return doc, views


def _named_by_labels(name: str, size: int):
    """Each view of :func:`_crop_views` with its labelled pose and its outline found, the corners
    named from the labels (a localizer names them from its last pose or the whole design):
    ``(frame, cam2pad, camera, detection)``; every outline must be found."""
    from hvloc.phases import detect_outline

    doc, views = _crop_views(name, size)
    geo = make_pad(doc["pad_spec"]).geometry
    for crop, cam, fr in views:
        G = np.array(fr["cam2pad"])
        det, why = detect_outline(crop, geo, cam, yaw_hint_corner0=cam.project_from(G, geo.outer_corners)[0])
        assert det is not None, (fr["frame"], why)
        yield fr, G, cam, det


def _far_pad_jpeg50():
    """unseen29's far frames kept losslessly in tests/data (a 0.5 m pad 17-21 px across at 11-12 m
    through an 85 degree lens pitched 30 degrees, JPEG 50 at dusk): ``(pad, [(crop, camera, frame), ...])``."""
    doc, views = _crop_views("far_pad_jpeg50", 64)
    return make_pad(doc["pad_spec"]), views


def test_a_small_pad_whose_colour_jpeg_swells_is_found_as_a_ring(monkeypatch):
    """On a 17-21 px pad JPEG's half-resolution chroma spreads the border's colour about 3 px past
    the pad and a pixel into its white field: 68-74 % of the hull is coloured where the ring is 42 %
    of the pad, over the 1.6x a large pad may show, and the pad was taken for a solid patch ("no
    pad-coloured quadrilateral").  The ceiling now allows that swell on small pads: these four
    views are found and posed within 6 % of the height with the AHRS's up (their neighbours that
    the localizer accepts: 2 % in the median), and with the former ceiling none is."""
    import hvloc.phases as ph

    pad, views = _far_pad_jpeg50()
    geo = pad.geometry
    for crop, cam, fr in views[:4]:
        G = np.array(fr["cam2pad"])
        det, why = detect_outline(crop, geo, cam, yaw_hint_corner0=np.array(fr["corners_px"][0]))
        assert det is not None, (fr["sequence"], fr["frame"], why)
        pose = solve_planar_pose(cam, det.pts_P, det.px, up_in_camera(G))
        assert pose_error(pose.cam2pad, G)[0] < 0.06 * fr["height_m"], (fr["frame"], det.info)
    ring = 1.0 - (geo.field_side_m / geo.side_m) ** 2
    monkeypatch.setattr(ph, "_ring_share_ceiling", lambda g, side: min(0.95, 1.6 * ring))
    assert all(find_outline(crop, geo, cam)[1] == "no pad-coloured quadrilateral" for crop, cam, _ in views[:4])


def test_a_small_pads_white_field_is_refitted_until_it_settles(monkeypatch):
    """Under JPEG the colour of a 17-21 px pad swells and the white field's luma edges place it
    instead; the field's fit window is the checker's width, about +-1 px there, and a side started
    2-3 px off ended between its start and the field's edge.  Fitted once, the field's worst corner
    on these views lay 5-22 % of its side off and one pose with the AHRS's up was 10.6 % of the
    height off (unseen31: three such false accepts); refitted from where each fit ended, every
    corner within 8 % and every pose within 4 %."""
    import hvloc.phases as ph
    from hvloc.geometry import invert, transform_points
    from hvloc.phases import _mean_side

    pad, views = _far_pad_jpeg50()
    geo = pad.geometry
    worst = {}
    for rounds in (1, ph.FIELD_FIT_ROUNDS):
        monkeypatch.setattr(ph, "FIELD_FIT_ROUNDS", rounds)
        corner, pose = [], []
        for crop, cam, fr in views:
            G = np.array(fr["cam2pad"])
            found, _ = find_outline(crop, geo, cam)
            if found is None or found.field_px is None:
                continue
            truth = cam.project(transform_points(invert(G), geo.field_corners))
            corner.append(min(np.abs(np.roll(q, k, axis=0) - truth).max() for k in range(4)
                              for q in (found.field_px, found.field_px[::-1])) / _mean_side(truth))
            det, why = detect_outline(crop, geo, cam, yaw_hint_corner0=np.array(fr["corners_px"][0]))
            assert det is not None and det.info.get("corners") == "field", (fr["frame"], why)
            pose.append(pose_error(solve_planar_pose(cam, det.pts_P, det.px, up_in_camera(G)).cam2pad, G)[0]
                        / fr["height_m"])
        assert len(corner) >= 6, (rounds, len(corner))
        worst[rounds] = (max(corner), max(pose))
    assert worst[ph.FIELD_FIT_ROUNDS][0] < 0.08 and worst[ph.FIELD_FIT_ROUNDS][1] < 0.04, worst
    assert worst[1][0] > 0.15 and worst[1][1] > 0.08, worst  # what one fit did


def test_a_solid_patch_of_the_border_colour_is_no_ring_however_small():
    """The ring's share ceiling grows on small pads (JPEG swells their colour), but a solid patch of
    the border's colour, 16-30 px and JPEG'd at 50, is still never taken for a ring, while a ring
    of the same size and colour is."""
    from hvloc.phases import _best_ring, _segment

    geo = make_pad().geometry

    def view(side, solid, turn, seed):
        r = np.random.default_rng(seed)
        grey = cv2.GaussianBlur(r.normal(115, 25, (80, 80)).astype(np.float32), (0, 0), 1.0)
        big = cv2.resize(np.clip(np.dstack([grey] * 3), 0, 255).astype(np.uint8), (640, 640),
                         interpolation=cv2.INTER_NEAREST)
        a = math.radians(turn)
        R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        unit = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) @ R.T
        cv2.fillConvexPoly(big, (320 + unit * side * 4).astype(np.int32), geo.border.color_rgb)
        if not solid:
            cv2.fillConvexPoly(big, (320 + unit * side * 4 * geo.field_side_m / geo.side_m).astype(np.int32),
                               (235, 235, 235))
        small = cv2.resize(big, (80, 80), interpolation=cv2.INTER_AREA)
        ok, buf = cv2.imencode(".jpg", cv2.cvtColor(small, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 50])
        return cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)

    for side in (16, 20, 24, 30):
        for turn, seed in ((0, 0), (20, 1), (35, 2)):
            for solid in (False, True):
                mask = _segment(view(side, solid, turn, seed), geo, None, 1)[-1]
                assert (_best_ring(mask, geo) is None) == solid, (side, turn, solid)


def test_the_band_check_reads_a_small_pad_in_stretches_a_jpeg_block_long():
    """The band check reads the border's colour just inside and outside each side in three
    stretches; on a 17-21 px pad under JPEG 50 a stretch is 3-4 px, inside one chroma block, and
    the labelled outline itself failed it in 7 of these 8 views.  Read in stretches at least 11 px
    long (one per side on these pads), the labelled outline passes in 7, and the same outline moved
    3 px, which puts a side on the platform or the ground, still fails in all 8, whichever way it
    moves."""
    from hvloc.phases import _band_missing

    pad, views = _far_pad_jpeg50()
    passed = 0
    for crop, cam, fr in views:
        truth = np.array(fr["corners_px"])
        passed += not _band_missing(crop, truth, pad.geometry, cam)
        for d in ([3, 0], [-3, 0], [0, 3], [0, -3]):
            assert _band_missing(crop, truth + d, pad.geometry, cam), (fr["frame"], d)
    assert passed >= 7, passed


def _far_pad_clean():
    """bench_v2's far clean views kept losslessly in tests/data (28-45 px pads at 11-20 m; one
    with a box's shadow across part of it): ``[(pad, crop, camera, frame), ...]``."""
    return [(make_pad(fr["pad_spec"]), crop, cam, fr) for crop, cam, fr in _crop_views("far_pad_clean", 80)[1]]


def test_a_far_pad_fitted_by_its_drawn_design_loses_the_outlines_height_bias():
    """A step-edge fit of a 28-45 px pad's outline is biased by what lies a few px inside its edges:
    with the AHRS's up these views' heights come out 0.43 % low on average (0.62 % off).  The
    design drawn at the pose and blurred as the camera blurs it, fitted to the frame's luma, places
    them 0.1 % low on average, each within 0.3 %; a crop of ground alone is not taken for the pad."""
    from hvloc.synthesis import PadSynthesis
    from hvloc.texfit import fit_pose_to_design

    step, drawn = [], []
    for pad, crop, cam, fr in _far_pad_clean():
        G = np.array(fr["cam2pad"])
        det, why = detect_outline(crop, pad.geometry, cam, yaw_hint_corner0=np.array(fr["corners_px"][0]))
        assert det is not None, (fr["source"], fr["frame"], why)
        start = solve_planar_pose(cam, det.pts_P, det.px, up_in_camera(G)).cam2pad
        fitted, info = fit_pose_to_design(crop, cam, PadSynthesis(pad), start)
        assert fitted is not None, (fr["source"], fr["frame"], info)
        step.append((start[2, 3] - G[2, 3]) / fr["height_m"])
        drawn.append((fitted[2, 3] - G[2, 3]) / fr["height_m"])
        # the yaw and the tilt stay the IMU's: only where the pad lies, its size and yaw move
        assert math.degrees(rotation_angle(fitted[:3, :3], G[:3, :3])) < 1.0, info
    step, drawn = np.array(step), np.array(drawn)
    assert np.mean(step) < -0.003 and np.mean(np.abs(step)) > 0.004, step  # the bias the outline has
    assert abs(np.mean(drawn)) < 0.0015 and np.max(np.abs(drawn)) < 0.0035, drawn
    assert np.mean(np.abs(drawn)) < 0.5 * np.mean(np.abs(step)), (step, drawn)
    # ground with no pad in it (the first view's corner, tiled) is not fitted as one, in colour or
    # as a grey camera's frame
    pad, crop, cam, fr = _far_pad_clean()[0]
    ground = np.tile(crop[:16, :16], (5, 5, 1))
    for frame in (ground, cv2.cvtColor(ground, cv2.COLOR_RGB2GRAY)):
        got, info = fit_pose_to_design(frame, cam, PadSynthesis(pad), np.array(fr["cam2pad"]))
        assert got is None, info


def test_a_small_windows_ideal_places_are_its_own_not_the_whole_frames_grid(pad):
    """The design fit's window through a lens: its pixels undistorted one by one, the same places as
    read off the whole frame's grid (to a hundredth of a pixel), without making that grid (780 ms
    at 1280x960 on the first far pad, in flight)."""
    from hvloc.geometry import ideal_grid
    from hvloc.synthesis import PadSynthesis

    cam = Camera(1280, 960, 760.0, 760.0, 639.5, 479.5, (-0.1, 0.02, 0.0, 0.0, 0.0))
    syn = PadSynthesis(pad)
    for box in ((500, 400, 590, 470), (0, 0, 64, 48), (1200, 900, 1280, 960)):
        ideal_grid.cache_clear()
        own = syn.window(cam, box, 1.0, own=True)
        assert ideal_grid.cache_info().currsize == 0  # no whole-frame grid made
        grid = syn.window(cam, box, 1.0)
        assert own.shape == grid.shape and np.abs(own - grid).max() < 0.01, (box, np.abs(own - grid).max())
    ideal_grid.cache_clear()


@pytest.mark.parametrize("blur", [0.0, 0.6, 1.0, 1.5])
def test_a_far_pad_fitted_by_its_design_is_as_far_as_it_is_under_any_blur(pad, blur):
    """A camera integrates light over each pixel and blurs it, channel by channel, then writes each
    channel through its tone curve (here: a 4x finer view averaged in light, a Gaussian blur, sRGB).
    The design fit as it was (the frame's grey taken to light as one channel, the tone's exponent
    fitted, the Jacobian's columns 0.2-0.5 correlated with the residual's change) put 15-19 m pads
    0.24-0.62 % too near under 0-1 px of blur.  Each channel drawn in light and written as sRGB, the
    luma compared, the Jacobian right: within 0.2 %, and the blur found within 0.15 px."""
    from hvloc.synthesis import PadSynthesis
    from hvloc.texfit import fit_pose_to_design

    syn, rng = PadSynthesis(pad), np.random.default_rng(int(10 * blur))
    errs = []
    for trial in range(3):
        h = rng.uniform(14.0, 19.0)
        G = tilted(rng.uniform(-1, 1), rng.uniform(-1, 1), h, rng.uniform(0, 2 * np.pi), 0.02, -0.01)
        fine = (warp_pad_view(pad, CAM.scaled(4), G, (120, 90, 60), supersample=1).astype(np.float32) / 255.0) ** 2.2
        light = cv2.resize(fine, (CAM.width, CAM.height), interpolation=cv2.INTER_AREA)
        if blur:
            light = cv2.GaussianBlur(light, (0, 0), blur)
        light += rng.normal(0.0, 0.003, light.shape).astype(np.float32)
        frame = (255.0 * np.clip(light, 0, 1) ** (1 / 2.2) + 0.5).astype(np.uint8)
        fitted, info = fit_pose_to_design(frame, CAM, syn, G)
        assert fitted is not None, info
        assert abs(info["blur_px"] - max(blur, 0.25)) < 0.15, info
        errs.append((fitted[2, 3] - G[2, 3]) / h)
    assert np.max(np.abs(errs)) < 0.002, (blur, errs)


def _camera_view(pad, rng, heights, ground, gamma: float = 2.2, sharpen: float = 0.0, G=None, blur_px: float = 0.6):
    """``(G, h, frame)``: the pad seen from a height drawn in ``heights`` (or from ``G``), as a camera
    makes it: a 4x finer view averaged in light, blurred (``blur_px``), noise, each channel written as
    light ** (1 / gamma) and sharpened by an unsharp mask of 1 px (clipped at black), 8 bits.  A drawn
    heading keeps the pad's sides 3 degrees or more off the pixel rows and columns: a side along them
    crosses the finer view's samples at one phase, its place rounded to an eighth of a pixel (fits of
    12 such views of 30-50 px pads: height errors of 0.11 % RMS against 0.06 % from a 12x finer view)."""
    if G is None:
        h = rng.uniform(*heights)
        yaw = rng.uniform(0, 2 * np.pi)
        off = (yaw + np.pi / 4) % (np.pi / 2) - np.pi / 4  # from the nearest axis
        yaw += math.copysign(max(abs(off), math.radians(3.0)), off) - off
        G = tilted(rng.uniform(-1, 1), rng.uniform(-1, 1), h, yaw, 0.02, -0.01)
    h = float(G[2, 3])
    fine = (warp_pad_view(pad, CAM.scaled(4), G, ground, supersample=1).astype(np.float32) / 255.0) ** 2.2
    light = cv2.GaussianBlur(cv2.resize(fine, (CAM.width, CAM.height), interpolation=cv2.INTER_AREA), (0, 0), blur_px)
    light += rng.normal(0.0, 0.003, light.shape).astype(np.float32)
    written = np.clip(light, 0, 1) ** (1 / gamma)
    written = np.clip((1 + sharpen) * written - sharpen * cv2.GaussianBlur(written, (0, 0), 1.0), 0, 1)
    return G, h, (255.0 * written + 0.5).astype(np.uint8)


def test_a_far_pads_design_is_drawn_over_each_pixels_area(pad, monkeypatch):
    """A camera's pixel sums the light over its area.  The design fit draws each pixel as the mean of
    2 x 2 points over it (:data:`hvloc.texfit.SUBSAMPLES`); drawn at the pixel's centre alone from the
    level whose texels are no larger than a pixel, 17-26 px pads came out 0.2-0.4 % too near on
    average (single views up to 0.6 %; within 0.1 % from 28 px), drawn over the pixel within 0.1 %
    (single views 0.2 %).  On renders whose pixels average 3 x 3 samples, the fit from the labelled
    pose was 0.4 % and 0.3 % too near at 16-20 and 20-30 px, within 0.06 % drawn over the pixel."""
    import hvloc.texfit as tf
    from hvloc.synthesis import PadSynthesis

    syn, rng = PadSynthesis(pad), np.random.default_rng(11)
    views = []
    for side in np.linspace(17.0, 26.0, 8):
        h = CAM.fx * pad.geometry.side_m / side
        views.append(_camera_view(pad, rng, (h, h), (120, 90, 60)))

    def heights(subsamples=None):
        if subsamples is not None:
            monkeypatch.setattr(tf, "SUBSAMPLES", subsamples)
        out = []
        for G, h, frame in views:
            fitted, info = tf.fit_pose_to_design(frame, CAM, syn, G, (2.2, 0.0, 1.0))
            assert fitted is not None, info
            out.append((fitted[2, 3] - G[2, 3]) / h)
        return np.array(out)

    drawn, centred = heights(), heights(1)
    assert abs(np.mean(drawn)) < 0.001 and np.max(np.abs(drawn)) < 0.003, drawn
    assert np.mean(centred) < -0.0015, centred


def test_a_large_pads_design_fit_stops_once_its_steps_are_a_small_share_of_what_they_move(pad, monkeypatch):
    """The design fit stops when its last step moved the pad's image ~0.01 px, its tilt a tenth of its
    doubt (:data:`hvloc.texfit.TILT_SETTLED`) and its blur and sharpening by 0.02 on a 32 px pad, more
    on a larger one (:data:`hvloc.texfit.CAMERA_SETTLED_SIDE_PX`).  Held to 0.02 and a hundredth of a
    px at the tilt's corners whatever the pad's size, 100-120 px pads took 11-13 iterations; now
    fewer, ending within a hundredth of a percent of the height of where those ended; on pads up to
    32 px across nothing changes."""
    import hvloc.texfit as tf
    from hvloc.synthesis import PadSynthesis

    syn, rng = PadSynthesis(pad), np.random.default_rng(0)
    strict, now = [], []
    for side in (28.0, 32.0, 100.0, 120.0, 100.0, 120.0):
        h = CAM.fx * pad.geometry.side_m / side
        G, h, frame = _camera_view(pad, rng, (h, h), (80, 110, 60), blur_px=0.5)
        frame = _jpeg(frame, 70)
        start = G.copy()
        start[:3, 3] = G[:3, 3] * 1.01 + np.array([0.003, -0.002, 0.0]) * h
        for out, held in ((strict, True), (now, False)):
            with monkeypatch.context() as m:
                if held:
                    m.setattr(tf, "TILT_SETTLED", 0.0)
                    m.setattr(tf, "CAMERA_SETTLED_SIDE_PX", math.inf)
                fitted, info = tf.fit_pose_to_design(frame, CAM, syn, start, None, tf.HALVED_MAX_SIDE_PX,
                                                     G[:3, :3].T @ np.array([0.0, 0.0, 1.0]), 0.5)
            assert fitted is not None, info
            out.append((side, (fitted[2, 3] - G[2, 3]) / h, info["iterations"]))
    strict, now = np.array(strict), np.array(now)
    small = strict[:, 0] <= 32
    assert np.array_equal(strict[small], now[small]), (strict, now)
    assert np.abs(now[~small, 1] - strict[~small, 1]).max() < 1e-4, (strict, now)
    assert now[~small, 2].sum() < strict[~small, 2].sum(), (strict, now)


@pytest.mark.parametrize("gamma,sharpen", [(2.42, 0.4), (2.2, 0.5), (2.42, 0.0)])
def test_a_far_pad_fitted_with_its_cameras_known_response_is_as_far_as_it_is(pad, gamma, sharpen):
    """A camera whose tone curve is not sRGB's (written = light ** (1 / 2.42), a gamma of 1.1 on top)
    or that sharpens what it writes (an unsharp mask, clipped at black) moves a far pad's fitted
    size: blurred, an edge's profile as written is the tone's, and the mask's overshoot falls on
    either side of it.  Not known, the design fit puts these 30 px pads 0.15-0.45 % too near; with
    the camera's response known (camera.json's ``response``, the localizer's ``response``) within
    0.12 %, and the localizer's own far pose says the sharpening it drew."""
    from hvloc.synthesis import PadSynthesis
    from hvloc.texfit import fit_pose_to_design

    syn, rng = PadSynthesis(pad), np.random.default_rng(int(100 * gamma + 10 * sharpen))
    errs = {False: [], True: []}
    for trial in range(3):
        G, h, frame = _camera_view(pad, rng, (14.0, 19.0), (120, 90, 60), gamma, sharpen)
        for known in (False, True):
            fitted, info = fit_pose_to_design(frame, CAM, syn, G, (gamma, sharpen, 1.0) if known else None)
            assert fitted is not None, info
            errs[known].append((fitted[2, 3] - G[2, 3]) / h)
    assert np.mean(errs[False]) < -0.0015, errs  # the bias an unknown response leaves
    assert np.max(np.abs(errs[True])) < 0.0012, errs
    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), T_B_C=np.eye(4), response=(gamma, sharpen, 1.0))
    e = loc.process(frame, 0.0, imu=G[:3, :3])  # the body is the camera; the pad lies level
    assert e.status == "ok" and e.method == "outline", e.reason
    assert e.extras["design_fit"]["sharpen"] == round(sharpen, 3) and abs(e.cam2pad[2, 3] - G[2, 3]) / h < 0.0015
    with pytest.raises(ValueError, match="response"):
        HierarchicalLocalizer(pad, CAM, LocalizerConfig(), response=(-2.2, 0.0, 1.0))


def test_a_pad_of_100_to_130_px_in_a_compressed_frame_is_placed_by_its_design(pad, monkeypatch):
    """Where a frame's chroma is at half resolution (JPEG 50 here), the border's colour edges smear
    and the outline's step fit puts a 100-130 px pad several tenths of a percent of the height off; its
    design drawn and fitted on the frame's luma (up to :data:`hvloc.texfit.HALVED_MAX_SIDE_PX`) within
    0.15 %.  The same views uncompressed keep their outline, which is right there (within 0.05 %), and
    do not pay for the fit (above :data:`hvloc.texfit.GLOBAL_MAX_SIDE_PX`)."""
    import hvloc.texfit as tf

    rng = np.random.default_rng(5)
    step = []
    near, far = (CAM.fx * pad.geometry.side_m / px for px in (128.0, 102.0))
    for trial in range(3):
        G, h, frame = _camera_view(pad, rng, (near, far), (70, 110, 50))
        jpeg = _jpeg(frame, 50)

        def posed(img):
            e = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), T_B_C=np.eye(4)).process(img, 0.0, imu=G[:3, :3])
            assert e.status == "ok" and e.method == "outline", e.reason
            return e, (e.cam2pad[2, 3] - G[2, 3]) / h

        e, dh = posed(frame)
        assert not isinstance(e.extras.get("design_fit"), dict) and abs(dh) < 0.0005, (e.extras.get("design_fit"), dh)
        e, dh = posed(jpeg)
        assert isinstance(e.extras.get("design_fit"), dict) and abs(dh) < 0.0015, (e.extras.get("design_fit"), dh)
        with monkeypatch.context() as m:  # the step fit alone, as before
            m.setattr(tf, "HALVED_MAX_SIDE_PX", tf.MAX_SIDE_PX)
            step.append(posed(jpeg)[1])
    assert np.mean(np.abs(step)) > 0.002, step


def test_a_level_pad_of_64_to_100_px_is_tilted_by_its_design_not_by_the_ahrs(pad, monkeypatch):
    """Under a global shutter the step fit places a 64-100 px pad well, but tilts it as the AHRS does
    (its four corners say little of a few tenths of a degree), and the AHRS's error moves the pose
    sideways by the height times that error: bench_v1's sim800 at 64-100 px, 1.01 % of the height.
    Its design fitted with its tilt (up to :data:`hvloc.texfit.GLOBAL_MAX_SIDE_PX`), as it is at
    44-64 px, puts it within a fraction of that (0.09 % there).  Under a rolling shutter it is not
    fitted there: the drawing is a global shutter's."""
    import hvloc.phases as ph
    import hvloc.texfit as tf

    # a frame whose chroma is whole (a plain ground's few colour edges would read as halved, whose
    # rule is HALVED_MAX_SIDE_PX's)
    monkeypatch.setattr(ph, "chroma_halved", lambda rgb: False)
    rng = np.random.default_rng(17)
    lateral = {"design": [], "step": []}
    for trial in range(4):
        side = rng.uniform(tf.MAX_SIDE_PX + 4, tf.GLOBAL_MAX_SIDE_PX - 4)
        h = CAM.fx * pad.geometry.side_m / side
        G = tilted(rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), h, rng.uniform(0, 2 * np.pi), 0.02, -0.01)
        frame = _camera_view(pad, rng, None, (70, 110, 50), G=G)[2]
        phi = rng.uniform(0, 2 * np.pi)
        imu = so3_exp(math.radians(0.5) * np.array([math.cos(phi), math.sin(phi), 0.0])) @ G[:3, :3]
        for kind in ("design", "step"):
            with monkeypatch.context() as m:
                if kind == "step":  # as before: the design fitted up to MAX_SIDE_PX
                    m.setattr(tf, "GLOBAL_MAX_SIDE_PX", tf.MAX_SIDE_PX)
                e = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), T_B_C=np.eye(4)).process(frame, 0.0, imu=imu)
            assert e.ok and e.method == "outline", (trial, kind, e.status, e.reason)
            assert ("tilt_deg" in e.extras.get("design_fit", {})) == (kind == "design"), (trial, kind, e.extras.get("design_fit"))
            lateral[kind].append(float(np.linalg.norm((e.cam2pad[:3, 3] - G[:3, 3])[:2])) / h)
        rolling = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), T_B_C=np.eye(4), line_s=2e-5).process(frame, 0.0, imu=imu)
        assert rolling.ok and not isinstance(rolling.extras.get("design_fit"), dict), rolling.extras.get("design_fit")
    assert np.mean(lateral["step"]) > 0.005, lateral  # the premise: the AHRS's half degree
    assert np.mean(lateral["design"]) < 0.3 * np.mean(lateral["step"]), lateral


def _pitched_view(pad, rng, side_px, pitch_deg=35.0):
    """``T_P_C`` of a camera pitched ``pitch_deg`` off nadir whose view holds the pad near its centre,
    ``side_px`` across (about), yawed at random."""
    d = CAM.fx * pad.geometry.side_m / side_px
    pitch = math.radians(pitch_deg)
    G = tilted(0.0, 0.0, d * math.cos(pitch), rng.uniform(0, 2 * np.pi), 0.0, pitch)
    axis = G[:3, 2]
    hit = G[:3, 3] - G[2, 3] / axis[2] * axis  # where the optical axis meets the pad's plane
    G[:2, 3] -= hit[:2] + rng.uniform(-0.3, 0.3, 2)
    return G


def test_a_pitched_cameras_far_pad_is_as_high_as_it_is_when_its_tilt_is_fitted(pad, monkeypatch):
    """A camera pitched 35 degrees off nadir sees a 55-110 px pad foreshortened along its pitch, by how
    much the pad's tilt says; the AHRS's tilt error (0.4 degrees here) then puts the design fit's pose
    (its tilt held) 0.4-1.5 % of the height off (unseen104: 0.38 % high in the median).  With the tilt
    fitted too, weighed against the IMU's up (:data:`hvloc.texfit.TILT_MIN_SIDE_PX`), and the pose
    solved with the fitted up, the height is within a few tenths of that and the tilt within
    0.2 degrees on average; held, as before, neither."""
    import hvloc.texfit as tf

    rng = np.random.default_rng(11)
    errs = {True: [], False: []}
    for trial in range(6):
        G = _pitched_view(pad, rng, rng.uniform(55, 110))
        h = G[2, 3]
        frame = _jpeg(_camera_view(pad, rng, None, (120, 110, 90), G=G)[2], 70)
        phi = rng.uniform(0, 2 * np.pi)
        imu = so3_exp(math.radians(0.4) * np.array([math.cos(phi), math.sin(phi), 0.0])) @ G[:3, :3]
        for fit in (False, True):
            with monkeypatch.context() as m:
                if not fit:  # the tilt held, as before
                    m.setattr(tf, "TILT_MIN_SIDE_PX", math.inf)
                e = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), T_B_C=np.eye(4)).process(frame, 0.0, imu=imu)
            assert e.ok and isinstance(e.extras.get("design_fit"), dict), (e.status, e.reason, e.extras.get("design_fit"))
            assert ("tilt_deg" in e.extras["design_fit"]) == fit, e.extras["design_fit"]
            errs[fit].append((abs(e.cam2pad[2, 3] - h) / h, math.degrees(rotation_angle(e.cam2pad[:3, :3], G[:3, :3]))))
    held, fitted = np.array(errs[False]), np.array(errs[True])
    assert np.mean(held[:, 0]) > 0.004 and np.mean(held[:, 1]) > 0.3, held  # the premise: the AHRS's tilt costs
    assert np.mean(fitted[:, 0]) < 0.4 * np.mean(held[:, 0]) and np.mean(fitted[:, 1]) < 0.2, (held, fitted)


def test_a_tilting_decks_pad_is_posed_by_its_design_fitted_with_its_tilt(pad, monkeypatch):
    """On a deck that may tilt 10 degrees (``pad_tilt_deg``) the IMU's up says little of the pad's
    tilt, and a 70-100 px pad's four corners fix it loosely: tilted 6 degrees here, its outline's
    poses were refused as too loosely fixed (sideways sigma 3.5-11 % of the height) or taken 3-6
    degrees and 5-10 % of the height off.  Its design fitted with the tilt (the IMU's up its prior,
    at the deck's sigma) fixes it: every view posed within 1.5 % of the height and a degree (the
    smoke suite's deck: Approaching 26 -> 60 % posed)."""
    import hvloc.localizer as L
    import hvloc.texfit as tf

    rng = np.random.default_rng(4)
    cfg = LocalizerConfig(pad_tilt_deg=10.0, use_markers=False)
    for trial in range(4):
        h = CAM.fx * pad.geometry.side_m / rng.uniform(70, 100)
        G = tilted(rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), h, rng.uniform(0, 2 * np.pi),
                   rng.uniform(-0.03, 0.03), rng.uniform(-0.03, 0.03))
        frame = _jpeg(_camera_view(pad, rng, None, (120, 110, 90), G=G)[2], 70)
        phi = rng.uniform(0, 2 * np.pi)
        imu = so3_exp(math.radians(6.0) * np.array([math.cos(phi), math.sin(phi), 0.0])) @ G[:3, :3]  # the deck's tilt
        e = HierarchicalLocalizer(pad, CAM, cfg, T_B_C=np.eye(4)).process(frame, 0.0, imu=imu)
        assert e.ok and "tilt_deg" in e.extras.get("design_fit", {}), (trial, e.status, e.reason)
        dp, dr = pose_error(e.cam2pad, G)
        assert dp < 0.015 * h and dr < 1.0, (trial, dp / h, dr)
        with monkeypatch.context() as m:  # the tilt held, as before
            m.setattr(tf, "TILT_MIN_SIDE_PX", math.inf)
            m.setattr(L, "UNTRACKED_TILT_MIN_SIDE_PX", math.inf)
            e = HierarchicalLocalizer(pad, CAM, cfg, T_B_C=np.eye(4)).process(frame, 0.0, imu=imu)
        assert not e.ok or pose_error(e.cam2pad, G)[0] > 0.02 * h, (trial, e.status, pose_error(e.cam2pad, G))


def test_a_design_fit_that_held_the_found_corners_tilt_states_their_noise(pad, monkeypatch):
    """A pad under :data:`hvloc.texfit.TILT_MIN_SIDE_PX` has its design fitted with the tilt held
    where its found corners and the IMU's up put it: the fitted corners carry that tilt, with the
    found corners' error, however well the design placed the rest.  Stated at the 0.3 px every
    corner gets, a random scene (fuzz seed 142: a nested pad's 37 px outline, found 1-1.7 px off by
    its fine checker border, on a deck told 7 degrees) was posed 21 % of the height off, 7 of its
    sigmas, "ok".  Here the found corners are 0.8 px off on a deck tilting 5 degrees (told 8), the
    design's tilt held below TILT_MIN_SIDE_PX (as where it cannot be fitted on an untracked deck: under
    :data:`hvloc.localizer.UNTRACKED_TILT_MIN_SIDE_PX`, or blurred): every pose, taken or refused, lies
    within 3 of its stated sigmas sideways (before: up to 16, and one taken 27 % of the height off),
    and none is taken wrong."""
    import hvloc.localizer as L
    import hvloc.phases as ph
    from hvloc.texfit import TILT_MIN_SIDE_PX

    monkeypatch.setattr(L, "UNTRACKED_TILT_MIN_SIDE_PX", TILT_MIN_SIDE_PX)

    real, offset = ph.find_outline, {}

    def found_off(*args, **kwargs):  # the outline's corners as a biased edge fit places them
        found, why = real(*args, **kwargs)
        return (found if found is None else dataclasses.replace(found, quad_px=found.quad_px + offset["px"])), why

    monkeypatch.setattr(ph, "find_outline", found_off)
    rng = np.random.default_rng(2)
    cfg = LocalizerConfig(pad_tilt_deg=8.0, use_markers=False, use_flow=False)
    held = 0
    for trial in range(12):
        h = CAM.fx * pad.geometry.side_m / rng.uniform(24, 0.95 * TILT_MIN_SIDE_PX)
        G = tilted(rng.uniform(-0.05, 0.05) * h, rng.uniform(-0.05, 0.05) * h, h, rng.uniform(0, 2 * np.pi),
                   rng.uniform(-0.03, 0.03), rng.uniform(-0.03, 0.03))
        frame = _camera_view(pad, rng, None, GROUND, G=G)[2]
        phi = rng.uniform(0, 2 * np.pi)
        imu = so3_exp(math.radians(5.0) * np.array([math.cos(phi), math.sin(phi), 0.0])) @ G[:3, :3]  # the deck's tilt
        offset["px"] = rng.normal(0.0, 0.8, (4, 2))
        e = HierarchicalLocalizer(pad, CAM, cfg, T_B_C=np.eye(4)).process(frame, 0.0, imu=imu)
        dp, dr = pose_error(e.cam2pad, G) if e.cam2pad is not None else (0.0, 0.0)
        assert not (e.ok and (dp > 0.1 * h or dr > 5.0)), (trial, e.status, dp / h, dr)
        fit = e.extras.get("design_fit")
        if e.cam2pad is None or not isinstance(fit, dict) or "tilt_deg" in fit:
            continue
        held += 1
        d = e.cam2pad[:2, 3] - G[:2, 3]
        assert d @ np.linalg.solve(e.cov[:2, :2], d) < 9.0, (trial, e.status, d / h, np.sqrt(np.diag(e.cov[:2, :2])) / h)
    assert held >= 8, held  # the premise: the design held the tilt in most views


def test_a_grey_cameras_pad_on_a_tilting_deck_is_posed_where_its_design_fits_the_tilt(pad):
    """A grey frame's outline is its white field's four corners, which on a tilted pad came out
    10-12 degrees off in tilt (deck_mono): on a deck whose tilt is not tracked yet they are not
    posed.  Its design, fitted with the tilt where the pad is large and sharp enough
    (:data:`hvloc.texfit.TILT_MIN_SIDE_PX`, up to :data:`hvloc.texfit.MAX_SIDE_PX` in a frame without
    chroma), fixes the tilt as on a colour frame: those pads are posed, each within 3 of its stated
    sigmas and none wrong (before: every one refused; random scenes fz128, fz121 and fz102 lost
    half their frames so).  A smaller one is still refused on a first sight, saying why: its tilt
    not fitted, or fitted (:data:`hvloc.localizer.UNTRACKED_TILT_MIN_SIDE_PX`) but not yet seen to
    agree from frame to frame.  (From 56 px: nearer 44 px, under this 60 degree lens the drawing's own
    error, :data:`hvloc.texfit.DESIGN_MODEL_PX`, leaves the tilt too loose to take.)"""
    from hvloc.texfit import MAX_SIDE_PX, TILT_MIN_SIDE_PX

    rng = np.random.default_rng(4)
    cfg = LocalizerConfig(pad_tilt_deg=10.0, use_markers=False)
    posed = refused = 0
    for trial, side_px in enumerate([rng.uniform(56.0, MAX_SIDE_PX - 2) for _ in range(6)] + [36.0, 40.0, 42.0]):
        h = CAM.fx * pad.geometry.side_m / side_px
        G = tilted(rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), h, rng.uniform(0, 2 * np.pi),
                   rng.uniform(-0.03, 0.03), rng.uniform(-0.03, 0.03))
        grey = cv2.cvtColor(_jpeg(_camera_view(pad, rng, None, (120, 110, 90), G=G)[2], 70), cv2.COLOR_RGB2GRAY)
        phi = rng.uniform(0, 2 * np.pi)
        imu = so3_exp(math.radians(6.0) * np.array([math.cos(phi), math.sin(phi), 0.0])) @ G[:3, :3]  # the deck's tilt
        e = HierarchicalLocalizer(pad, CAM, cfg, T_B_C=np.eye(4)).process(np.dstack([grey] * 3), 0.0, imu=imu)
        if side_px < TILT_MIN_SIDE_PX:
            assert not e.ok, (trial, side_px, e.status)
            refused += "its design did not fit it" in e.reason or "too loosely" in e.reason  # (else its field was not found at all)
            continue
        assert e.ok and e.method == "outline" and "tilt_deg" in e.extras.get("design_fit", {}), (trial, e.status, e.reason)
        dp, dr = pose_error(e.cam2pad, G)
        assert dp < 0.1 * h and dr < 5.0, (trial, dp / h, dr)
        d = e.cam2pad[:2, 3] - G[:2, 3]
        assert d @ np.linalg.solve(e.cov[:2, :2], d) < 9.0, (trial, d / h, np.sqrt(np.diag(e.cov[:2, :2])) / h)
        posed += 1
    assert posed == 6 and refused >= 1, (posed, refused)


def _deck_view(pad, rng, side_px: float, grey: bool) -> tuple:
    """``(G, frame, v)``: a pad ``side_px`` across seen from a random nearly nadir pose ``G``, on a
    deck tilting 6 degrees in a random direction (``v``: that tilt in the world, a rotation vector;
    the IMU reads ``so3_exp(v) @ G[:3, :3]``)."""
    h = CAM.fx * pad.geometry.side_m / side_px
    G = tilted(rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), h, rng.uniform(0, 2 * np.pi),
               rng.uniform(-0.03, 0.03), rng.uniform(-0.03, 0.03))
    frame = _camera_view(pad, rng, None, (120, 110, 90), G=G)[2]
    phi = rng.uniform(0, 2 * np.pi)
    return G, _grey(frame) if grey else frame, math.radians(6.0) * np.array([math.cos(phi), math.sin(phi), 0.0])


@pytest.mark.parametrize("grey", [False, True])
def test_a_near_pad_on_an_untracked_deck_is_posed_by_its_design_fitted_with_its_tilt(pad, grey):
    """The design is fitted on pads up to :data:`hvloc.texfit.GLOBAL_MAX_SIDE_PX` (larger ones the step
    fit places well on level ground), :data:`hvloc.texfit.HALVED_MAX_SIDE_PX` under JPEG's halved chroma.
    On a deck whose tilt is not tracked only the design fixes the tilt: a sharp frame's 66-130 px
    pad on a deck tilting 6 degrees (told 10) was posed by its corners 0.2-1.8 % of the height off
    or refused as loosely fixed (3 of 10); in a grey frame, whose corners are not posed there, every
    one was refused (fuzz seed 146 lost 76 frames so).  The design is fitted up to
    HALVED_MAX_SIDE_PX there: every view posed by it, with its tilt, within 0.5 % of the height."""
    from hvloc.texfit import HALVED_MAX_SIDE_PX, MAX_SIDE_PX

    rng = np.random.default_rng(4)
    cfg = LocalizerConfig(pad_tilt_deg=10.0, use_markers=False)
    for trial in range(5):
        side = rng.uniform(MAX_SIDE_PX + 2, HALVED_MAX_SIDE_PX - 10)
        G, frame, v = _deck_view(pad, rng, side, grey)
        h = G[2, 3]
        e = HierarchicalLocalizer(pad, CAM, cfg, T_B_C=np.eye(4)).process(frame, 0.0, imu=so3_exp(v) @ G[:3, :3])
        assert e.ok and "tilt_deg" in e.extras.get("design_fit", {}), (trial, side, e.status, e.reason)
        dp, dr = pose_error(e.cam2pad, G)
        assert dp < 0.005 * h and dr < 0.5, (trial, side, dp / h, dr)


@pytest.mark.parametrize("grey", [False, True])
def test_a_decks_tilt_is_tracked_from_an_outline_whose_design_fixed_it(pad, grey):
    """An outline whose design fit fixed the pad's tilt surely (within :data:`hvloc.localizer.SURE_TILT_DEG`)
    measured it with the whole pad's drawing, as a texture pose's points do: the deck's track takes it
    (its four corners alone never count).  Left out, fzu165's grey deck was posed by such outlines from 3 m
    to 2 m, 0.1-0.4 % of the height off, its tilt untracked, and the 36 marker corners that came next
    were refused as loose.  The track is the deck's tilt within 3 of its sigmas.  A track of one pose
    does not know the swell's rate and spreads within tenths of a second: past
    :data:`hvloc.localizer.DECK_TRACKED_SIGMA_DEG` the deck counts as untracked again (where fzu165's
    grey outline was no longer fitted by its design and was posed 5.6 % of the height off), until the
    next pose tells it."""
    from hvloc.localizer import DECK_TRACKED_SIGMA_DEG

    rng = np.random.default_rng(12)
    cfg = LocalizerConfig(pad_tilt_deg=10.0, use_markers=False)
    for trial in range(2):
        G, frame, v = _deck_view(pad, rng, rng.uniform(70.0, 95.0), grey)
        loc = HierarchicalLocalizer(pad, CAM, cfg, T_B_C=np.eye(4))
        assert not loc.deck.prior(0.0)[3]
        for t, tracked in ((0.0, False), (0.05, True), (0.5, False), (0.55, True)):
            e = loc.process(frame, t, imu=so3_exp(v) @ G[:3, :3])
            assert loc.deck_tracked == tracked, (trial, t, loc.up_sigma_deg)
            assert e.ok and e.method == "outline" and "design_normal_C" in e.extras, (trial, t, e.status, e.reason)
            tilt, sigma, _, known = loc.deck.prior(t)
            assert known and sigma < DECK_TRACKED_SIGMA_DEG, (trial, t, sigma)
            assert np.linalg.norm(tilt[:2] - v[:2]) < 3.0 * math.radians(sigma), (trial, t, np.degrees(tilt - v), sigma)
        assert loc.deck.prior(1.0)[1] > DECK_TRACKED_SIGMA_DEG  # (two poses 0.05 s apart: the rate not yet learnt)


def test_markers_that_stood_on_a_track_only_design_fits_made_do_not_move_it(pad):
    """A far markers fit can lie degrees off its stated sigma (fz253's 13-15 px markers: 5 degrees off,
    stating 0.96).  On a track of their own they were taken first where they stood alone; on one
    that only design-fitted outlines made they may stand on it, and there they must not feed it
    (fz253's drew its track 5 degrees off in a frame and were posed up to 11 % of the height off).
    Here a near view's markers on such a track leave it where it was predicted; the same view on a
    deck not tracked yet starts a track of the markers'."""
    rng = np.random.default_rng(5)
    cfg = LocalizerConfig(pad_tilt_deg=10.0)
    v = math.radians(6.0) * np.array([0.6, 0.8, 0.0])
    views = []
    for side in (85.0, 260.0):
        h = CAM.fx * pad.geometry.side_m / side
        G = tilted(0.1, -0.1, h, 0.7, 0.02, -0.01)
        views.append((G, _camera_view(pad, rng, None, (120, 110, 90), G=G)[2]))
    loc = HierarchicalLocalizer(pad, CAM, cfg, T_B_C=np.eye(4))
    (Gf, far), (Gn, near) = views
    e = loc.process(far, 0.0, imu=so3_exp(v) @ Gf[:3, :3])
    assert e.ok and e.method == "outline" and loc.deck.by_design, (e.status, e.reason, e.method)
    predicted = loc.deck._predicted(0.3)[0].copy()
    e = loc.process(near, 0.3, imu=so3_exp(v) @ Gn[:3, :3])  # (as fast as a drone may come nearer)
    assert e.ok and e.method == "markers", (e.status, e.reason, e.method)
    assert loc.deck.t == 0.0 and loc.deck.by_design, (loc.deck.t, np.degrees(loc.deck.x), np.degrees(predicted))
    fresh = HierarchicalLocalizer(pad, CAM, cfg, T_B_C=np.eye(4))
    for t in (0.05, 0.1):  # (the first frame in the Approaching phase: its outline, which tells no tilt here)
        e = fresh.process(near, t, imu=so3_exp(v) @ Gn[:3, :3])
    assert e.ok and e.method == "markers" and fresh.deck.t == 0.1 and not fresh.deck.by_design, (e.status, e.reason)


def test_a_design_fits_tilt_with_its_prior_taken_out_is_the_images_alone():
    """The deck's track takes a design fit's tilt as a measurement of its own, so the IMU's up the fit
    was weighed against is taken out again: that image-only normal and doubt, weighed with the same
    prior, give back the fit's; and a fit that told nothing beyond its prior gives nothing."""
    from hvloc.localizer import _image_only_up

    rng = np.random.default_rng(3)
    for _ in range(20):
        prior = so3_exp(rng.normal(0.0, 0.1, 3)) @ np.array([0.0, 0.0, 1.0])
        sp = rng.uniform(1.0, 8.0)
        sm = rng.uniform(0.05, 0.9) * sp
        axis = np.cross(prior, rng.normal(size=3))
        fitted = so3_exp(axis / np.linalg.norm(axis) * math.radians(rng.uniform(0.0, 3.0))) @ prior
        got = _image_only_up(fitted, sm, prior, sp)
        si, n = math.radians(got["design_tilt_sigma_deg"]), got["design_normal_C"]
        w_i, w_p = 1.0 / si ** 2, 1.0 / math.radians(sp) ** 2
        assert 1.0 / math.sqrt(w_i + w_p) == pytest.approx(math.radians(sm), rel=1e-9)
        # the two Gaussians' mean, along the great circle through both (they lie on one, with the fit)
        ang = math.atan2(np.linalg.norm(np.cross(prior, n)), prior @ n) * w_i / (w_i + w_p)
        mean = so3_exp(np.cross(prior, n) / np.linalg.norm(np.cross(prior, n)) * ang) @ prior
        assert np.linalg.norm(mean - fitted) < 1e-9
    assert _image_only_up(prior, 0.99 * sp, prior, sp) == {} and _image_only_up(prior, math.nan, prior, sp) == {}


def test_a_stained_pads_fitted_tilt_is_doubted_for_the_drawings_own_error(pad, monkeypatch):
    """A small pad's tilt shows only in its foreshortening, a tenth of a pixel across a 30-40 px pad
    per few degrees: stains the design does not show move that more than the pixels' noise says.  A
    fuzz scene's dirty 31 px pad, fitted from its labelled pose, went 3.5 degrees off stating 0.9.  The
    doubt the fit states carries the drawing's own error (:data:`hvloc.texfit.DESIGN_MODEL_PX`): every
    stained view here within 3 of its stated doubt, as none was without it while every stain's pixels
    counted.  Since a stain's patch is left out where the tilt is fitted (fuzz seed 545's shadow,
    :func:`hvloc.texfit._unexplained`) the stains pull less: without the drawing's error the worst
    view here lies 2.8 of its doubt off.  The error stays for what no patch shows (a relief, wear)."""
    import hvloc.texfit as tf
    from hvloc.synthesis import PadSynthesis
    from render.textures import dirty_texture

    syn = PadSynthesis(pad)

    def ratios():
        rng, out = np.random.default_rng(5), []
        for trial in range(8):
            dirty = dataclasses.replace(pad, texture_rgb=dirty_texture(pad.texture_rgb, 0.3, 100 + trial))
            side = rng.uniform(28.0, 40.0)
            G = _pitched_view(pad, rng, side, pitch_deg=15.0)
            frame = _camera_view(dirty, rng, None, (120, 110, 90), G=G, blur_px=0.6)[2]
            up_C = G[:3, :3].T @ np.array([0.0, 0.0, 1.0])
            got, info = tf.fit_pose_to_design(frame, CAM, syn, G, max_side_px=tf.HALVED_MAX_SIDE_PX, up_C=up_C,
                                              up_sigma_deg=5.0, tilt_min_side_px=24.0)
            assert got is not None and "tilt_deg" in info, (trial, info)
            if tf.DESIGN_MODEL_PX > 0:  # at least the drawing's error, with the prior's weight
                floor = math.degrees(tf.DESIGN_MODEL_PX * CAM.fx / side**2)
                assert info["tilt_sigma_deg"] >= 0.99 / math.hypot(1 / floor, 1 / 5.0), (trial, side, info)
            n = got[:3, :3].T @ np.array([0.0, 0.0, 1.0])
            out.append(math.degrees(math.acos(min(1.0, float(n @ up_C)))) / info["tilt_sigma_deg"])
        return np.array(out)

    assert ratios().max() < 3.0
    monkeypatch.setattr(tf, "DESIGN_MODEL_PX", 0.0)
    monkeypatch.setattr(tf, "PATCH_K", 0.0)  # (no patch left out)
    assert ratios().max() > 3.0  # the premise: the pixels' noise alone understates where the stains pull


def test_a_drawing_that_matches_its_pad_poorly_doubts_the_pads_fitted_tilt_more(pad, monkeypatch):
    """Where the fitted drawing explains the pad poorly (its correlation with the frame under
    :data:`hvloc.texfit.DESIGN_MODEL_NCC`: stains, a grey camera's JPEG), it misplaces a far pad's tilt
    by more than the drawing's usual error: fz377's grey JPEG 60 pads, 51-54 px at 11 m matched at
    0.90, had tilts stated to 1.6-2.0 degrees 5-7 off, 1-1.3 m, accepted.  The drawing's error then
    grows as 1 - ncc.  Here: heavily stained 44-56 px grey views, JPEG 50, 18 degrees off nadir, each
    fitted from (and weighed against) a tilt 4 degrees off.  Every view within 1.5 of its stated
    doubt; stated with the usual error, the worst were nearly twice it off."""
    import hvloc.texfit as tf
    from hvloc.synthesis import PadSynthesis
    from render.textures import dirty_texture

    syn = PadSynthesis(pad)

    def fits():
        rng, out = np.random.default_rng(7), []
        for trial in range(10):
            dirty = dataclasses.replace(pad, texture_rgb=dirty_texture(pad.texture_rgb, 0.7, 200 + trial))
            G = _pitched_view(dirty, rng, rng.uniform(44.0, 56.0), pitch_deg=18.0)
            frame = _jpeg(_grey(_camera_view(dirty, rng, None, (120, 110, 90), G=G, blur_px=0.6)[2]), 50)
            turn = so3_exp(math.radians(4.0) * np.array([math.cos(phi := rng.uniform(0, 2 * np.pi)), math.sin(phi), 0.0]))
            start = G.copy()
            start[:3, :3], start[:3, 3] = turn @ G[:3, :3], turn @ G[:3, 3]  # (the pad turned about its centre)
            got, info = tf.fit_pose_to_design(frame, CAM, syn, start, max_side_px=tf.HALVED_MAX_SIDE_PX,
                                              up_C=start[:3, :3].T @ np.array([0.0, 0.0, 1.0]), up_sigma_deg=5.0,
                                              tilt_min_side_px=40.0)
            assert got is not None and "tilt_deg" in info, (trial, info)
            up = np.array([0.0, 0.0, 1.0])
            off = math.degrees(math.acos(min(1.0, float((got[:3, :3].T @ up) @ (G[:3, :3].T @ up)))))
            out.append((off / info["tilt_sigma_deg"], info["ncc"], info["tilt_sigma_deg"]))
        return np.array(out)

    scaled = fits()
    poor = scaled[:, 1] < tf.DESIGN_MODEL_NCC
    assert (scaled[:, 1] < tf.DESIGN_MODEL_NCC - 0.03).sum() >= 4, scaled[:, 1]  # the premise: poorly matched views
    assert scaled[:, 0].max() < 1.5, scaled
    monkeypatch.setattr(tf, "DESIGN_MODEL_NCC", 0.0)  # the drawing's usual error, however it matches
    usual = fits()
    assert np.all(scaled[:, 2] >= usual[:, 2] - 1e-9) and np.all(scaled[poor, 2] > usual[poor, 2]), (scaled, usual)
    assert usual[:, 0].max() > 1.5, usual  # the premise: stated so, the worst views lie further off


def _shadowed(frame, G, rng, pad, cover: float):
    """``frame`` with a hard shadow (60 % of the light taken) over a square 0.6 of the pad's side
    beside one of its sides, reaching ``cover`` of the side onto the pad: the drone's own shadow
    under a high sun, as it lies in fuzz seed 545's frames."""
    half = pad.geometry.side_m / 2
    quad = CAM.project_from(G, np.array([[-half, half, 0], [half, half, 0], [half, -half, 0], [-half, -half, 0.0]]))
    k = int(rng.integers(4))
    mid = (quad[k] + quad[(k + 1) % 4]) / 2
    out = (mid - quad.mean(axis=0)) / np.linalg.norm(mid - quad.mean(axis=0))
    side = float(np.linalg.norm(quad[(k + 1) % 4] - quad[k]))
    along, s = (quad[(k + 1) % 4] - quad[k]) / side, 0.6 * side
    centre = mid + out * (s / 2 - cover * side)
    corners = np.array([centre + (a * along + b * out) * s / 2 for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    m = np.zeros(frame.shape[:2], np.float32)
    cv2.fillConvexPoly(m, np.round(corners * 16).astype(np.int32), 1.0, cv2.LINE_AA, 4)
    m = cv2.GaussianBlur(m, (0, 0), 0.8)[..., None]
    return (frame * (1.0 - 0.6 * m) + 0.5).astype(np.uint8)


@pytest.mark.parametrize("grey", [False, True], ids=["colour", "grey_jpeg60"])
def test_a_shadow_beside_a_far_pad_does_not_steer_its_fitted_tilt(pad, monkeypatch, grey):
    """A far pad's tilt shows only in its foreshortening, a few tenths of a pixel per degree.  A hard
    shadow over part of it and the ground beside it (the drone's own, under a high sun) is light the
    drawing does not hold.  Down-weighted by Huber's rule its pixels still pull, each by a bounded
    amount, and together they outweighed that signal: fuzz seed 545's grey 47-58 px pad, fitted from
    its labelled pose, tilted 3.3-7.8 degrees off stating 1.5-1.7 (two false accepts).  Where the tilt
    is fitted, a patch the held fit leaves unexplained counts for nothing
    (:func:`hvloc.texfit._unexplained`).  Here 44-62 px views pitched 15 degrees, a shadow reaching
    10-30 % of the side onto the pad, fitted from the labelled pose against a 5 degree prior: every
    tilt within 0.6 degrees in colour, 1.2 in grey under JPEG 60, half within 0.3 and 0.6; every pixel
    counted, 0.7-1.9 and 1.2-2.8, half over 1.3 and 2."""
    import hvloc.texfit as tf
    from hvloc.synthesis import PadSynthesis

    syn = PadSynthesis(pad)

    def errors():
        rng, out = np.random.default_rng(5), []
        for trial in range(10):
            G = _pitched_view(pad, rng, rng.uniform(44.0, 62.0), pitch_deg=15.0)
            frame = _shadowed(_camera_view(pad, rng, None, (120, 110, 90), G=G)[2], G, rng, pad, rng.uniform(0.1, 0.3))
            if grey:
                frame = _jpeg(_grey(frame), 60)
            up_C = G[:3, :3].T @ np.array([0.0, 0.0, 1.0])
            got, info = tf.fit_pose_to_design(frame, CAM, syn, G, max_side_px=tf.HALVED_MAX_SIDE_PX, up_C=up_C,
                                              up_sigma_deg=5.0, tilt_min_side_px=24.0)
            if got is None:  # (refused: the shadow takes the drawing's correlation under MIN_NCC)
                assert "matches the frame poorly" in info["why"], info
                continue
            assert "tilt_deg" in info, info
            out.append(math.degrees(math.acos(min(1.0, float((got[:3, :3].T @ np.array([0.0, 0.0, 1.0])) @ up_C)))))
        return np.array(out)

    robust = errors()
    assert len(robust) >= 7 and robust.max() < 1.5 and np.median(robust) < 0.6, robust
    monkeypatch.setattr(tf, "PATCH_K", 0.0)  # (no patch left out)
    counted = errors()
    assert np.median(counted) > 1.0, counted  # the premise: the shadow's pixels, down-weighted only, tilt the fit


def test_a_design_fit_stopped_while_its_tilt_still_moves_states_no_sure_tilt(pad, monkeypatch):
    """The design fit descends at most :data:`hvloc.texfit.ITERATIONS` steps.  Stopped there with the
    tilt still moving, the doubt its last linearisation states is not what it knows: fz531's 40 px
    pad on a deck moved 2.4 degrees in its last step, stated 1.9 and lay 4.9 off (5.5 in another
    run: a false accept).  Such a fit's doubt now holds its last step.  Here 40-60 px views pitched
    15 degrees, fitted from a pose whose pad is tilted 15 degrees off (the prior 6.4, an untracked
    deck's), with one step allowed: 8-17 degrees off, and each states about the prior's doubt (it
    stated 1.5-2.7 before).  Allowed to settle from 7 degrees off, every fit states its image's own
    doubt, under half the prior's, and lies well within it."""
    import hvloc.texfit as tf
    from hvloc.synthesis import PadSynthesis

    syn = PadSynthesis(pad)

    def fits(off_deg):
        rng, out = np.random.default_rng(3), []
        for trial in range(10):
            G = _pitched_view(pad, rng, rng.uniform(40.0, 60.0), pitch_deg=15.0)
            frame = _camera_view(pad, rng, None, (120, 110, 90), G=G)[2]
            up_C = G[:3, :3].T @ np.array([0.0, 0.0, 1.0])
            axis = rng.normal(size=2)
            turn = np.eye(4)  # the pad tilted about its centre: it stays where it is in the image
            turn[:3, :3] = so3_exp(math.radians(off_deg) * np.array([*(axis / np.linalg.norm(axis)), 0.0]))
            got, info = tf.fit_pose_to_design(frame, CAM, syn, turn @ G, max_side_px=tf.HALVED_MAX_SIDE_PX, up_C=up_C,
                                              up_sigma_deg=6.4, tilt_min_side_px=24.0)
            assert got is not None and "tilt_deg" in info, info
            err = math.degrees(math.acos(min(1.0, float((got[:3, :3].T @ np.array([0.0, 0.0, 1.0])) @ up_C))))
            out.append((err, info["tilt_sigma_deg"]))
        return np.array(out)

    settled = fits(7.0)
    assert np.all(settled[:, 1] < 0.5 * 6.4) and np.all(settled[:, 0] < settled[:, 1]), settled
    monkeypatch.setattr(tf, "ITERATIONS", 1)
    stopped = fits(15.0)
    assert np.all(stopped[:, 0] > 5.0), stopped  # the premise: one step leaves the tilt far off
    assert np.all(stopped[:, 1] > 0.9 * 6.4), stopped


def test_a_middle_far_pad_on_an_untracked_deck_is_posed_by_its_design_with_its_tilt(pad):
    """On a deck whose tilt is not tracked, a pad's four corners fix its tilt too loosely below
    ~100 px, and the pose is refused; the design fit holds the IMU's tilt below
    :data:`hvloc.texfit.TILT_MIN_SIDE_PX`, where an AHRS tells it better, which the deck's swing
    does not.  There it fits the tilt from :data:`hvloc.localizer.UNTRACKED_TILT_MIN_SIDE_PX` (fuzz
    seeds 114, 117 and 142 lost 35-47 far frames each, refused as loose), believed once successive
    frames' fits agree (:data:`hvloc.localizer.FAR_TILT_STEPS`): a wide camera's 34-42 px pad on a
    deck tilting 6 degrees (told 10), drifting over five frames at 10 Hz, refused until then, then
    every view posed, with its tilt, within 3 of its stated sigma."""
    from hvloc.localizer import FAR_TILT_STEPS
    from hvloc.texfit import TILT_MIN_SIDE_PX

    cam = Camera.from_hfov(480, 360, math.radians(75.0))
    rng = np.random.default_rng(9)
    cfg = LocalizerConfig(pad_tilt_deg=10.0, use_markers=False)
    for trial in range(2):
        side = rng.uniform(34.0, TILT_MIN_SIDE_PX - 2.0)
        h = cam.fx * pad.geometry.side_m / side
        G0 = tilted(rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), h, rng.uniform(0, 2 * np.pi),
                    rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05))
        phi = rng.uniform(0, 2 * np.pi)
        deck = so3_exp(math.radians(6.0) * np.array([math.cos(phi), math.sin(phi), 0.0]))
        loc = HierarchicalLocalizer(pad, cam, cfg, T_B_C=np.eye(4))
        for k in range(FAR_TILT_STEPS + 2):
            G = G0.copy()
            G[0, 3] += 0.03 * k
            fine = (warp_pad_view(pad, cam.scaled(4), G, (120, 110, 90), supersample=1).astype(np.float32) / 255.0) ** 2.2
            light = cv2.GaussianBlur(cv2.resize(fine, (cam.width, cam.height), interpolation=cv2.INTER_AREA), (0, 0), 0.6)
            light += rng.normal(0.0, 0.003, light.shape).astype(np.float32)
            frame = (255.0 * np.clip(light, 0, 1) ** (1 / 2.2) + 0.5).astype(np.uint8)
            e = loc.process(frame, 0.1 * k, imu=deck @ G[:3, :3])  # the IMU's up: the deck's tilt off the pad's normal
            if k < FAR_TILT_STEPS:  # too few fits in a row to tell their scatter: doubted as the deck's swing
                assert not e.ok and "too loosely" in e.reason, (trial, k, e.status, e.reason)
                continue
            assert e.ok and "tilt_deg" in e.extras.get("design_fit", {}), (trial, k, side, e.status, e.reason)
            d = e.cam2pad[:3, 3] - G[:3, 3]
            assert float(d @ np.linalg.solve(e.cov[:3, :3], d)) < 14.16 and np.linalg.norm(d) < 0.03 * h, (trial, k, d / h)


def test_a_far_pads_fitted_tilt_is_doubted_as_far_as_successive_fits_scatter():
    """A far pad's tilt fitted on an untracked deck is doubted at least as far as the run of such
    fits before it scatter from frame to frame (the RMS of their steps over sqrt 2, turned into the
    world by the AHRS), and as the deck's swing until :data:`hvloc.localizer.FAR_TILT_STEPS` steps
    are seen, each within :data:`hvloc.localizer.FAR_TILT_GAP_S` of the last: a gap starts the run
    again."""
    from hvloc.localizer import FAR_TILT_GAP_S, FAR_TILT_STEPS

    loc = HierarchicalLocalizer(make_pad(), CAM, LocalizerConfig(pad_tilt_deg=10.0), T_B_C=np.eye(4))
    loc.up_sigma_deg = 7.0
    rng = np.random.default_rng(2)
    noise = math.radians(3.0)

    def fit(t, sigma=1.0):
        loc.frame_t, loc.attitude = t, so3_exp(rng.normal(0.0, 0.5, 3))  # the camera turns; the pad's normal does not
        n_W = so3_exp(np.array([rng.normal(0.0, noise), rng.normal(0.0, noise), 0.0])) @ np.array([0.0, 0.0, 1.0])
        return loc._far_tilt_doubt(loc.attitude.T @ n_W, sigma)

    got = [fit(0.1 * k) for k in range(40)]
    for k, (sigma, scatter) in enumerate(got[:FAR_TILT_STEPS]):
        assert sigma == 7.0 and scatter is None, k  # the run too short: the deck's swing
    scatters = np.array([g[1] for g in got[FAR_TILT_STEPS:]])
    # steps between two errors of 3 degrees per axis: 6 degrees RMS, over sqrt 2
    assert 0.7 * 3.0 * math.sqrt(2) < np.median(scatters) < 1.3 * 3.0 * math.sqrt(2)
    assert all(g[0] == max(1.0, g[1]) for g in got[FAR_TILT_STEPS:])
    assert fit(4.0 + FAR_TILT_GAP_S + 0.1) == (7.0, None)  # after a gap: a new run
    assert fit(4.0 + FAR_TILT_GAP_S + 0.1, 0.5) == (7.0, None)  # (a second fit of that frame replaces the first)



def test_a_pads_stated_relief_is_not_taken_for_a_loosely_fixed_tilt():
    """On a tilting deck a pose whose covariance puts its sideways position more than
    :data:`hvloc.localizer.MAX_SIDEWAYS_SIGMA` of the height loose is refused: its tilt is fixed too
    loosely.  The pad's stated relief (``pad_relief_m``) is in every pose's covariance too, half of it
    per axis, whatever fixes the tilt: near the ground it alone passed that bar (a random scene's
    19 mm relief, fuzz seed 107, refused its touchdown flow poses at 0.2-0.28 m, 0.2-1 mm right
    otherwise).  It is not counted as looseness; a tilt loose beyond it still is, and so is the tilt
    the pad's wrinkles may give the patch seen."""
    from hvloc.localizer import MAX_SIDEWAYS_SIGMA, Estimate, loose_tilt_refusal

    h, relief = 0.28, 0.02
    cov = np.diag([1e-8] * 3 + [1e-6] * 3)
    cov[:3, :3] += np.eye(3) * (relief / 2.0) ** 2  # as the localizer adds it
    est = Estimate(0.0, "touchdown", "ok", tilted(0.0, 0.0, h, 0.3), n_corr=40, cov=cov, method="flow")
    told = LocalizerConfig(pad_tilt_deg=7.0, pad_relief_m=relief)
    assert relief / 2.0 > MAX_SIDEWAYS_SIGMA * h  # the premise: the relief alone is past the bar
    assert loose_tilt_refusal(est, told, True) == ""
    loose = cov.copy()
    loose[0, 0] += (1.5 * MAX_SIDEWAYS_SIGMA * h) ** 2
    assert "too loosely" in loose_tilt_refusal(dataclasses.replace(est, cov=loose), told, True)
    # the tilt its wrinkles may give the patch seen is a tilt the image does not fix: it counts (fuzz
    # seed 365: two markers at 2.2 m, their patch's tilt 59 mm sideways, passed without it at 3.1 %
    # of the height and were 8.9 % and 5 degrees off)
    wrinkled = cov.copy()
    wrinkle = 0.8 * MAX_SIDEWAYS_SIGMA * h
    wrinkled[0, 0] += (0.8 * MAX_SIDEWAYS_SIGMA * h) ** 2 + wrinkle ** 2
    # (the localizer once reported that share in the extras and left it out of the bar: it no longer does)
    est = dataclasses.replace(est, cov=wrinkled, extras={"relief_sideways_var": wrinkle ** 2})
    assert "too loosely" in loose_tilt_refusal(est, told, True)


def test_a_far_pads_tilt_is_held_where_the_frames_motion_smears_it(pad):
    """The design fit's blur is isotropic, and motion smears a pad one way: a tilt fitted there takes
    up the smear (unseen100, 1-4 px of it: heights 0.14-0.39 % off fitted, 0.08-0.24 held).  Where
    the frame's motion, as the localizer knows it (the last poses' velocity over the exposure),
    smears the pad more than :data:`hvloc.localizer.TILT_MAX_SMEAR_PX`, the tilt is held; with no
    exposure known it is fitted."""
    rng = np.random.default_rng(21)
    G = _pitched_view(pad, rng, 80.0)
    views = []
    for k in range(3):  # 3 m/s along the pad's x, frames 0.1 s apart
        Gk = G.copy()
        Gk[0, 3] += 0.3 * k
        views.append((Gk, _jpeg(_camera_view(pad, rng, None, (120, 110, 90), G=Gk)[2], 70)))
    for exposure_s in (0.0, 0.02):  # 6 cm of motion over 0.02 s: ~4 px at this range
        loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), T_B_C=np.eye(4), exposure_s=exposure_s)
        for k, (Gk, frame) in enumerate(views):
            e = loc.process(frame, 0.1 * k, imu=Gk[:3, :3])
            assert e.ok and isinstance(e.extras.get("design_fit"), dict), (k, e.status, e.reason)
        assert ("tilt_deg" in e.extras["design_fit"]) == (exposure_s == 0.0), (exposure_s, e.extras["design_fit"])


def test_a_far_pads_tilt_is_fitted_only_where_its_view_can_tell_it(pad):
    """The design fit moves the IMU's tilt only on a pad of :data:`hvloc.texfit.TILT_MIN_SIDE_PX` or
    more whose fitted blur is at most :data:`hvloc.texfit.TILT_MAX_BLUR_PX`, and only with the IMU's
    up given: a smaller pad, or one smeared past that (motion the isotropic blur does not model),
    tells the tilt worse than the AHRS.  Where it is fitted, it lands nearer the truth than the
    IMU's up it started from."""
    from hvloc.synthesis import PadSynthesis
    from hvloc.texfit import HALVED_MAX_SIDE_PX, TILT_MIN_SIDE_PX, fit_pose_to_design

    syn, rng = PadSynthesis(pad), np.random.default_rng(3)
    for side_px, blur, fitted_tilt in ((80, 0.6, True), (0.8 * TILT_MIN_SIDE_PX, 0.6, False), (80, 2.0, False)):
        G = _pitched_view(pad, rng, side_px)
        frame = _camera_view(pad, rng, None, (120, 110, 90), G=G, blur_px=blur)[2]
        start = G.copy()
        start[:3, :3] = so3_exp(math.radians(0.4) * np.array([0.6, 0.8, 0.0])) @ G[:3, :3]
        up_C = start[:3, :3].T @ np.array([0.0, 0.0, 1.0])  # the IMU's up: the start's tilt
        got, info = fit_pose_to_design(frame, CAM, syn, start, max_side_px=HALVED_MAX_SIDE_PX, up_C=up_C, up_sigma_deg=0.3)
        assert got is not None, info
        assert ("tilt_deg" in info) == fitted_tilt, (side_px, blur, info)
        if fitted_tilt:
            assert math.degrees(rotation_angle(got[:3, :3], G[:3, :3])) < 0.5 * 0.4, info
            held, _ = fit_pose_to_design(frame, CAM, syn, start, max_side_px=HALVED_MAX_SIDE_PX)  # no IMU's up: held
            assert math.degrees(rotation_angle(held[:3, :3], start[:3, :3])) < 0.2, "the yaw alone moves"


def test_a_pad_of_16_to_20_px_placed_by_its_white_field_is_placed_by_its_design_instead(pad, monkeypatch):
    """Under JPEG the border's colour swells past a far pad, and the white field's luma corners place
    it.  Summed in light (a camera's pixel, and the renderer's default), the border's inner checker,
    cells of a quarter pixel here, averages to a grey half as bright as the white, and a blurred field
    comes out larger than it is: its corners put 16-20 px pads 1-2.5 % too near here (7-9 % of the
    field's side on far_wide's renders, whose poses at 17-18 m were 10-12 % off: false accepts).
    Fitted by its design from 16 px (:data:`hvloc.texfit.MIN_SIDE_PX`), within 0.4 % in the mean (single
    views up to 0.65 % off: JPEG 50's noise on a 17 px pad, 0.3 % RMS over 40 views); where the design
    is not fitted (``design_fit: false`` here), the field's corners alone no longer place a pad under
    :data:`hvloc.localizer.FIELD_MIN_SIDE_PX`."""
    import hvloc.localizer as L
    import hvloc.texfit as tf

    rng = np.random.default_rng(7)
    fitted, field = [], []
    for trial in range(12):
        side_px = rng.uniform(16.5, 19.5)
        h = CAM.fx * pad.geometry.side_m / side_px
        x, y, yaw = rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(0, 2 * np.pi)
        G0, G = tilted(x, y, 0.7 * h, yaw, 0.02, -0.01), tilted(x, y, h, yaw, 0.02, -0.01)
        near = _camera_view(pad, rng, None, (200, 195, 185), G=G0)[2]  # the pad's heading learnt from a nearer pose
        far = _jpeg(_camera_view(pad, rng, None, (200, 195, 185), G=G, blur_px=1.0)[2], 50)

        def posed(cfg=LocalizerConfig()):
            loc = HierarchicalLocalizer(pad, CAM, cfg, T_B_C=np.eye(4))
            assert loc.process(near, 0.0, imu=G0[:3, :3]).ok
            return loc.process(far, 2.0, imu=G[:3, :3])

        e = posed()
        if not (e.ok and e.extras.get("corners") == "field"):
            continue
        assert isinstance(e.extras.get("design_fit"), dict), e.extras.get("design_fit")
        fitted.append((e.cam2pad[2, 3] - G[2, 3]) / h)
        e = posed(LocalizerConfig(design_fit=False))
        assert not e.ok and "is not placed by the field's corners" in e.reason, (e.status, e.reason)
        with monkeypatch.context() as m:  # the field's corners alone, as before
            m.setattr(tf, "MIN_SIDE_PX", 20.0)
            m.setattr(L, "FIELD_MIN_SIDE_PX", 0.0)
            e = posed()
            assert e.ok and not isinstance(e.extras.get("design_fit"), dict), (e.status, e.reason)
            field.append((e.cam2pad[2, 3] - G[2, 3]) / h)
    assert len(fitted) >= 3 and np.mean(np.abs(fitted)) < 0.004 and np.max(np.abs(fitted)) < 0.008, fitted
    assert np.mean(field) > 0.01, field


def test_a_far_pad_smeared_past_what_its_drawings_blur_models_is_not_placed_by_its_design(pad):
    """The design's drawing is blurred isotropically, its blur kept within
    :data:`hvloc.texfit.BLUR_RANGE_PX`.  A motion smear over half a pad's side is no such blur: fitted
    from the labelled pose, 24-36 px pads smeared 16-24 px came out 3-21 % of the height off (conditions'
    snow scene: a 102 px pad under a 26 px smear from a 4 rad/s jolt, 10.6 % off, "ok"), every one
    with its blur at the range's top.  Such a fit fails, saying why; the same views smeared a fifth of
    their side are fitted within 1.5 %."""
    from hvloc.synthesis import PadSynthesis
    from hvloc.texfit import fit_pose_to_design

    syn, rng = PadSynthesis(pad), np.random.default_rng(4)
    refused = 0
    for side, share in ((24.0, 0.2), (24.0, 0.8), (36.0, 0.2), (36.0, 0.7)):
        h = CAM.fx * pad.geometry.side_m / side
        for _ in range(2):
            G = tilted(rng.uniform(-1, 1), rng.uniform(-1, 1), h, rng.uniform(0, 2 * np.pi), 0.02, -0.01)
            d = rng.uniform(0, 2 * np.pi)
            shift = share * side * h / CAM.fx * np.array([np.cos(d), np.sin(d), 0.0])
            img = _motion_blurred(pad, G, shift, (110, 90, 60), n=int(2 * share * side) + 1)
            fitted, info = fit_pose_to_design(img, CAM, syn, G)
            if share > 0.5:
                refused += fitted is None
                assert fitted is None or abs(fitted[2, 3] - h) < 0.03 * h, (side, share, info)
                assert fitted is not None or "blurred past what the drawing models" in info["why"], info
            else:
                assert fitted is not None and abs(fitted[2, 3] - h) < 0.015 * h, (side, share, info)
    assert refused >= 3, refused


def test_the_design_is_not_fitted_where_the_imu_says_motion_smears_the_pad_past_its_drawings_blur(pad):
    """Where the frame's motion (the gyro's rate over the exposure, with the last poses' velocity)
    smears a corner over :data:`hvloc.localizer.DESIGN_FIT_MAX_SMEAR_SHARE` of the pad's side, the
    design is not fitted (its isotropic blur does not stand for such a smear) and the reason says
    how far; a quiet frame's pad is fitted.  Not on a descent's first frame (no velocity from poses):
    its one gyro row may be a jolt's (nested_deck_pitched: 1.19 rad/s, the frame smeared 2.8 px).
    The rate is what the gyro surely says: read whole but mostly its doubt, the pad is fitted."""
    from hvloc.localizer import DESIGN_FIT_MAX_SMEAR_SHARE

    G = tilted(0.3, -0.2, CAM.fx * pad.geometry.side_m / 40.0, 0.4, 0.02, -0.01)
    img = _motion_blurred(pad, G, np.zeros(3), (110, 90, 60), n=2)
    up_C = G[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), T_B_C=np.eye(4), exposure_s=0.012)
    loc.rate_B = np.array([3.0, 0.0, 0.0])
    assert loc._design_fit(G, img, up_C, ("first frame",))[0] is not None  # no velocity from poses yet
    loc.velocity, loc.unposed = np.zeros(3), 0  # the last two poses: hovering
    fits = {}
    for rate in (0.2, 3.0):  # rad/s about the camera's x: 0.1 and 1.4 of the pad's 40 px side over 12 ms
        loc.rate_B = np.array([rate, 0.0, 0.0])
        loc.work = type(loc.work)()
        fits[rate] = loc._design_fit(G, img, up_C, ("test", rate))
        smear = rate * 0.012 * CAM.fx
        assert (fits[rate][0] is None) == (smear > DESIGN_FIT_MAX_SMEAR_SHARE * 40.0), (rate, fits[rate][1])
    assert abs(fits[0.2][0][2, 3] - G[2, 3]) < 0.005 * G[2, 3], fits[0.2][1]
    assert "smears the pad" in fits[3.0][1]["why"] and "px side" in fits[3.0][1]["why"], fits[3.0][1]
    # the same rate read whole but mostly its doubt (a vibrating gyro): the motion surely smears the pad
    # under a pixel, and the design is fitted (fzu12: 0.3-0.4 rad/s on 0.25 of doubt, 14 frames lost)
    loc.rate_B, loc.rate_doubt = np.array([3.0, 0.0, 0.0]), np.full(3, 2.95)
    loc.work = type(loc.work)()
    assert loc._design_fit(G, img, up_C, ("vibration",))[0] is not None


def test_a_far_pads_tilt_is_held_only_where_the_gyro_surely_turns_the_camera(pad):
    """The tilt is held where the frame's motion smears the pad past
    :data:`hvloc.localizer.TILT_MAX_SMEAR_PX` (test_a_far_pads_tilt_is_held_where_the_frames_motion_smears_it),
    judged on the gyro's rate less its doubt: a multirotor's vibration is most of one frame's rate,
    and read whole it held a deck's tilt where the frame was sharp (fz313: 0.1-0.27 rad/s read with
    0.06-0.12 of doubt predicted 1.0-1.7 px, the pad moved 0.3-0.4 over its 10 ms exposures; those frames were
    refused).  The same rate, sure (its doubt small), still holds it."""
    rng = np.random.default_rng(8)
    G = _pitched_view(pad, rng, 80.0)
    img = _camera_view(pad, rng, None, (120, 110, 90), G=G)[2]
    up_C = G[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    rate = 0.25  # rad/s about the camera's x: ~2 px over 12 ms at this focal length (~690 px)
    assert rate * 0.012 * CAM.fx > 1.5
    fitted = {}
    for doubt in (0.22, 0.02):  # vibration: the rate mostly noise; a real turn
        loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(), T_B_C=np.eye(4), exposure_s=0.012)
        loc.velocity, loc.unposed = np.zeros(3), 0  # the last two poses: hovering
        loc.rate_B, loc.rate_doubt = np.array([rate, 0.0, 0.0]), np.full(3, doubt)
        F, info = loc._design_fit(G, img, up_C, ("test", doubt))
        assert F is not None, info
        fitted[doubt] = "tilt_deg" in info
    assert fitted == {0.22: True, 0.02: False}, fitted


def test_the_localizer_fits_a_far_pads_design_when_asked():
    """``design_fit``: the hierarchical localizer's Approaching poses of the far views are placed by
    the drawn design (said in the estimate's extras) and lie nearer the truth in height than the
    outline's own; without the option (``design_fit: false``) the outline's corners are kept."""
    errs = {}
    for on in (False, True):
        errs[on] = []
        for pad, crop, cam, fr in _far_pad_clean():
            G = np.array(fr["cam2pad"])
            loc = HierarchicalLocalizer(pad, cam, LocalizerConfig(design_fit=on), T_B_C=np.eye(4))
            e = loc.process(crop, 0.0, imu=G[:3, :3])  # the body is the camera; the pad lies level
            assert e.status == "ok" and e.method == "outline", (fr["frame"], e.reason)
            assert isinstance(e.extras.get("design_fit"), dict) == on, e.extras.get("design_fit")
            errs[on].append(abs(e.cam2pad[2, 3] - G[2, 3]) / fr["height_m"])
    assert np.mean(errs[True]) < 0.5 * np.mean(errs[False]), errs


def test_an_outline_whose_design_fit_lies_far_from_its_corners_is_not_taken(monkeypatch):
    """The design fitted from an outline's pose is a second measure of the same pad.  Where it moves
    a corner by over :data:`hvloc.localizer.DESIGN_FIT_MAX_MOVE` of the side, the two disagree and
    neither is sure: the outline's corners were kept instead, and on far_wide (JPEG 50) a 21 px
    pad's were 11.5 % of the height off, "ok".  Such an outline is refused, saying why; a fit a
    twentieth of the side away is taken."""
    import hvloc.localizer as hl

    real = hl.HierarchicalLocalizer._design_fit
    for pad, crop, cam, fr in _far_pad_clean()[:2]:
        G = np.array(fr["cam2pad"])
        side_px = float(np.mean(np.linalg.norm(np.diff(np.array(fr["corners_px"] + fr["corners_px"][:1]), axis=0), axis=1)))
        for share in (0.05, 0.2):
            def moved(self, cam2pad, rgb, up_C, key, share=share):
                fitted, info = real(self, cam2pad, rgb, up_C, key)
                if fitted is not None:  # the fit's pose carried across the pad by ``share`` of its side
                    fitted = fitted.copy()
                    fitted[0, 3] += share * pad.geometry.side_m
                return fitted, info

            monkeypatch.setattr(hl.HierarchicalLocalizer, "_design_fit", moved)
            loc = HierarchicalLocalizer(pad, cam, LocalizerConfig(use_markers=False, use_flow=False), T_B_C=np.eye(4))
            e = loc.process(crop, 0.0, imu=G[:3, :3])
            if share < hl.DESIGN_FIT_MAX_MOVE:
                assert e.status == "ok" and isinstance(e.extras.get("design_fit"), dict), (fr["frame"], e.reason)
            else:
                assert e.status != "ok" and "neither is sure" in e.reason, (fr["frame"], side_px, e.status, e.reason)


def test_corners_the_gates_take_are_placed_by_the_design_whatever_the_start_said(monkeypatch):
    """An outline's design is fitted only where its corners are a square's (else a drawing fitted
    from there would hide what they showed, and the gates refuse them).  The start that judged it
    (the corners' pose with the IMU's gravity) and the refined pose the gates judge measure nearly
    but not quite the same: on unseen47 at render revision 14 a 26 px pad's field corners, 13 % too
    large, were no square's to the start by a hair (2.002 % of the side) and square to the gates
    (1.996 %), so they were taken unchecked, the pose 12 % of the height off, "ok"; placed by its
    design, 0.2 %.  Here every start is judged just past the bar: corners the gates take must still
    be placed by the design, and a design fit that lies far from them still refuses them."""
    import hvloc.localizer as hl

    real_share, real_fitted, real_fit = hl._rms_share, hl.HierarchicalLocalizer._design_fitted, hl.HierarchicalLocalizer._design_fit
    inside = []

    def share(rms, info):  # the start's verdict (the first, not rescuing, call): just past the bar
        return LocalizerConfig().max_outline_rms_share * 1.001 if inside == [False] else real_share(rms, info)

    def fitted(self, det, rgb, up_C, rescue=False):
        inside.append(rescue)
        try:
            return real_fitted(self, det, rgb, up_C, rescue)
        finally:
            inside.pop()

    monkeypatch.setattr(hl, "_rms_share", share)
    monkeypatch.setattr(hl.HierarchicalLocalizer, "_design_fitted", fitted)
    views = _far_pad_clean()[:3]
    for pad, crop, cam, fr in views:
        G = np.array(fr["cam2pad"])
        loc = HierarchicalLocalizer(pad, cam, LocalizerConfig(use_markers=False, use_flow=False), T_B_C=np.eye(4))
        e = loc.process(crop, 0.0, imu=G[:3, :3])
        assert e.status == "ok" and isinstance(e.extras.get("design_fit"), dict), (fr["frame"], e.status, e.reason)
        assert abs(e.cam2pad[2, 3] - G[2, 3]) < 0.01 * fr["height_m"], (fr["frame"], e.cam2pad[2, 3], G[2, 3])

    def far(self, cam2pad, rgb, up_C, key):  # the fit's pose carried a fifth of the side across the pad
        f, info = real_fit(self, cam2pad, rgb, up_C, key)
        if f is not None:
            f = f.copy()
            f[0, 3] += 0.2 * pad.geometry.side_m
        return f, info

    monkeypatch.setattr(hl.HierarchicalLocalizer, "_design_fit", far)
    for pad, crop, cam, fr in views:
        G = np.array(fr["cam2pad"])
        loc = HierarchicalLocalizer(pad, cam, LocalizerConfig(use_markers=False, use_flow=False), T_B_C=np.eye(4))
        e = loc.process(crop, 0.0, imu=G[:3, :3])
        assert e.status != "ok" and "neither is sure" in e.reason, (fr["frame"], e.status, e.reason)


def test_a_small_pad_summed_in_light_is_posed_by_its_design_not_its_swollen_field():
    """light_twins' dusk scene rendered in light, as a camera sums it (kept losslessly in tests/data:
    21-23 px pads on a grey deck at dusk, a 115 degree lens 20 degrees off nadir, JPEG 45).  The
    border's magenta ran onto the deck, and the white field, fitted as one edge where the blurred
    checker ring fills in, came out 0.6-1.4 px large along the diagonal: the outline's pose (the
    field's corners) 9-15 % of the height low, and in the descent four such poses were accepted.
    The design drawn in light and fitted from that pose (``design_fit``, now the default) places
    every view within 3 % of the height."""
    from hvloc.pose import solve_planar_pose

    doc, views = _crop_views("small_pad_deck_light", 64)
    pad = make_pad(doc["pad_spec"])
    crops = {fr["frame"]: crop for crop, _, fr in views}
    assert LocalizerConfig().design_fit
    for fr, G, cam, det in _named_by_labels("small_pad_deck_light", 64):
        up = up_in_camera(G)
        before = solve_planar_pose(cam, det.pts_P, det.px, up, sigma_px=corner_sigma_px(det.info))
        assert (before.cam2pad[2, 3] - G[2, 3]) / G[2, 3] < -0.08, fr["frame"]  # (the premise: the field swollen)
        fitted = HierarchicalLocalizer(pad, cam, LocalizerConfig(), T_B_C=np.eye(4))._design_fitted(det, crops[fr["frame"]], up)
        assert isinstance(fitted.info.get("design_fit"), dict), (fr["frame"], fitted.info.get("design_fit"))
        pose = solve_planar_pose(cam, fitted.pts_P, fitted.px, up, sigma_px=corner_sigma_px(fitted.info))
        assert abs(pose.cam2pad[2, 3] - G[2, 3]) < 0.03 * G[2, 3], (fr["frame"], pose.cam2pad[2, 3], G[2, 3])
        assert np.linalg.norm(pose.cam2pad[:2, 3] - G[:2, 3]) < 0.03 * G[2, 3], fr["frame"]


def _far_view_after(monkeypatch):
    """The first of :func:`_far_pad_clean`'s views (a 30 px pad at 20 m) widened 40 px each way (its
    edges repeated, so that the view can move): ``(view, camera, frame, find, run)``.  ``find``: the
    outline finder; ``run(before, config, then)`` localizes the images ``before`` (10 Hz, the pad's
    outline found as it is), then the view with the finder answering ``then``."""
    import hvloc.phases as ph_mod

    pad, crop, cam, fr = _far_pad_clean()[0]
    m = 40
    view = np.pad(crop, ((m, m), (m, m), (0, 0)), mode="edge")
    cam = dataclasses.replace(cam.shifted(-m, -m), width=view.shape[1], height=view.shape[0])
    G = np.array(fr["cam2pad"])
    find = ph_mod.find_outline

    def run(before, config, then):
        loc = HierarchicalLocalizer(pad, cam, config, T_B_C=np.eye(4))
        monkeypatch.setattr(ph_mod, "find_outline", find)
        for k, image in enumerate(before):
            e = loc.process(image, 0.1 * k, imu=G[:3, :3])
            assert e.status == "ok", e.reason
        monkeypatch.setattr(ph_mod, "find_outline", lambda *a, **kw: then)
        return loc.process(view, 0.1 * len(before), imu=G[:3, :3])

    return view, cam, fr, lambda: find(view, pad.geometry, cam), run


def test_an_outline_no_square_is_placed_by_its_design_where_the_pad_was_foreseen(monkeypatch):
    """Corners that are no square's (one a tenth of the side out: a shadow or JPEG swelling it) are
    refused by the gates, design_fit on or off; where the velocity filter foresaw the pad (two poses
    just before, of the same view), the pad's drawn design places it instead, within 1 % of its
    height.  Foreseen elsewhere (the two poses before of the view moved 45 px: a pad seen 1.3 m
    away at 20 m), or with nothing foreseen (no pose before), the bent corners stay refused."""
    view, cam, fr, find, run = _far_view_after(monkeypatch)
    G = np.array(fr["cam2pad"])
    found, why = find()
    assert found is not None, why
    out = found.quad_px[0] - found.quad_px.mean(axis=0)
    bent_quad = found.quad_px.copy()
    bent_quad[0] += 0.1 * found.side_px * out / np.linalg.norm(out)
    bent = (dataclasses.replace(found, quad_px=bent_quad, field_px=None), "ok")
    moved = np.roll(view, 45, axis=1)
    for on in (False, True):
        e = run([view, view], LocalizerConfig(design_fit=on), bent)
        assert e.status == "ok" and e.extras.get("rescued") == "design fit", (on, e.reason, e.extras.get("design_fit"))
        assert abs(e.cam2pad[2, 3] - G[2, 3]) < 0.01 * fr["height_m"], (e.cam2pad[2, 3], G[2, 3])
        assert np.linalg.norm(e.cam2pad[:2, 3] - G[:2, 3]) < 0.01 * fr["height_m"]
        for before in ([moved, moved], []):
            e = run(before, LocalizerConfig(design_fit=on), bent)
            assert e.status == "rejected" and "no square's" in e.reason, (on, len(before), e.status, e.reason)


def test_a_small_pad_whose_outline_is_lost_is_placed_by_its_design_at_the_predicted_pose(monkeypatch):
    """A 30 px pad at 20 m whose outline is not found (its border band missing beside a corner:
    JPEG's chroma, a shadow) is too small for its smeared drawing to be aligned (under 45 px), and
    was lost.  Where the velocity filter carries a recent pose to the frame, the pad's printed
    design is fitted from that predicted pose (position and yaw, the tilt the IMU's) and, landing
    where it was foreseen, poses the frame within 1 % of the height, its covariance from the blur
    the fit found.  With no pose before, or one of a view 45 px away (the design fitted there finds
    no pad), the frame stays lost."""
    view, cam, fr, _, run = _far_view_after(monkeypatch)
    G = np.array(fr["cam2pad"])
    lost = (None, "its border band is missing beside a corner")
    e = run([view, view], LocalizerConfig(), lost)
    assert e.status == "ok" and e.extras.get("by") == "design at the predicted pose", (e.reason, e.extras)
    err = e.cam2pad[:3, 3] - G[:3, 3]
    assert np.linalg.norm(err) < 0.01 * fr["height_m"], err
    assert float(err @ np.linalg.solve(e.cov[:3, :3], err)) < 11.34, (err, np.sqrt(np.diag(e.cov[:3, :3])))
    for before in ([np.roll(view, 45, axis=1)] * 2, []):
        e = run(before, LocalizerConfig(), lost)
        assert e.status != "ok", (len(before), e.extras.get("by"))


# ----------------------------------------------------------------------------- a tilting deck

def _rendered_descent(tmp_path, spec: dict) -> tuple:
    """Render ``spec``'s first descent into ``tmp_path/ds``: ``(its T_P_C per frame, its heights)``."""
    from render.dataset import Dataset
    from render.generate import generate
    from render.spec import DatasetSpec

    generate(DatasetSpec.model_validate(spec), tmp_path / "ds", show_progress=False)
    seq = Dataset(tmp_path / "ds")[0]
    truth = [seq.frame(k).cam2pad for k in range(len(seq))]
    return truth, np.array([T[2, 3] for T in truth])


def _localized_descent(tmp_path, name: str, truth, cfg: LocalizerConfig, use_imu: bool = True) -> tuple:
    """The rendered descent localized into ``tmp_path/name``: ``(its estimates, ok, wrong)``, wrong
    being an ok pose off by more than a tenth of the height or 5 degrees (a false accept)."""
    from benchmarks.run import localize_dataset, read_estimates
    from hvloc.geometry import transform_from_tum

    localize_dataset(tmp_path / "ds", tmp_path / name, config=cfg, use_imu=use_imu, show_progress=False)
    est = read_estimates(tmp_path / name / "seq_0000" / "estimates.csv")
    ok = est["status"] == "ok"
    wrong = np.zeros(len(truth), bool)
    for k in np.flatnonzero(ok):
        E = transform_from_tum([est[c][k] for c in ("tx", "ty", "tz", "qx", "qy", "qz", "qw")])
        wrong[k] = (np.linalg.norm(E[:3, 3] - truth[k][:3, 3]) > 0.1 * truth[k][2, 3]
                    or math.degrees(rotation_angle(E[:3, :3], truth[k][:3, :3])) > 5.0)
    return est, ok, wrong


def test_on_a_rolling_deck_a_level_pad_is_not_assumed_when_told_or_once_the_markers_show_it_tilts(tmp_path):
    """A ship's deck rolling 8, pitching 5 and yawing 5 degrees.  Told the deck may tilt
    (``pad_tilt_deg``), the localizer weighs the IMU's up by that, refuses the far poses whose tilt
    the image cannot fix, and poses the near ones right: no false accept, and nearly all of the
    descent below 5 m posed (the deck's yaw followed: the vision-IMU heading's slow reference lagged
    it past the jump's bar near the ground).  Untold, it takes the pad for level (the default): the
    gravity prior holds every pose's tilt to the IMU's, and the far poses are wrong by the deck's
    tilt while saying ``ok``; but once the markers have shown the pad tilting (three poses whose
    image alone contradicts the IMU's up), it says so in that frame's reason and from the next frame
    is what it would have been told: no false accept after it, and the rest posed as when told.
    (Before, it had 3 false accepts after the frame where it now sees the deck, and 26 of those 32
    frames, down to touchdown, refused or lost.)  Rendered in light (the default): with the
    markers' corners placed in display values, the deck was seen tilting surely only at 0.9 m on
    these frames; placed in light, as the pixels sum it, above 2.5 m as on frames mixed in display
    values."""
    truth, h = _rendered_descent(tmp_path, {
        "name": "deck", "seed": 7, "sequences": 1, "pad_ppm": 1000,
        "camera": {"width": 480, "height": 480, "hfov_deg": 60, "fps": 4, "exposure_s": 0.004},
        "platform": {"height_m": 2.0, "size_m": 1.6, "roll_deg": 8.0, "pitch_deg": 5.0, "heave_m": 0.5,
                     "yaw_deg": 5.0, "yaw_period_s": 10.0},
        "trajectory": {"families": ["spiral"], "start_height_m": 10.0, "duration_s": [16, 16],
                       "lateral_offset_m": [0.0, 1.0]}})
    est, ok_level, wrong_level = _localized_descent(tmp_path, "level", truth, LocalizerConfig())
    _, ok_deck, wrong_deck = _localized_descent(tmp_path, "deck", truth, LocalizerConfig(pad_tilt_deg=15.0))
    assert wrong_deck.sum() == 0
    near = h < 5.0
    assert ok_deck[near].mean() >= 0.9, ok_deck[near].mean()
    seen = [k for k in range(len(truth)) if "taken for a deck tilting up to" in str(est["reason"][k])]
    assert len(seen) == 1, seen  # said once, where it was seen
    k0 = seen[0]
    assert wrong_level[:k0].sum() >= 5  # the failure only the user can prevent: far, wrong, and saying ok
    assert h[k0] > 2.5 and not wrong_level[k0 + 1:].any(), (round(h[k0], 2), np.flatnonzero(wrong_level))
    after = np.arange(len(truth)) > k0
    assert ok_level[after].mean() >= 0.9, ok_level[after].mean()


def test_a_pad_is_taken_for_a_deck_only_where_sure_poses_show_it_tilting_within_seconds(pad):
    """What makes a pad taken for level one that tilts (:meth:`HierarchicalLocalizer._pad_tilt_seen`):
    poses whose image alone fixes the tilt (markers, to a degree), three within 5 s, each further from
    the IMU's up than the tilt gate allows and five sigmas.  Not an AHRS a little off, not the
    outline's four corners, not a loose markers fit, not three such poses spread over a minute, not
    poses of a patch of the pad (a marker's corners alone, which a wrinkle tilts as far).  It
    says so in the frame, takes no other pose that frame, and from the next one is a deck tilting 1.5
    times as far, its tilt tracked from those poses, widened as the image shows more; a new track
    (time going back) forgets it.  A deck told too small a tilt is widened where a sure pose lies
    three of its sigmas past it."""
    from hvloc.localizer import Estimate

    loc = HierarchicalLocalizer(pad, CAM)
    R_B_C = loc.T_B_C[:3, :3]

    def seen(t, tilt_deg, sigma=0.2, method="markers", spread_m=0.25):  # (three markers' spread)
        n_W = so3_exp([math.radians(tilt_deg), 0.0, 0.0]) @ np.array([0.0, 0.0, 1.0])
        e = Estimate(t, "adjustment", "ok", np.eye(4), 24, 0.3, method=method,
                     extras={"tilt_err_deg": tilt_deg, "tilt_sigma_deg": sigma, "normal_img_C": R_B_C.T @ n_W,
                             "spread_m": spread_m})
        loc._pad_tilt_seen(e, np.eye(3))
        return bool(loc.deck_seen)

    blank = np.zeros((CAM.height, CAM.width, 3), np.uint8)
    assert not any(seen(0.1 * k, 2.5) for k in range(20))  # an AHRS 2.5 degrees off: within the gate
    assert not any(seen(2.0 + 0.1 * k, 9.0, method="outline") for k in range(5))
    assert not any(seen(3.0 + 0.1 * k, 9.0, sigma=1.5) for k in range(5))  # a loose fit
    assert not any(seen(5.0 + 0.1 * k, 6.0, spread_m=0.03) for k in range(5))  # one small marker's patch
    assert not any(seen(10.0 + 20.0 * k, 6.0) for k in range(4))  # over a minute
    assert not seen(100.0, 6.0) and not seen(102.0, 7.0) and seen(104.0, 6.5)
    assert "taken for a deck tilting up to 10.5 deg" in loc.deck_note
    assert "no pose" in loc._gate(Estimate(104.0, "approaching", "ok", np.eye(4), 4, 0.1, method="outline"), np.eye(3))
    assert loc.config.pad_tilt_deg == 0.0 and loc.deck is None  # until the next frame
    loc.process(blank, 104.1, np.eye(3))
    assert loc.config.pad_tilt_deg == pytest.approx(10.5) and loc.gates.config is loc.config
    tilt, sigma, tol, tracked = loc.deck.prior(104.2)
    assert tracked and math.degrees(tilt[0]) == pytest.approx(6.5, abs=1.0), (tilt, sigma)
    seen(104.3, 8.0)
    assert loc.config.pad_tilt_deg == pytest.approx(12.0) and math.degrees(loc.deck.A) == pytest.approx(12.0)
    loc.process(blank, 50.0, np.eye(3))  # time went back: a new track
    assert loc.config.pad_tilt_deg == 0.0 and loc.deck is None and loc.told_config is None

    # told too small a tilt: widened only where a sure pose lies three of its sigmas past it
    loc = HierarchicalLocalizer(pad, CAM, LocalizerConfig(pad_tilt_deg=3.0))
    seen(1.0, 3.4)
    assert loc.config.pad_tilt_deg == 3.0
    seen(1.05, 6.0, spread_m=0.03)  # a small marker's patch: a wrinkle's tilt as well
    assert loc.config.pad_tilt_deg == 3.0
    seen(1.1, 6.0)
    assert loc.config.pad_tilt_deg == pytest.approx(9.0) and "it was told" in loc.deck_note
    loc.process(blank, 1.2, np.eye(3))
    loc.process(blank, 0.5, np.eye(3))  # time went back: as told again
    assert loc.config.pad_tilt_deg == 3.0 and loc.deck is not None and loc.told_config is None


def test_without_the_imu_a_pose_whose_tilt_the_image_hardly_fixes_is_refused_not_stated(tmp_path):
    """No IMU (``--no-imu``, or a flight log without attitude): only the image and the level-flight
    prior fix the pad's tilt, and a far pad's four corners, seen obliquely through a barrel lens on
    a rolling deck, fix it to several degrees, which puts the pose a tenth of the height and more
    off sideways.  Such a pose is refused with its reason (its pose and covariance kept in the
    row), not stated ``ok``; the poses whose tilt the markers fix, nearer, are kept.  Without the
    refusal this descent had 4 false accepts."""
    truth, h = _rendered_descent(tmp_path, {
        "name": "oblique_deck", "seed": 7, "sequences": 1, "pad_ppm": 1000,
        "camera": {"width": 480, "height": 360, "hfov_deg": 90, "fps": 4, "exposure_s": 0.004,
                   "dist": [-0.2, 0.04, 0.0, 0.0, 0.0], "mount": {"rpy_deg": [200.0, 0.0, -90.0]}},
        "platform": {"height_m": 2.0, "size_m": 1.6, "roll_deg": 8.0, "pitch_deg": 5.0, "heave_m": 0.5},
        "trajectory": {"families": ["spiral"], "start_height_m": 10.0, "duration_s": [16, 16],
                       "lateral_offset_m": [0.0, 1.0]}})
    est, ok, wrong = _localized_descent(tmp_path, "est", truth, LocalizerConfig(), use_imu=False)
    assert not wrong.any(), [(k, round(h[k], 1)) for k in np.flatnonzero(wrong)]
    loose = [k for k in range(len(truth)) if "without the IMU's gravity the image fixes the pad's tilt too loosely"
             in str(est["reason"][k])]
    assert loose and all(est["status"][k] == "rejected" and np.isfinite(est["tz"][k]) for k in loose), loose
    assert min(h[k] for k in loose) > 2.0, [(k, round(h[k], 1)) for k in loose]
    near = h < 3.0
    assert ok[near].mean() >= 0.9, ok[near].mean()


def test_a_tilting_deck_and_learning_the_ahrs_error_from_the_pad_are_refused_together():
    from pad_design.errors import InputError, validate_model

    with pytest.raises(InputError, match="ahrs_bias_time_s"):
        validate_model(LocalizerConfig, {"pad_tilt_deg": 10.0, "ahrs_bias_time_s": 10.0})
    assert LocalizerConfig(pad_tilt_deg=10.0).up_sigma_deg() == pytest.approx(math.hypot(0.5, 10.0 / math.sqrt(2)))
    assert LocalizerConfig().up_sigma_deg() == 0.5


def test_heading_turn_ignores_tilt():
    from hvloc.geometry import heading_turn

    tilt = so3_exp([0.15, -0.1, 0.0])
    for yaw in (0.3, -2.9, 3.1):
        Rz = so3_exp([0.0, 0.0, yaw])
        assert heading_turn(tilt, Rz @ tilt) == pytest.approx(yaw, abs=0.02)
    assert heading_turn(np.eye(3), so3_exp([0.0, 0.0, 3.0]) @ so3_exp([0.0, 0.0, 0.5])) == pytest.approx(3.5 - 2 * math.pi)


def test_a_decks_tilt_is_tracked_from_noisy_normals_and_a_mirror_is_not_taken():
    """DeckTilt: a swell of 8 degrees (period 7 s) measured at 10 Hz with 1 degree of noise per
    axis: its prediction one frame on is within 1.5 degrees nearly always, and says so (sigma well
    under the deck's RMS tilt, the tolerance well under its amplitude); a normal 13 degrees off (a
    mirror pose) is skipped; with nothing for long it falls back to the IMU's up, as sure as the
    deck's RMS tilt."""
    from hvloc.localizer import DeckTilt

    rng = np.random.default_rng(3)
    deck = DeckTilt(15.0, 0.5)
    A, w = math.radians(8.0), 2 * math.pi / 7.0

    def truth(t):
        return np.array([A * math.sin(w * t), 0.6 * A * math.cos(1.3 * w * t), 0.0])

    def normal(rv):
        return so3_exp(rv) @ np.array([0.0, 0.0, 1.0])

    errs, ratio = [], []
    for i in range(200):
        t = 0.1 * i
        tilt, sigma, tol, tracked = deck.prior(t)
        if i > 20:
            assert tracked and sigma < 3.0 and tol < 9.0
            errs.append(math.degrees(np.linalg.norm((tilt - truth(t))[:2])))
            ratio.append(np.abs(np.degrees((tilt - truth(t))[:2])).max() / sigma)
        deck.update(t, normal(truth(t) + np.append(rng.normal(0, math.radians(1.0), 2), 0.0)), 1.0)
    # (it follows a swell as short as 4 s at 15 degrees: it smooths little, but a mirror 13 degrees
    # off lies far outside what it allows, and the untracked up is off by the whole tilt)
    assert np.percentile(errs, 99) < 4.5 and np.percentile(ratio, 99) < 3.0, (np.percentile(errs, [50, 99]),
                                                                               np.percentile(ratio, [50, 99]))
    before = deck.x.copy()
    deck.update(20.0, normal(truth(20.0) + np.radians([13.0, 0.0, 0.0])), 0.5)  # a mirror: skipped
    assert np.allclose(deck.x, before)
    tilt, sigma, tol, tracked = deck.prior(60.0)  # 40 s with nothing
    assert not tracked and np.allclose(tilt, 0.0) and tol == pytest.approx(15.0)
    assert sigma == pytest.approx(math.hypot(0.5, 15.0 / math.sqrt(2)))


def _far_oblique_outline():
    """``(geo, cam, T, px, up_C)``: a far pad's outer corners seen 23 degrees off axis, where IPPE's
    pose and its mirror fit alike (the mirror's pad ~46 degrees from up), and the world's up."""
    geo = make_pad().geometry
    cam = Camera(640, 480, 500.0, 500.0, 319.5, 239.5)
    T = look_at_cam2world(np.array([6.0, 0.0, 14.0]), np.zeros(3))
    return geo, cam, T, cam.project_from(T, geo.outer_corners), T[:3, :3].T @ np.array([0.0, 0.0, 1.0])


def test_on_a_tilting_deck_gravity_does_not_choose_between_a_pose_and_its_mirror():
    """A far pad seen obliquely: IPPE's two poses fit alike.  On level ground gravity picks the one
    whose pad lies level; where the pad may tilt by more than both lie from up, nothing picks it
    (``ambiguous``), so the localizer refuses it rather than guess."""
    geo, cam, T, px, up_C = _far_oblique_outline()
    level = solve_planar_pose(cam, geo.outer_corners, px, up_C=up_C)
    assert level.flip_choice == "gravity" and rotation_angle(level.cam2pad[:3, :3], T[:3, :3]) < 0.01
    deck = solve_planar_pose(cam, geo.outer_corners, px, up_C=up_C, up_tolerance_deg=60.0)
    assert deck.flip_choice == "ambiguous"
    tight = solve_planar_pose(cam, geo.outer_corners, px, up_C=up_C, up_tolerance_deg=2.0)
    assert tight.flip_choice == "gravity"


def test_a_mirror_refused_on_a_deck_says_the_deck_not_a_missing_imu():
    """The refusal of a pose whose mirror fits alike names what failed to choose: on a tilting deck
    the IMU is there, but both lie within the deck's tilt of its up; without it, no IMU (nor a
    previous pose, nor level flight) chose.  A deck's refusal once read "no IMU", sending its user
    after a fault they did not have."""
    from hvloc.localizer import _mirror_refusal

    geo, cam, T, px, up_C = _far_oblique_outline()  # (a deck allowed 60 degrees keeps both)
    deck = solve_planar_pose(cam, geo.outer_corners, px, up_C=up_C, up_tolerance_deg=60.0)
    assert deck.flip_choice == "ambiguous"
    why = _mirror_refusal(deck, 60.0)
    assert "within the 60 deg a deck may tilt" in why and "no IMU" not in why, why
    alone = solve_planar_pose(cam, geo.outer_corners, px)  # no IMU, no previous pose, no level up
    assert alone.flip_choice == "rms" and _mirror_refusal(alone) == ""
    # a level up that decides nothing (sideways: neither pad lies within 30 degrees of it)
    blind = solve_planar_pose(cam, geo.outer_corners, px, level_up_C=np.array([1.0, 0.0, 0.0]))
    assert blind.flip_choice == "ambiguous" and "no IMU" in _mirror_refusal(blind)
    level = solve_planar_pose(cam, geo.outer_corners, px, up_C=up_C)
    assert _mirror_refusal(level, 60.0) == ""  # gravity chose: nothing to refuse
