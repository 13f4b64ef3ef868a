"""Every spec field renders what its labels say: images against labels, visibility against an
independent ray test, moving platforms, the one-render blur against sub-frames."""
import csv
import functools
import hashlib
import json
import math
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from hvloc.geometry import invert, make_transform, rotation_z, so3_exp, transform_points
from render.checks import check_image
from render.dataset import Dataset, sha256_file, verify_dataset
from render.frames import SequenceRenderer
from render.generate import camera_info, generate
from render.imaging import display_bytes
from render.phase import PadSamples
from render.spec import DatasetSpec
from tests.conftest import run_cli
from tests.spec_space import BASE, FIELDS, leaf_paths, random_spec, set_path


def _spec(d: dict) -> DatasetSpec:
    return DatasetSpec.model_validate(d)


def _merge(base: dict, updates: dict) -> dict:
    d = json.loads(json.dumps(base))
    for path, value in updates.items():
        set_path(d, path, value)
    return d


# ----------------------------------------------------------------------------- every field is rendered

def test_every_spec_field_is_in_the_spec_space():
    missing = sorted(set(leaf_paths()) - set(FIELDS))
    stale = sorted(set(FIELDS) - set(leaf_paths()))
    assert not missing, f"spec fields with no domain or effect in tests/spec_space.py: {missing}"
    assert not stale, f"tests/spec_space.py names fields the spec does not have: {stale}"


def _outputs(d: dict, render: bool) -> str:
    """A digest of what sequence 0 of a spec is: its plan, its camera.json, labels and (with ``render``) pixels."""
    return _outputs_of(json.dumps(d, sort_keys=True), render)


@functools.lru_cache(maxsize=64)
def _outputs_of(spec_json: str, render: bool) -> str:
    spec = _spec(json.loads(spec_json))
    h = hashlib.sha256(json.dumps([spec.name, spec.sequences]).encode())
    with SequenceRenderer(spec, 0) as r:
        p = r.plan
        for part in (r.times, r.body2world, r.pad2world, p.imu, r.T_B_C, r.pad.texture_rgb):
            h.update(np.ascontiguousarray(part).tobytes())
        h.update(json.dumps([p.scene_draw.to_dict(), p.imaging.to_dict(), camera_info(spec, r), r.pad.document()],
                            default=str).encode())
        if render:
            for k in range(len(r)):
                layers = r.render(k)
                h.update(layers.rgb.tobytes())
                h.update(json.dumps(layers.labels, default=str).encode())
    return h.hexdigest()


@pytest.mark.parametrize("path", sorted(FIELDS))
def test_every_spec_field_changes_what_is_rendered(path):
    _, perturbed, context = FIELDS[path]
    base = _merge(BASE, context)
    changed = _merge(base, {path: perturbed})
    assert changed != base, f"{path}: the perturbation equals the base value"
    if _outputs(changed, render=False) != _outputs(base, render=False):
        return
    assert _outputs(changed, render=True) != _outputs(base, render=True), \
        f"{path}: changing it changes neither the plan, the labels nor the pixels of sequence 0"


# ----------------------------------------------------------------------------- labels against images

def test_random_specs_render_what_their_labels_say():
    """Random valid specs (mounts off nadir, lenses, moving platforms, sun, distractors, blur,
    rolling shutter, airframes, glossy dirty pads, supersampling...): where the pad is near and
    sharp, the image shows it at the labelled pose."""
    tested = 0
    for seed in range(6):
        rng = np.random.default_rng(1000 + seed)
        spec = _spec(random_spec(rng))
        with SequenceRenderer(spec, 0) as r:
            f = min(r.camera.fx, r.camera.fy)
            across = np.array([r.pad.side_m * f / r.cam2pad(k)[2, 3] for k in range(len(r))])
            cand = np.nonzero((across >= 60) & (across <= 0.8 * min(r.camera.width, r.camera.height)))[0]
            here = 0
            for k in cand[np.linspace(0, len(cand) - 1, min(8, len(cand))).round().astype(int)] if len(cand) else []:
                if here == 3:
                    break
                layers = r.render(int(k))
                L = layers.labels
                if L["blur_px"] > 1.5 or L["pad_visible_fraction"] < 0.5:
                    continue
                matched, cells, required = check_image(r.camera, r.pad, r.cam2pad(int(k)), layers.rgb,
                                                       L["pad_visible_fraction"])
                assert matched >= required, (f"spec {seed} frame {k}: {matched} of {cells} pad cells match "
                                             f"({required} needed): {spec.canonical_json()}")
                here += 1
            tested += here
    assert tested >= 8, f"only {tested} frames of 6 random specs were near and sharp enough to check"


def _seg_hits_box(C, X, box, grow):
    """Does the segment C->X pass through the oriented box (grown by ``grow`` metres)?"""
    x, y, yaw, sx, sy, sz, _ = box
    R = rotation_z(yaw)
    c = np.array([x, y, sz / 2])
    a, b = R.T @ (C - c), R.T @ (X - c)
    d = b - a
    half = np.array([sx, sy, sz]) / 2 + grow
    t0, t1 = 0.0, 1.0
    for i in range(3):
        if abs(d[i]) < 1e-12:
            if abs(a[i]) > half[i]:
                return False
            continue
        u, v = (-half[i] - a[i]) / d[i], (half[i] - a[i]) / d[i]
        t0, t1 = max(t0, min(u, v)), min(t1, max(u, v))
    return t0 < t1 - 1e-9


def test_visibility_labels_agree_with_a_ray_test_in_a_scene_built_to_occlude():
    """A camera 20 deg off nadir and a wall beside the pad: per-corner and per-marker visibility
    (from the renderer's depth) against an exact segment-box intersection."""
    spec = _spec({"name": "occ", "seed": 4, "sequences": 1,
                  "camera": {"width": 200, "height": 200, "hfov_deg": 70, "fps": 2, "exposure_s": 0.0,
                             "mount": {"rpy_deg": [200, 0, -90]}},
                  "platform": {"height_m": 0.0},
                  "trajectory": {"families": ["straight"], "start_height_m": 5, "duration_s": [10, 10],
                                 "lateral_offset_m": [0, 0], "final_offset_m": [0, 0], "yaw_deg": [180, 180],
                                 "yaw_change_deg": [0, 0], "gust_accel_mps2": [0, 0]},
                  "environment": {"distractors": {"boxes": [0, 0], "decoy_patches": [0, 0], "decoy_markers": [0, 0],
                                                  "boxes_at": [{"xy_m": [0.55, 0.0], "size_m": [0.12, 1.2, 1.0]}]}}})
    disagree, tested, occluded = [], 0, 0
    with SequenceRenderer(spec, 0) as r:
        samples = PadSamples.of(r.pad.geometry)
        box = r.plan.scene_draw.boxes[0]
        for k in range(len(r)):
            labels = r.render(k).labels
            T_W_C = r.body2world[k] @ r.T_B_C
            C = T_W_C[:3, 3]
            gsd = max(np.linalg.norm(C), 0.1) / r.camera.fx
            pts = {f"c{i}_visible": samples.corners[i:i + 1] for i in range(4)}
            pts.update({f"marker_{n.lower()}_visible": samples.markers[n] for n in samples.markers})
            for col, P in pts.items():
                Xw = transform_points(r.pad2world[k], P)
                in_image = r.camera.in_image(r.camera.project_from(invert(r.pad2world[k]) @ T_W_C, P)).all()
                hit_out = [_seg_hits_box(C, X, box, 2 * gsd) for X in Xw]
                hit_in = [_seg_hits_box(C, X, box, -2 * gsd) for X in Xw]
                if hit_out != hit_in:
                    continue  # within two pixels of the wall's edge: either answer is right
                truth = bool(in_image and not any(hit_out))
                tested += 1
                occluded += bool(in_image and any(hit_out))
                if bool(labels[col]) != truth:
                    disagree.append((k, col, labels[col], truth))
    assert tested >= 100 and occluded >= 10, (tested, occluded)
    assert not disagree, disagree[:5]


# ----------------------------------------------------------------------------- moving platform, verify

def _moving_spec(**over):
    d = {"name": "mp", "seed": 3, "sequences": 1,
         "camera": {"width": 240, "height": 240, "hfov_deg": 60, "fps": 2, "exposure_s": 0.004},
         "platform": {"height_m": 0.5, "velocity_mps": [0.6, 0.3]},
         "trajectory": {"families": ["straight"], "start_height_m": 4, "duration_s": [9, 9],
                        "lateral_offset_m": [0, 0.5]}}
    return _spec(_merge(d, over))


@pytest.fixture(scope="module")
def moving_dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("mp") / "ok"
    generate(_moving_spec(), root, show_progress=False)
    return root


def test_moving_platform_is_rendered_where_its_labels_say(moving_dataset):
    seq = Dataset(moving_dataset)[0]
    c = seq.columns
    # the pad's world pose moves with the spec's velocity, and T_P_C = T_W_P^-1 T_W_B T_B_C
    np.testing.assert_allclose(c["pad2world_tx"], 0.6 * c["t"], atol=1e-9)
    np.testing.assert_allclose(c["pad_vel_y"], 0.3)
    from hvloc.geometry import transform_from_tum

    for k in (0, len(seq) // 2, len(seq) - 1):
        T_W_P = transform_from_tum([c[f"pad2world_{q}"][k] for q in ("tx", "ty", "tz", "qx", "qy", "qz", "qw")])
        T_W_B = transform_from_tum([c[f"body2world_{q}"][k] for q in ("tx", "ty", "tz", "qx", "qy", "qz", "qw")])
        np.testing.assert_allclose(invert(T_W_P) @ T_W_B @ seq.T_B_C, seq.frame(k).cam2pad, atol=1e-9)
    assert verify_dataset(moving_dataset) == []


def test_verify_catches_a_platform_that_is_labelled_moving_but_rendered_still(tmp_path, monkeypatch):
    """The bug this round fixed: the trajectory moved with the pad, the rendered pad did not."""
    import render.scene as scene

    monkeypatch.setattr(scene.LandingScene, "set_platform", lambda self, T: None)
    generate(_moving_spec(), tmp_path / "bad", show_progress=False)
    r = run_cli("dataset", "verify", tmp_path / "bad")
    assert r.returncode == 1 and "does not show the pad at its labelled pose" in r.stdout, r.stdout


def _rewrite_checksums(root: Path, sid: str, names) -> None:
    m = json.loads((root / "manifest.json").read_text())
    meta = json.loads((root / sid / "meta.json").read_text())
    for n in names:
        meta["files"][n] = m["files"][f"{sid}/{n}"] = sha256_file(root / sid / n)
    (root / sid / "meta.json").write_text(json.dumps(meta, indent=1) + "\n")
    m["files"][f"{sid}/meta.json"] = sha256_file(root / sid / "meta.json")
    (root / "manifest.json").write_text(json.dumps(m, indent=1) + "\n")


def test_verify_catches_labels_off_by_a_pixel_with_consistent_checksums(moving_dataset, tmp_path):
    """Poses moved by ~1.5 px at the tested frames, the corner columns and groundtruth.tum moved
    with them and every checksum rewritten: only the image check can tell, and it does."""
    root = tmp_path / "shifted"
    shutil.copytree(moving_dataset, root)
    seq = Dataset(root)[0]
    path = root / seq.id / "frames.csv"
    rows = list(csv.DictReader(path.open()))
    from hvloc.geometry import transform_from_tum

    for row in rows:
        h = float(row["tz"])
        row["tx"] = repr(float(row["tx"]) + 1.5 * h / seq.camera.fx)
        T = transform_from_tum([float(row[q]) for q in ("tx", "ty", "tz", "qx", "qy", "qz", "qw")])
        px = seq.camera.project_from(T, seq.pad.outer_corners_P)
        inside = seq.camera.in_image(px)
        for i in range(4):
            row[f"c{i}u"], row[f"c{i}v"] = (repr(float(v)) for v in px[i]) if inside[i] else ("nan", "nan")
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    tum = root / seq.id / "groundtruth.tum"
    lines = tum.read_text().splitlines()
    out = [lines[0]] + [" ".join([r["t"], r["tx"], r["ty"], r["tz"], r["qx"], r["qy"], r["qz"], r["qw"]]) for r in rows]
    tum.write_text("\n".join(out) + "\n")
    _rewrite_checksums(root, seq.id, ["frames.csv", "groundtruth.tum"])
    res = run_cli("dataset", "verify", root)
    assert res.returncode == 1 and "does not show the pad" in res.stdout, res.stdout


def test_reading_a_sequence_never_rasterises_the_pad(moving_dataset, monkeypatch):
    import pad_design.pad
    import pad_design.texture

    def boom(*a, **k):
        raise AssertionError("the pad texture was rasterised on read")

    monkeypatch.setattr(pad_design.texture, "render_texture", boom)
    monkeypatch.setattr(pad_design.pad, "render_texture", boom)
    seq = Dataset(moving_dataset, verify=True)[0]
    assert seq.pad.texture_rgb.shape[0] == int(round(seq.pad.side_m * seq.pad.ppm))
    assert (seq.root / "pad.json").read_text().count("../pad.png") == 1


# ----------------------------------------------------------------------------- the one-render blur

def test_velocity_blur_matches_the_subframe_reference():
    """Strong motion blur (20 ms exposure, gusts): the one-render blur against one render per
    sample time, on the corners of the marker squares (refined on both images)."""
    from hvloc.features import refine_quads

    def spec(method):
        return _spec({"name": "blur", "seed": 800, "sequences": 1, "pad_ppm": 2000,
                      "camera": {"width": 300, "height": 300, "hfov_deg": 60, "fps": 2, "exposure_s": 0.02,
                                 "supersample": 2},
                      "platform": {"height_m": 0.5},
                      "trajectory": {"families": ["spiral"], "start_height_m": 4, "duration_s": [10, 10],
                                     "lateral_offset_m": [0, 1], "gust_accel_mps2": [1.0, 1.0]},
                      "environment": {"shadows": False},
                      "degradations": {"blur_method": method, "shot_noise": [0, 0], "read_noise": [0, 0],
                                       "defocus_sigma_px": [0, 0]}})

    fast, ref = SequenceRenderer(spec("velocity"), 0), SequenceRenderer(spec("subframes"), 0)
    errs, psnr, blurs = [], [], []
    try:
        for k in range(len(fast) // 2, len(fast) - 1):
            a, b = fast.render(k), ref.render(k)
            assert a.labels["blur_subframes"] == b.labels["blur_subframes"]
            blurs.append(a.labels["blur_px"])
            d = a.rgb.astype(float) - b.rgb.astype(float)
            psnr.append(10 * math.log10(255**2 / max(float((d * d).mean()), 1e-9)))
            pad2cam = invert(fast.cam2pad(k))
            quads = np.array([fast.camera.project(transform_points(pad2cam, sq.corners))
                              for m in fast.pad.geometry.markers_in("corner") for sq in m.squares])
            ok = (np.isfinite(quads).all(axis=(1, 2)) & (quads.min(axis=(1, 2)) > 5) & (quads.max(axis=(1, 2)) < 294)
                  & (np.linalg.norm(quads[:, 0] - quads[:, 1], axis=1) > 20))
            if not ok.any():
                continue
            g = [cv2.cvtColor(x.rgb, cv2.COLOR_RGB2GRAY).astype(np.float32) for x in (a, b)]
            qa, _ = refine_quads(g[0], quads[ok], 3.0, fast.camera)
            qb, _ = refine_quads(g[1], quads[ok], 3.0, fast.camera)
            e = np.linalg.norm(qa - qb, axis=2).ravel()
            errs += list(e[np.isfinite(e)])
    finally:
        fast.close()
        ref.close()
    assert max(blurs) > 4.0 and len(errs) >= 40, (max(blurs), len(errs))
    assert float(np.median(errs)) <= 0.05 and float(np.median(psnr)) >= 33.0, \
        f"corner difference median {np.median(errs):.3f} px, PSNR median {np.median(psnr):.1f} dB"


# ----------------------------------------------------------------------------- the camera

def _rs_spec(line_s):
    return _spec({"name": "rs", "seed": 5, "sequences": 1,
                  "camera": {"width": 480, "height": 480, "hfov_deg": 70, "fps": 10, "exposure_s": 0.0, "supersample": 2,
                             "rolling_shutter_line_s": line_s},
                  "platform": {"height_m": 0.5},
                  "trajectory": {"families": ["straight"], "start_height_m": 3.0, "duration_s": [6, 6],
                                 "lateral_offset_m": [0, 0.2], "yaw_change_deg": [400, 400], "gust_accel_mps2": [0, 0]},
                  "environment": {"shadows": False, "distractors": {"boxes": [0, 0], "decoy_patches": [0, 0],
                                                                    "decoy_markers": [0, 0]}},
                  "degradations": {"shot_noise": [0, 0], "read_noise": [0, 0], "defocus_sigma_px": [0, 0]}})


def test_rolling_shutter_skew_matches_the_line_time():
    """During a fast yaw, every textured point of the pad moves between a global-shutter and a
    rolling-shutter image by its image velocity times its row's time offset: the line time
    estimated from the images (LK on 7 x 7 pad points, three frames) is within 5 % of the spec's."""
    line = 40e-6
    gs, rs = SequenceRenderer(_rs_spec(0.0), 0), SequenceRenderer(_rs_spec(line), 0)
    num = den = 0.0
    try:
        for k in (20, 25, 30):
            a, b = gs.render(k), rs.render(k)
            t, cam = float(gs.times[k]), gs.camera
            g = np.linspace(-0.3, 0.3, 7)
            P = np.array([[x, y, 0.0] for x in g for y in g])
            x0 = cam.project_from(gs.cam2pad(k), P)
            B, Q = gs._poses_at(np.array([t - 1e-3, t + 1e-3]))
            v = (cam.project_from(invert(Q[1]) @ B[1] @ gs.T_B_C, P)
                 - cam.project_from(invert(Q[0]) @ B[0] @ gs.T_B_C, P)) / 2e-3
            ga, gb = (cv2.cvtColor(x.rgb, cv2.COLOR_RGB2GRAY) for x in (a, b))
            inside = (x0 > 20).all(axis=1) & (x0 < 460).all(axis=1)
            p1, st, _ = cv2.calcOpticalFlowPyrLK(ga, gb, x0[inside].astype(np.float32).reshape(-1, 1, 2), None,
                                                 winSize=(15, 15), maxLevel=2,
                                                 criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-4))
            ok = st[:, 0] == 1
            shift = (p1[:, 0, :] - x0[inside])[ok]
            A = (v[inside] * (x0[inside, 1:2] - rs.ref_row))[ok]
            num += float((A * shift).sum())
            den += float((A * A).sum())
            # and the corner labels are where the corners appear, each at its own row's time (a corner
            # near the reference row barely moves: the one furthest from it moves most)
            moved = max(math.hypot(b.labels[f"c{i}u"] - a.labels[f"c{i}u"], b.labels[f"c{i}v"] - a.labels[f"c{i}v"])
                        for i in range(4))
            assert moved > 0.3, (k, moved)
    finally:
        gs.close()
        rs.close()
    assert abs(num / den / line - 1) < 0.05, f"line time from the images {num / den * 1e6:.2f} us, spec {line * 1e6:.1f} us"


def test_rolling_shutter_dataset_verifies(tmp_path):
    spec = _spec({**json.loads(_rs_spec(4e-5).canonical_json()), "camera": {
        **json.loads(_rs_spec(4e-5).canonical_json())["camera"], "width": 240, "height": 240}})
    generate(spec, tmp_path / "rs", show_progress=False)
    assert verify_dataset(tmp_path / "rs") == []


def test_auto_exposure_darkens_as_the_white_pad_fills_the_view_and_lags():
    d = {"name": "ae", "seed": 2, "sequences": 1, "camera": {"width": 96, "height": 96, "fps": 10, "auto_exposure_lag_s": 0.5},
         "trajectory": {"families": ["straight"], "start_height_m": 5.0, "duration_s": [8, 8], "lateral_offset_m": [0, 0]}}
    with SequenceRenderer(_spec(d), 0) as r:
        g = r.exposure_gain
        assert g[0] > 0.95 and g[-1] < 0.8 * g[0]  # the pad fills the view at the end: less gain
        target_end = g[-1]
    d["camera"]["auto_exposure_lag_s"] = 0.05
    with SequenceRenderer(_spec(d), 0) as r:
        fast = r.exposure_gain
    assert np.argmax(fast < 0.9) < np.argmax(g < 0.9)  # a longer lag follows later
    assert abs(fast[-1] - target_end) < 0.05


@pytest.mark.parametrize("family", ["straight", "spiral", "hover_correct", "manoeuvres"])
def test_trajectories_are_smooth_whatever_their_duration(family):
    """A multirotor's attitude follows its acceleration: no frame may tilt more than its
    neighbours allow.  Short gusty descents (fade-in and fade-out of the gusts overlapping) had
    an acceleration spike at the end of the fade-in: a 54 deg tilt for exactly one frame."""
    from render.spec import TrajectorySpec
    from render.trajectory import make_trajectory

    checked = []
    for duration in (3.0, 4.0, 5.0, 7.0, 9.0):
        spec = TrajectorySpec.model_validate({"duration_s": [duration, duration], "gust_accel_mps2": [2.0, 2.0],
                                              "start_height_m": 4.0, "lateral_offset_m": [0.0, 0.3],
                                              "families": [family]})
        traj = make_trajectory(spec, np.random.default_rng(3), family, 0.05, 0.5)
        t = np.arange(0.0, traj.duration, 0.002)
        s = traj.state(t)
        traj.gusts = None
        calm = traj.state(t)
        gust = s.acc_W - calm.acc_W  # what the gusts add: bounded by their amplitude, and smooth
        assert np.linalg.norm(gust, axis=1).max() < 3 * 2.0, (family, duration)
        assert np.linalg.norm(np.diff(gust, axis=0), axis=1).max() < 0.2, (family, duration)
        if np.linalg.norm(calm.acc_W, axis=1).max() < 5.0:  # a path a multirotor can fly (short keyframe
            # families squeezed into 3 s are not: the spec does not refuse them yet)
            tilt = np.degrees(np.arccos(np.clip(s.R_W_B[:, 2, 2], -1, 1)))
            assert np.abs(np.diff(tilt)).max() < 1.0, (family, duration)  # per 2 ms
            checked.append((family, duration))
    assert family in ("hover_correct", "manoeuvres") or len(checked) >= 2


@pytest.mark.parametrize("family", ["straight", "spiral", "hover_correct", "manoeuvres"])
def test_the_bodys_rate_never_steps(family):
    """The attitude follows the acceleration, so the body's rate follows the jerk: where a path joins
    two moves (keyframes, a lateral move that ends before the descent does, the gusts' fade) the jerk
    must not step, or the rate jumps between two IMU rows (4.7 rad/s on a hover-and-correct descent
    with minimum-jerk segments) and one frame is smeared 30 px behind a sharp one.  A continuous rate
    changes four times less over a quarter of the time; a step changes as much."""
    from render.spec import TrajectorySpec
    from render.trajectory import make_trajectory

    for seed in (1, 2, 3):
        spec = TrajectorySpec.model_validate({"duration_s": [12, 16], "gust_accel_mps2": [1.0, 1.0],
                                              "start_height_m": 12.0, "lateral_offset_m": [1.0, 3.0],
                                              "final_offset_m": [0.0, 0.3], "families": [family]})
        traj = make_trajectory(spec, np.random.default_rng(seed), family, 0.05, 0.0)
        step = []
        for dt in (0.02, 0.005):  # both past the 2 ms over which state() differentiates
            w = traj.state(np.arange(0.0, traj.duration, dt)).omega_B
            step.append(np.linalg.norm(np.diff(w, axis=0), axis=1).max())
        assert step[1] < 0.4 * step[0], (family, seed, step)


def test_a_gusty_rolling_shutter_descent_on_a_moving_deck_verifies(tmp_path):
    """Rolling shutter at a low frame rate, gusts, an oblique mount, a wide lens, a moving deck:
    the labels must pass the dataset's own checks.  verify used to flag such a dataset (its
    interpolated poses err by more than a fixed 0.5 px when the motion bends between frames) and
    the generator labelled a corner visible after the shutter had carried it out of the image."""
    spec = DatasetSpec.model_validate({
        "name": "rsgust", "seed": 11, "sequences": 2, "pad_ppm": 600,
        "pad": {"side_m": 1.5, "border_m": 0.18, "marker_size_m": 0.22},
        "platform": {"height_m": 0.4, "size_m": 2.0, "velocity_mps": [0.5, -0.3]},
        "camera": {"width": 480, "height": 270, "fps": 10, "hfov_deg": 100, "dist": [-0.2, 0.03, 0, 0, 0],
                   "rolling_shutter_line_s": 8e-5, "mount": {"rpy_deg": [200, 0, -90]}},
        "trajectory": {"start_height_m": 10.0, "duration_s": [14, 16], "gust_accel_mps2": [0.5, 0.8],
                       "families": ["straight", "spiral"]}})
    generate(spec, tmp_path / "ds", show_progress=False)
    assert verify_dataset(tmp_path / "ds") == []


def test_a_box_shadow_across_a_pad_on_the_ground_darkens_it_evenly(tmp_path):
    """A shadow lying in the pad's own plane z-fought with it: the pad came out in stripes, half lit,
    half shadowed (a 64 px descent that `verify` refused).  Now the shadowed pad is the lit pad times
    one factor: same scene with and without shadows, the luma ratio over the pad is one number."""
    spec = {"name": "shade", "seed": 6, "sequences": 3, "pad_ppm": 500, "camera": {"width": 64, "height": 64, "fps": 2},
            "trajectory": {"start_height_m": 3.0, "duration_s": [4.0, 4.0], "lateral_offset_m": [0.0, 0.3],
                           "families": ["straight", "spiral"]},
            "degradations": {"shot_noise": [0.0, 0.0], "read_noise": [0.0, 0.0]}}
    generate(_spec(spec), tmp_path / "on", show_progress=False)
    generate(_spec({**spec, "environment": {"shadows": False}}), tmp_path / "off", show_progress=False)
    assert verify_dataset(tmp_path / "on") == []
    on, off = Dataset(tmp_path / "on")["seq_0002"], Dataset(tmp_path / "off")["seq_0002"]
    k = 4  # the whole pad in view, a box's shadow over all of it
    assert on.columns["pad_visible_fraction"][k] > 0.5
    corners = np.array([[on.columns[f"c{i}u"][k], on.columns[f"c{i}v"][k]] for i in range(4)])
    inside = np.zeros((64, 64), np.uint8)
    if np.isfinite(corners).all():
        cv2.fillConvexPoly(inside, np.round(corners).astype(np.int32), 1)
    else:  # the pad fills the view
        inside[:] = 1
    inside = cv2.erode(inside, np.ones((5, 5), np.uint8)) > 0
    a = cv2.cvtColor(on.image(k), cv2.COLOR_RGB2GRAY).astype(float)[inside]
    b = cv2.cvtColor(off.image(k), cv2.COLOR_RGB2GRAY).astype(float)[inside]
    bright = b > 120  # the white field: the ratio is well defined there
    ratio = a[bright] / b[bright]
    assert bright.sum() > 300 and ratio.mean() < 0.8  # in shadow
    assert np.percentile(ratio, 95) - np.percentile(ratio, 5) < 0.15, np.percentile(ratio, [5, 50, 95])


def test_a_mono_camera_sums_the_light_its_colour_twin_sees(tmp_path):
    """``camera.mono``: no colour filter, so each pixel is the scene's light summed with Rec. 709's
    weights before the tone curve (not a grey conversion of the finished colour frame), written as
    grey RGB; its JPEG is grey too.  Same scene, same draws: the mono frame is the colour frame's
    linear channels weighted, through the sequence's own tone curve, within a level's rounding."""
    from render.imaging import MONO_RESPONSE, SRGB_GAMMA

    spec = {"name": "grey", "seed": 9, "sequences": 1, "pad_ppm": 500,
            "camera": {"width": 96, "height": 96, "fps": 2, "vignetting": [0.3, 0.3]},
            "trajectory": {"start_height_m": 3.0, "duration_s": [2.0, 2.0], "lateral_offset_m": [0.0, 0.3],
                           "families": ["spiral"]},
            "degradations": {"shot_noise": [0.0, 0.0], "read_noise": [0.0, 0.0], "defocus_sigma_px": [0.5, 0.5]}}
    generate(_spec(spec), tmp_path / "rgb", show_progress=False)
    generate(_spec(_merge(spec, {"camera.mono": True})), tmp_path / "mono", show_progress=False)
    assert verify_dataset(tmp_path / "mono") == []
    rgb, mono = Dataset(tmp_path / "rgb")["seq_0000"], Dataset(tmp_path / "mono")["seq_0000"]
    assert mono.camera_info["mono"] is True and rgb.camera_info["mono"] is False
    imaging = json.loads((tmp_path / "mono" / "seq_0000" / "meta.json").read_text())["imaging"]
    assert imaging["mono"] is True
    e = SRGB_GAMMA * imaging["gamma"]
    apart = 0.0
    for k in range(len(mono)):
        c, m = rgb.image(k).astype(np.float64), mono.image(k)
        assert (m[..., 0] == m[..., 1]).all() and (m[..., 1] == m[..., 2]).all()
        lit = c.max(axis=2) < 255  # (a clipped channel's light is not known)
        want = 255.0 * (((c / 255.0) ** e) @ MONO_RESPONSE.astype(np.float64)) ** (1.0 / e)
        off = np.abs(m[..., 0].astype(np.float64) - want)[lit]
        assert lit.mean() > 0.9 and np.percentile(off, 99) <= 1.5, np.percentile(off, [50, 99, 100])
        apart = max(apart, np.abs(m[..., 0].astype(np.float64) - cv2.cvtColor(rgb.image(k), cv2.COLOR_RGB2GRAY)).max())
    assert apart > 5  # not the finished colour frame's grey: that differs where colours do (the magenta border)
    generate(_spec(_merge(spec, {"camera.mono": True, "degradations.jpeg_quality": 40})), tmp_path / "jpeg",
             show_progress=False)
    j = Dataset(tmp_path / "jpeg")["seq_0000"].image(0)
    assert (j[..., 0] == j[..., 1]).all() and (j[..., 1] == j[..., 2]).all()


def test_real_timing_jitter_dropped_frames_and_imu_clock_offset_are_rendered_and_labelled(tmp_path):
    """The time contract with a real camera's timing: frame k is captured at k / fps plus its jitter
    (frames.csv's t is the true time), dropped frames leave gaps in k (rows and images missing), and
    imu.csv runs on the IMU's clock, offset as camera.json says.  Labels still agree with the images
    (verify, image check included), and the localizer's harness reads the IMU at the right time."""
    from benchmarks.run import imu_at, imu_since, localize_dataset, read_estimates
    from hvloc.geometry import matrix_from_quat_xyzw, rotation_angle

    base = {"name": "timing", "seed": 3, "sequences": 1, "pad_ppm": 500,
            "camera": {"width": 240, "height": 240, "fps": 8, "exposure_s": 0.004},
            "trajectory": {"families": ["straight"], "start_height_m": 3.0, "duration_s": [6.0, 6.0],
                           "lateral_offset_m": [0.0, 0.1], "yaw_change_deg": [40.0, 40.0]},
            "environment": {"distractors": {"boxes": [0, 0], "decoy_patches": [0, 0], "decoy_markers": [0, 0]}}}
    real = _merge(base, {"camera.frame_time_jitter_s": 0.01, "camera.frame_drop_rate": 0.25, "imu.time_offset_s": 0.03})
    generate(_spec(base), tmp_path / "ideal", show_progress=False)
    generate(_spec(real), tmp_path / "real", show_progress=False)
    assert verify_dataset(tmp_path / "real") == []
    ideal, seq = Dataset(tmp_path / "ideal")["seq_0000"], Dataset(tmp_path / "real")["seq_0000"]
    k, t = seq.columns["frame"].astype(int), seq.t
    assert len(seq) < len(ideal) and k[0] == 0 and k[-1] == len(ideal) - 1 and np.all(np.diff(k) >= 1)
    assert np.any(np.diff(k) > 1)  # gaps
    assert sorted(p.name for p in (tmp_path / "real" / "seq_0000" / "images").iterdir()) == [f"{i:06d}.png" for i in k]
    dt = t - k / 8
    assert np.abs(dt).max() <= 0.4 / 8 + 1e-12 and np.std(dt[1:]) > 0.005  # jittered, never reordered
    # the true pose at the true time: the same trajectory as the ideal camera's, sampled where the frame was taken
    for i in (3, len(seq) // 2):
        assert np.allclose(seq.cam2pad_at(i), ideal.pose_at(float(t[i])), atol=2e-3)
    # imu.csv on the IMU's clock: the same samples, 30 ms later on it
    np.testing.assert_allclose(seq.imu[:, 0], ideal.imu[:, 0] + 0.03, atol=1e-12)
    np.testing.assert_allclose(seq.imu[:, 1:], ideal.imu[:, 1:], atol=1e-12)
    assert seq.imu_time_offset_s == 0.03 and seq.camera_info["frame_drop_rate"] == 0.25
    R_true = ideal.imu[int(np.searchsorted(ideal.imu[:, 0], t[5] + 1e-9)) - 1, 7:]
    assert rotation_angle(matrix_from_quat_xyzw(imu_at(seq.imu, float(t[5]), seq.imu_time_offset_s)[7:]),
                          matrix_from_quat_xyzw(R_true)) < 1e-9
    # the rows since the last frame (what the localizer is given): on the camera's clock after the
    # frame before, up to this one, the last the row imu_at reads; a gap's rows included
    for i in (5, int(np.argmax(np.diff(k) > 1)) + 1):
        blk = imu_since(seq.imu, float(t[i - 1]), float(t[i]), seq.imu_time_offset_s)
        on_cam = seq.imu[:, 0] - seq.imu_time_offset_s
        assert np.array_equal(blk, seq.imu[(on_cam > t[i - 1] + 1e-9) & (on_cam < t[i] + 1e-9)])
        assert np.array_equal(blk[-1], imu_at(seq.imu, float(t[i]), seq.imu_time_offset_s))
        assert len(blk) >= round((t[i] - t[i - 1]) * 200) - 1
    # the localizer's output names the dataset's frames, gaps and all
    localize_dataset(tmp_path / "real", tmp_path / "est", show_progress=False)
    est = read_estimates(tmp_path / "est" / "seq_0000" / "estimates.csv")
    assert list(est["frame"].astype(int)) == list(k)
    # benchmarks.tilt pairs each estimate with its own frame's truth (by row: the frame numbers have
    # gaps; it took the number for the row, paired later frames with earlier truths and ran off the end)
    from benchmarks.tilt import tilt_rows

    res = tmp_path / "res"
    (res / "estimates" / "hierarchical").mkdir(parents=True)
    (res / "datasets").mkdir()
    (res / "datasets" / "real").symlink_to(tmp_path / "real")
    (res / "estimates" / "hierarchical" / "real").symlink_to(tmp_path / "est")
    rows = tilt_rows(res)
    row_of = {int(f): i for i, f in enumerate(k)}
    assert len(rows) == int(np.sum(est["status"] == "ok")) > 5 and max(r[2] for r in rows) >= len(seq)
    for _, _, frame, h, lateral, *_ in rows:
        i = row_of[frame]
        assert h == seq.cam2pad[i][2, 3]
        assert lateral == pytest.approx(math.hypot(est["tx"][i] - seq.cam2pad[i][0, 3], est["ty"][i] - seq.cam2pad[i][1, 3]))
    localize_dataset(tmp_path / "ideal", tmp_path / "est_ideal", show_progress=False)
    ok_ideal = np.mean(read_estimates(tmp_path / "est_ideal" / "seq_0000" / "estimates.csv")["status"] == "ok")
    assert np.mean(est["status"] == "ok") >= ok_ideal - 0.1 and ok_ideal > 0.5  # the gates cope with the timing


def test_a_fisheye_action_camera_renders_true_labels_and_is_localized(tmp_path):
    """A fisheye (OpenCV's Kannala-Brandt model, 120 degrees across, mounted 15 degrees off nadir):
    its labels pass the dataset's own checks (the image check included), and the localizer, which
    fits every line in undistorted coordinates, holds on it: no false accept, few frames lost."""
    from benchmarks.run import localize_dataset, read_estimates
    from hvloc.geometry import matrix_from_quat_xyzw, rotation_angle

    spec = _spec({"name": "fish", "seed": 4, "sequences": 1, "pad_ppm": 600,
                  "camera": {"width": 480, "height": 360, "fps": 5, "model": "fisheye", "hfov_deg": 120,
                             "dist": [0.02, -0.01, 0.002, -0.0002], "mount": {"rpy_deg": [195, 0, -90]}},
                  "trajectory": {"families": ["straight"], "start_height_m": 5.0, "duration_s": [9.0, 9.0],
                                 "lateral_offset_m": [0.5, 1.0]}})
    generate(spec, tmp_path / "ds", show_progress=False)
    assert verify_dataset(tmp_path / "ds") == []
    seq = Dataset(tmp_path / "ds")["seq_0000"]
    assert seq.camera.model == "fisheye" and seq.camera_info["model"] == "fisheye"
    localize_dataset(tmp_path / "ds", tmp_path / "est", show_progress=False)
    est = read_estimates(tmp_path / "est" / "seq_0000" / "estimates.csv")
    ok = est["status"] == "ok"
    assert ok.mean() >= 0.9, ok.mean()
    for i in np.flatnonzero(ok):
        T = seq.cam2pad[i]
        pos = np.linalg.norm(np.array([est[c][i] for c in ("tx", "ty", "tz")]) - T[:3, 3])
        rot = np.degrees(rotation_angle(matrix_from_quat_xyzw([est[c][i] for c in ("qx", "qy", "qz", "qw")]), T[:3, :3]))
        assert pos < 0.1 * T[2, 3] and rot < 5.0, (i, pos, rot, T[2, 3])


def test_no_distractor_lies_within_keep_clear_of_the_pad():
    """``keep_clear_m`` is about the distractor, not its centre: a 2 x 5 m box drawn 2.5 m away used
    to cover part of the pad in the conditions suite's *nominal* descent (68 of its 157 Approaching
    frames lost).  Every drawn footprint's nearest point is now at least that far from the pad."""
    from render.scene import draw_scene

    def nearest(x, y, yaw, sx, sy):
        u, v = np.meshgrid(np.linspace(-sx / 2, sx / 2, 60), np.linspace(-sy / 2, sy / 2, 60))
        c, s = np.cos(yaw), np.sin(yaw)
        return float(np.hypot(x + c * u - s * v, y + s * u + c * v).min())

    checked = 0
    for keep in (0.8, 2.5):
        env = _spec({"environment": {"distractors": {"keep_clear_m": keep, "boxes": [4, 6], "decoy_patches": [2, 2],
                                                     "decoy_markers": [2, 2]}}}).environment
        for seed in range(30):
            d = draw_scene(env, np.random.default_rng(seed), 25.0)
            for x, y, yaw, sx, sy, *_ in d.boxes:
                assert nearest(x, y, yaw, sx, sy) >= keep - 1e-6, (keep, seed, x, y, sx, sy)
                checked += 1
            for x, y, yaw, sx, sy in d.decoy_patches:
                assert nearest(x, y, yaw, sx, sy) >= keep - 1e-6
            for x, y, yaw, size, *_ in d.decoy_markers:
                assert nearest(x, y, yaw, size, size) >= keep - 1e-6
    assert checked > 250


def test_no_distractor_lies_within_keep_clear_of_a_moving_pads_path():
    """A platform moving at constant velocity takes the pad along a straight path; distractors were
    kept clear of its start only, so the deck drove through boxes (the conditions suite's
    moving_deck: a box over the pad for 25 frames at 7-9 m).  Every footprint drawn at random now
    keeps ``keep_clear_m`` from every point of the path (as the spec's sequences plan it), while a
    box the spec places (``boxes_at``) stays where it is put; a pad that does not move draws its
    scene as before."""
    from render.plan import plan_sequence
    from render.scene import draw_scene

    def nearest(path, x, y, yaw, sx, sy):
        u, v = np.meshgrid(np.linspace(-sx / 2, sx / 2, 40), np.linspace(-sy / 2, sy / 2, 40))
        c, s = np.cos(yaw), np.sin(yaw)
        fx, fy = (x + c * u - s * v).ravel(), (y + s * u + c * v).ravel()
        return float(np.hypot(fx[:, None] - path[None, :, 0], fy[:, None] - path[None, :, 1]).min())

    keep, end = 1.0, np.array([9.0, -4.0])
    path = np.linspace(0.0, 1.0, 400)[:, None] * end
    env = _spec({"environment": {"distractors": {"keep_clear_m": keep, "boxes": [5, 6], "decoy_patches": [3, 3],
                                                 "decoy_markers": [3, 3]}}}).environment
    moved = 0
    for seed in range(30):
        still = draw_scene(env, np.random.default_rng(seed), 25.0)
        d = draw_scene(env, np.random.default_rng(seed), 25.0, pad_path_m=end)
        assert d.ground == still.ground and d.sun_elevation_rad == still.sun_elevation_rad
        for (x, y, yaw, sx, sy, *_), b in zip(d.boxes, still.boxes):
            assert nearest(path, x, y, yaw, sx, sy) >= keep - 0.01, (seed, x, y, sx, sy)
            moved += (x, y) != b[:2]
        for x, y, yaw, sx, sy in d.decoy_patches:
            assert nearest(path, x, y, yaw, sx, sy) >= keep - 0.01
        for x, y, yaw, size, *_ in d.decoy_markers:
            assert nearest(path, x, y, yaw, size, size) >= keep - 0.01
    assert moved >= 5, moved  # (the path does cross where boxes were drawn)
    # as the generator plans a sequence: the path is the platform's velocity over the descent
    spec = _spec({"platform": {"height_m": 0.4, "velocity_mps": [0.9, -0.4]},
                  "environment": {"distractors": {"keep_clear_m": keep, "boxes": [6, 6],
                                                  "boxes_at": [{"xy_m": [2.0, -0.9], "size_m": [0.5, 0.5, 1.0]}]}}})
    plan = plan_sequence(spec, 0)
    end = np.asarray(spec.platform.velocity_mps) * plan.trajectory.duration
    path = np.linspace(0.0, 1.0, 400)[:, None] * end
    placed, *drawn = plan.scene_draw.boxes
    assert placed[:2] == (2.0, -0.9)  # on the path, as the spec asks
    for x, y, yaw, sx, sy, *_ in drawn:
        assert nearest(path, x, y, yaw, sx, sy) >= keep - 0.01


def test_no_distractor_drawn_at_random_stands_in_the_platform():
    """``keep_clear_m`` is measured from the pad centre; under the platform's half-diagonal a box
    was drawn through the platform's solid (a patch or a marker under it).  With a 1.6 m platform
    and ``keep_clear_m`` 0.3, no point of any footprint drawn at random lies on the platform, in
    the scene the generator plans for each descent; a box the spec places (``boxes_at``) stays
    where it is put.  (Render revision 11.)"""
    from render.plan import plan_sequence

    side = 1.6
    d = {"platform": {"height_m": 0.5, "size_m": side},
         "environment": {"distractors": {"keep_clear_m": 0.3, "boxes": [4, 6], "decoy_patches": [3, 4],
                                         "decoy_markers": [3, 4],
                                         "boxes_at": [{"xy_m": [0.9, 0.0], "size_m": [0.3, 0.3, 1.0]}]}}}

    def on_platform(x, y, yaw, sx, sy):
        u, v = np.meshgrid(np.linspace(-sx / 2, sx / 2, 30), np.linspace(-sy / 2, sy / 2, 30))
        c, s = np.cos(yaw), np.sin(yaw)
        fx, fy = (x + c * u - s * v).ravel(), (y + s * u + c * v).ravel()
        return bool(((np.abs(fx) < side / 2) & (np.abs(fy) < side / 2)).any())

    drawn = 0
    for seed in range(12):
        sc = plan_sequence(_spec({**d, "seed": seed}), 0).scene_draw
        placed, *boxes = sc.boxes
        assert placed[:2] == (0.9, 0.0)
        for x, y, yaw, sx, sy, *_ in boxes:
            assert not on_platform(x, y, yaw, sx, sy), (seed, x, y, sx, sy)
        for x, y, yaw, sx, sy in sc.decoy_patches:
            assert not on_platform(x, y, yaw, sx, sy), (seed, x, y, sx, sy)
        for x, y, yaw, size, *_ in sc.decoy_markers:
            assert not on_platform(x, y, yaw, size, size), (seed, x, y, size)
        drawn += len(boxes) + len(sc.decoy_patches) + len(sc.decoy_markers)
    assert drawn >= 12 * 10


def test_the_drones_shadow_does_not_darken_a_box_shadow_twice():
    """Two translucent shadow layers multiply: where the drone's shadow fell inside a box's, the
    ground came out darker than either shadow (sun taken twice).  Now the drone's shadow takes
    nothing where the ground is already in shadow: inside a box's shadow the ground is as dark
    with the drone's shadow over it as without, and as dark as the drone's shadow on lit ground."""
    from hvloc.geometry import Camera, look_at_cam2world, make_transform
    from pad_design import make_pad
    from render.scene import LandingScene, SceneDraw

    e, a = math.radians(45.0), math.radians(90.0)  # the sun in the east: shadows fall west
    draw = SceneDraw("concrete", e, a, 3.0, 0.35, [(3.0, 6.0, 0.0, 2.0, 2.0, 4.0, (120, 120, 125))], [], [])
    cam = Camera.from_hfov(200, 200, math.radians(60))
    scene = LandingScene(make_pad(ppm=500), draw, 0.0, 0.0, cam, (255, 48, 224), np.random.default_rng(0))
    try:
        s = draw.sun_dir_W
        spot = np.array([-2.0, 6.0])  # the far edge of the box's shadow (it spans x from -2 to 4)
        body = make_transform(np.eye(3), (*(spot + s[:2] * 2.0 / s[2]), 2.0))  # its shadow centred on the spot
        scene.set_drone(body)
        T_W_C = look_at_cam2world((-2.0, 6.0, 4.0), (-2.0, 6.0, 0.0))
        img = cv2.cvtColor(scene.render(T_W_C), cv2.COLOR_RGB2GRAY).astype(float)
        scene.set_drone(make_transform(np.eye(3), (50.0, 50.0, 2.0)))  # the drone far away
        alone = cv2.cvtColor(scene.render(T_W_C), cv2.COLOR_RGB2GRAY).astype(float)
    finally:
        scene.close()

    def luma(im, x, y):
        u, v = np.round(cam.project_from(T_W_C, [[x, y, 0.0]])[0]).astype(int)
        return float(np.median(im[v - 2:v + 3, u - 2:u + 3]))

    box_only, both, drone_only, lit = luma(img, -1.0, 6.0), luma(img, -1.9, 6.0), luma(img, -2.1, 6.0), luma(img, -3.0, 6.0)
    assert lit > 1.5 * box_only  # the scene has a real shadow
    assert abs(luma(alone, -1.9, 6.0) - box_only) < 0.1 * box_only  # the box's shadow there, alone
    assert abs(both - box_only) < 0.1 * box_only, (both, box_only)  # no second darkening
    assert abs(drone_only - box_only) < 0.15 * box_only, (drone_only, box_only)  # one shadow, one darkness


def _pad_close_up(name: str, sun_elevation_deg: list, start_height_m: float) -> dict:
    """A short noiseless straight descent over sand, 240x240, the pad large in view: a spec to
    compare a pad material against the plain pad on (same seed: same flight, scene and light)."""
    return {"name": name, "seed": 8, "sequences": 1, "pad_ppm": 600,
            "camera": {"width": 240, "height": 240, "fps": 4, "hfov_deg": 60},
            "environment": {"sun_elevation_deg": sun_elevation_deg, "ground": ["sand"]},
            "trajectory": {"families": ["straight"], "start_height_m": start_height_m, "duration_s": [4.0, 4.0],
                           "lateral_offset_m": [0.0, 0.2]},
            "degradations": {"shot_noise": [0.0, 0.0], "read_noise": [0.0, 0.0], "motion_blur": False}}


def test_no_glare_where_the_drones_shadow_lies_on_a_glossy_pad():
    """The sun's glare was added over the whole pad, inside the drone's own shadow too (there the
    border came out grey instead of dark magenta).  Same descent with and without gloss: pad pixels
    in the drone's shadow are equal, lit pad pixels gain the glare."""
    base = _pad_close_up("glossy", [84.0, 86.0], 4.0)
    glossy = _spec({**base, "pad_material": {"gloss": [0.6, 0.6]}})
    checked = 0
    with SequenceRenderer(_spec(base), 0) as plain_r, SequenceRenderer(glossy, 0) as gloss_r:
        for k in range(len(gloss_r)):
            a, b = plain_r.render(k).rgb.astype(float), gloss_r.render(k).rgb.astype(float)
            g = np.linspace(-0.4, 0.4, 41)
            P = np.column_stack([np.repeat(g, len(g)), np.tile(g, len(g)), np.zeros(len(g) ** 2)])
            vis = gloss_r.scene.pad_sun_visibility(P[:, :2] + gloss_r.pad2world[k][:2, 3])
            px = np.round(gloss_r.camera.project_from(gloss_r.cam2pad(k), P)).astype(int)
            ok = np.all((px >= 2) & (px < 238), axis=1)
            dark, lit = ok & (vis == 0.0), ok & (vis == 1.0)
            if dark.sum() < 20 or lit.sum() < 20:
                continue
            # inside the shadow (away from its edge: the blur of the lens) nothing is added
            d = np.abs(b[px[dark, 1], px[dark, 0]] - a[px[dark, 1], px[dark, 0]]).mean(axis=1)
            gain = (b[px[lit, 1], px[lit, 0]] - a[px[lit, 1], px[lit, 0]]).mean()
            assert np.median(d) <= 1.0 and gain > 10.0, (k, np.median(d), gain)
            checked += 1
    assert checked >= 2


def test_glare_covers_the_pixels_the_pads_edge_crosses_by_their_share():
    """The multisampled raster mixes the colour of a pixel the pad's edge crosses by how much of
    it the pad covers, but the glare (and a wrinkle's light) was added by the depth at the pixel's
    centre, all or nothing: a glaring pad had a saturated, unlit ring a pixel wide around it
    (what the border's edge fit then read).  Same descent with and without gloss: at those pixels
    the glare added is the share of the pixel inside the labelled outline times the glare just
    inside it."""
    base = _pad_close_up("edge", [70.0, 70.0], 3.0)
    base["degradations"]["defocus_sigma_px"] = [0.0, 0.0]  # (the lens's blur would spread the ring too)
    glossy = _spec({**base, "pad_material": {"gloss": [0.5, 0.5], "gloss_roughness": [0.5, 0.5]}})
    errs = []
    with SequenceRenderer(_spec(base), 0) as plain_r, SequenceRenderer(glossy, 0) as gloss_r:
        for k in range(0, len(gloss_r), 2):
            # green: the border's weakest channel (its red is already 255), the glare is white
            g = [r.render(k).rgb[..., 1] for r in (plain_r, gloss_r)]
            lin = [(x.astype(float) / 255.0) ** (1.0 / gloss_r.imaging.tone_exponent) for x in g]
            added = np.where(g[1] < 250, lin[1] - lin[0], np.nan)  # (a clipped glare tells no share)
            quad = gloss_r.camera.project_from(gloss_r.cam2pad(k), gloss_r.pad.outer_corners_P).astype(np.float32)
            x0, y0 = np.floor(quad.min(axis=0)).astype(int) - 2
            x1, y1 = np.ceil(quad.max(axis=0)).astype(int) + 3
            if x0 < 5 or y0 < 5 or x1 > 235 or y1 > 235:
                continue
            inside = {(x, y): cv2.pointPolygonTest(quad, (float(x), float(y)), True)
                      for y in range(y0, y1) for x in range(x0, x1)}
            for (x, y), d in inside.items():
                if abs(d) > 0.35:
                    continue
                near = [added[v, u] for u in range(x - 4, x + 5) for v in range(y - 4, y + 5)
                        if inside.get((u, v), -1.0) >= 2.0]
                ref = float(np.mean(near)) if near else 0.0
                if ref > 0.02 and np.isfinite(added[y, x]):  # lit and glaring there (not in the drone's shadow)
                    errs.append(abs(added[y, x] / ref - (0.5 + d)))
    assert len(errs) > 200, len(errs)
    assert np.median(errs) < 0.1, np.median(errs)  # (all or nothing: 0.32)


def test_the_subframe_reference_blur_draws_the_pads_material_too():
    """The reference blur (one render per sample time, ``blur_method: subframes``) left out the
    pad's glare and wrinkles: a glossy, wrinkled pad came out matte and flat.  The same glossy
    descent under both blurs: on the pad they agree, where the glare is tens of levels."""
    base = _pad_close_up("sub", [70.0, 70.0], 3.0)
    base["degradations"].update(motion_blur=True)
    base["camera"]["exposure_s"] = 0.01
    mat = {"gloss": [0.5, 0.5], "gloss_roughness": [0.3, 0.3], "relief_m": [0.01, 0.01]}
    spec = {**base, "pad_material": mat}
    checked = 0
    with SequenceRenderer(_spec(_merge(spec, {"degradations.blur_method": "velocity"})), 0) as fast, \
            SequenceRenderer(_spec(_merge(spec, {"degradations.blur_method": "subframes"})), 0) as ref, \
            SequenceRenderer(_spec(base), 0) as matte:
        for k in range(1, len(fast), 3):
            a, b, m = (r.render(k) for r in (fast, ref, matte))
            quad = fast.camera.project_from(fast.cam2pad(k), fast.pad.outer_corners_P).astype(np.float32)
            pad = np.zeros(a.rgb.shape[:2], np.uint8)
            cv2.fillConvexPoly(pad, np.round(quad).astype(np.int32), 1)
            pad = cv2.erode(pad, np.ones((7, 7), np.uint8)) > 0
            if pad.sum() < 500:
                continue
            glare = np.abs(a.rgb.astype(float) - m.rgb.astype(float))[pad].mean()
            if glare < 10.0:
                continue
            assert np.abs(a.rgb.astype(float) - b.rgb.astype(float))[pad].mean() < 0.2 * glare
            checked += 1
    assert checked >= 2, checked


def test_arms_and_spinning_propellers_are_drawn_where_the_camera_sees_them():
    """``airframe.arms``: motor arms and a spinning propeller over each.  Rigid with the camera, a
    propeller is a translucent disc over whatever lies behind it (not smeared by the exposure):
    there the light is (1 - prop_alpha) of the scene's plus the blades' own; an arm in front of a
    disc is not darkened by it; the airframe mask covers both; the labels do not change.  A
    camera under the body looking down does not see arms and propellers above it."""
    base = {"name": "arms", "seed": 3, "sequences": 1,
            "camera": {"width": 160, "height": 120, "fps": 4, "hfov_deg": 90,
                       "mount": {"rpy_deg": [180.0, 60.0, -90.0], "xyz_m": [0.0, 0.0, -0.06]}},
            "airframe": {"arms": 4, "arm_azimuth_deg": 0.0, "arm_z_m": -0.1, "prop_z_m": -0.06, "prop_alpha": 0.35},
            "trajectory": {"families": ["straight"], "start_height_m": 4.0, "duration_s": [3.0, 3.0]},
            "degradations": {"shot_noise": [0.0, 0.0], "read_noise": [0.0, 0.0], "motion_blur": False}}
    bare = _merge(base, {"airframe.prop_alpha": 0.0})
    with SequenceRenderer(_spec(base), 0) as r, SequenceRenderer(_spec(bare), 0) as b:
        assert r.prop_alpha is not None and b.prop_alpha is None
        disc = r.prop_alpha > 0.3  # inside a disc, off its anti-aliased rim
        for k in (1, 4, 8):
            a, c = r.render(k), b.render(k)
            assert a.labels.keys() == c.labels.keys()
            assert all(x == c.labels[n] or (x != x and c.labels[n] != c.labels[n]) for n, x in a.labels.items())  # NaN: unseen
            behind = disc & (c.depth_m > r.prop_depth)  # the disc in front of what the pixel sees
            arm = disc & (c.depth_m < r.prop_depth)  # an arm in front of the disc
            assert behind.sum() > 50 and arm.sum() > 5, (behind.sum(), arm.sum())
            # back through the camera's own tone curve to its linear light (exposure gain included)
            la, lc = ((x.rgb.astype(np.float64) / 255.0) ** (1.0 / r.imaging.tone_exponent) for x in (a, c))
            expect = (1 - r.prop_alpha[..., None]) * lc + r.prop_alpha[..., None] * r.imaging.gain * r.prop_linear
            assert np.median(np.abs(la - expect)[behind]) < 0.01, np.median(np.abs(la - expect)[behind])
            assert np.median(np.abs(la - lc)[arm]) < 0.01
            bright = behind[..., None] & (lc > 0.1)
            assert bright.sum() > 50 and (la[bright] < lc[bright]).mean() > 0.95  # the blades take light
        assert a.airframe_mask[behind | arm].all() and not c.airframe_mask[behind].any()
    nadir = _merge(base, {"camera.mount.rpy_deg": [180.0, 0.0, -90.0], "airframe.arm_z_m": 0.0, "airframe.prop_z_m": 0.03,
                          "trajectory.lateral_offset_m": [0.0, 1.0]})
    with SequenceRenderer(_spec(nadir), 0) as r:
        assert r.prop_alpha is None and not r.airframe_mask.any()


def test_glare_on_a_wrinkled_pad_follows_its_facets():
    """The sun's glare was computed for the ideal plane's normal, so a wrinkled glossy pad shone as
    a flat one.  It now follows each facet's normal: the glare a glossy finish adds on a wrinkled
    pad tracks the Blinn-Phong lobe of the facets' normals, not the plane's."""
    base = _pad_close_up("glint", [70.0, 70.0], 3.0)
    mat = {"relief_m": [0.02, 0.02], "relief_wavelength_m": [0.2, 0.2]}
    shiny = {**mat, "gloss": [0.6, 0.6], "gloss_roughness": [0.2, 0.2]}
    lead = []
    with SequenceRenderer(_spec({**base, "pad_material": mat}), 0) as matte_r, \
            SequenceRenderer(_spec({**base, "pad_material": shiny}), 0) as gloss_r:
        relief = gloss_r.material["relief"]
        sun = gloss_r.plan.scene_draw.sun_dir_W
        g = np.linspace(-0.3, 0.3, 31)
        P = np.column_stack([np.repeat(g, len(g)), np.tile(g, len(g)), np.zeros(len(g) ** 2)])
        for k in (2, 6, 10):
            T = gloss_r.cam2pad(k)
            lin = [((r.render(k).rgb.astype(float) / 255.0) ** 2.2).mean(axis=2) for r in (matte_r, gloss_r)]
            px = np.round(gloss_r.camera.project_from(T, relief.on_surface(P))).astype(int)
            ok = np.all((px >= 3) & (px < 237), axis=1)
            added = (lin[1] - lin[0])[px[ok, 1], px[ok, 0]]
            view = T[:3, 3] - P[ok]
            half = view / np.linalg.norm(view, axis=1, keepdims=True) + sun
            half /= np.linalg.norm(half, axis=1, keepdims=True)
            lobe = {name: np.clip(np.sum(half * n, axis=1), 0, 1) ** (2 / 0.2**2 - 2)
                    for name, n in (("facets", relief.normal(P[ok, :2])), ("plane", np.array([0.0, 0.0, 1.0])))}
            if lobe["facets"].std() < 0.05:
                continue  # no glint in view
            r_facets = np.corrcoef(added, lobe["facets"])[0, 1]
            r_plane = np.corrcoef(added, lobe["plane"])[0, 1]
            assert r_facets > 0.5 and r_facets > r_plane, (k, r_facets, r_plane)
            lead.append(r_facets - r_plane)
    assert len(lead) >= 2 and np.mean(lead) > 0.15, lead  # (near the pad both lobes vary with the view)


def test_a_wrinkled_pad_is_drawn_on_its_surface_and_labelled_on_its_plane():
    """``pad_material.relief_m``: the printed pad's wrinkles and sag.  The depth the renderer draws
    lies on the relief (not on the plane), the sun shades its facets, the labels stay those of the
    flat pad's ideal plane, and meta's ``pad_relief`` says how far the features' images moved."""
    base = _pad_close_up("wrinkled", [30.0, 35.0], 3.0)
    with SequenceRenderer(_spec(base), 0) as flat, \
            SequenceRenderer(_spec({**base, "pad_material": {"relief_m": [0.02, 0.02]}}), 0) as wrinkled:
        relief = wrinkled.material["relief"]
        moved = []
        for k in (4, 10, 14):
            a, b = flat.render(k), wrinkled.render(k)
            assert a.labels.keys() == b.labels.keys()
            for c, v in a.labels.items():
                assert v == b.labels[c] or (v != v and b.labels[c] != b.labels[c]), c  # NaN == NaN
            for r, expect_relief in ((flat, False), (wrinkled, True)):
                cam2pad = r.cam2pad(k)
                _, z = r.scene.render_with_depth(r.pad2world[k] @ cam2pad)
                rows, cols, P, on = r._pad_pixels(r.imaging.depth_to_pixels(z), cam2pad)
                Q = P[on].astype(np.float64)
                want = relief.height(Q[:, :2]) if expect_relief else 0.0
                assert np.median(np.abs(Q[:, 2] - want)) < 1e-3, (k, expect_relief)
            assert Q[:, 2].max() > 0.6 * relief.amplitude_m
            diff = np.abs(a.rgb.astype(float) - b.rgb)[rows, cols][on]
            assert diff.mean() > 2.0, (k, diff.mean())  # shading and parallax are drawn
            # the features' images on the surface against the labels (an independent projection)
            pts = wrinkled.pad.geometry.outer_corners
            lifted = pts + np.column_stack([np.zeros((4, 2)), relief.height(pts[:, :2])])
            on_plane, on_relief = (wrinkled.camera.project_from(wrinkled.cam2pad(k), p) for p in (pts, lifted))
            seen = wrinkled.camera.in_image(on_plane) & wrinkled.camera.in_image(on_relief)
            moved.append(np.linalg.norm(on_relief - on_plane, axis=1)[seen].max() if seen.any() else 0.0)
        rep = wrinkled.relief_report()
        assert flat.relief_report() is None
        assert rep["labels"].startswith("the pad's ideal plane") and rep["amplitude_m"] == 0.02
        assert 0.3 < max(moved) <= rep["label_offset_px"]["max"] + 1e-9, (moved, rep["label_offset_px"])
    with pytest.raises(ValueError, match="pad_material.relief_m"):
        _spec({**base, "pad_material": {"relief_m": [0.0, 0.3]}})


def test_sun_visibility_is_read_at_any_number_of_pad_points():
    """A pad on the ground near the camera covers more than 32,767 pixels, and reading the boxes'
    ground shadows at all of them at once broke cv2.remap's size limit (a 1280x720 descent onto a
    wrinkled pad on the ground crashed the renderer at touchdown).  Many points read as few do."""
    spec = _spec({**_pad_close_up("on_ground", [20.0, 24.0], 3.0), "platform": {"height_m": 0.0},
                  "environment": {"sun_elevation_deg": [20.0, 24.0], "ground": ["sand"],
                                  "distractors": {"boxes": [3, 3], "keep_clear_m": 1.0}}})
    with SequenceRenderer(spec, 0) as r:
        assert r.scene._ground_shadow_maps, "the scene should have box shadows on the ground"
        rng = np.random.default_rng(3)
        xy = rng.uniform(-6.0, 6.0, (50_000, 2))
        many = r.scene.pad_sun_visibility(xy)
        few = np.concatenate([r.scene.pad_sun_visibility(xy[k:k + 5000]) for k in range(0, len(xy), 5000)])
        assert many.shape == (50_000,) and np.array_equal(many, few)
        assert 0.0 < np.mean(many < 1.0) < 1.0  # some in shadow, some lit


def test_blur_px_is_the_motion_of_the_pad_in_view_whatever_the_lens():
    """``blur_px`` is the largest image motion over the exposure of the pad's points in view, through
    the lens.  Read on the corners through an ideal pinhole, a fisheye pitched 25 degrees at 0.3 m
    above a 1.5 m pad (a far corner near the camera's plane) labelled 10^3-10^5 px where the pad in
    view moved some tens (unseen49).  Now the label agrees with the motion of a dense grid of the
    pad's points in view within a few per cent, the far corner's motion left out; a nadir pinhole
    view with the whole pad in it reads its corners' motion as before."""
    from hvloc.geometry import Camera, invert, so3_exp
    from render.phase import pad_image_motion_px

    def dense_motion(cam, A, B, half, n=201):
        g = np.linspace(-half, half, n)
        gx, gy = np.meshgrid(g, g)
        P = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
        a, b = cam.project_from(A, P), cam.project_from(B, P)
        ok = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1) & cam.in_image(a) & cam.in_image(b)
        return float(np.linalg.norm(b[ok] - a[ok], axis=1).max())

    fish = Camera(640, 480, 333.0, 333.0, 319.5, 239.5, (0.02, -0.005, 0.001, 0.0), "fisheye")
    R = np.diag([1.0, -1.0, -1.0]) @ so3_exp([np.radians(25.0), 0.0, 0.0])  # looking down, pitched 25 degrees
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, [0.2, -0.4, 0.3]
    v = np.array([0.3, 0.9, -0.4])  # m/s, over a 30 ms exposure
    A, B = T.copy(), T.copy()
    A[:3, 3] -= v * 0.015
    B[:3, 3] += v * 0.015
    half = 0.75
    corners = np.array([[-half, half, 0], [half, half, 0], [half, -half, 0], [-half, -half, 0]])
    pin = fish.without_distortion()
    old = np.nanmax(np.linalg.norm(pin.project_from(B, corners) - pin.project_from(A, corners), axis=1))
    assert not fish.in_image(fish.project_from(T, corners)).all()  # some corner out of view
    got, ref = pad_image_motion_px(fish, A, B, half, (T,)), dense_motion(fish, A, B, half)
    assert old > 10 * ref and 0.9 * ref <= got <= ref * 1.001, (old, got, ref)

    nadir = Camera.from_hfov(640, 480, math.radians(60))
    N = np.eye(4)
    N[:3, :3], N[:3, 3] = np.diag([1.0, -1.0, -1.0]) @ so3_exp([0.0, 0.0, 0.3]), [0.1, 0.0, 4.0]
    w = so3_exp([0.0, 0.0, 0.6 * 0.03])  # turning about the optical axis: the corners move most
    A, B = N.copy(), N.copy()
    B[:3, :3] = N[:3, :3] @ w
    d = np.linalg.norm(nadir.project_from(B, corners) - nadir.project_from(A, corners), axis=1)
    assert abs(pad_image_motion_px(nadir, A, B, half, (N,)) - d.max()) < 1e-9
    away = N.copy()
    away[:3, 3] = [30.0, 0.0, 4.0]  # the pad out of view: no motion to read
    assert math.isnan(pad_image_motion_px(nadir, away, away, half, (away,)))


def test_a_dataset_rendered_without_motion_blur_says_its_frames_are_instants(tmp_path):
    """``degradations.motion_blur: false`` renders each frame as an instant.  camera.json had kept the
    spec's exposure_s and frames.csv the motion over it (blur_px), so a localizer that read them
    predicted smear on sharp frames (fzu11: a 20 ms exposure, nothing smeared; its texture drawn
    smeared 5-6.5 px and posed 1.5-7 % of the height off, "ok").  The dataset now says what its
    frames show: exposure 0 and no blur; with blur rendered, the spec's exposure and the motion."""
    d = {"name": "instants", "seed": 3, "sequences": 1, "pad_ppm": 200,
         "camera": {"width": 96, "height": 96, "hfov_deg": 70, "fps": 2, "exposure_s": 0.03},
         "environment": {"distractors": {"boxes": [0, 0]}},
         "trajectory": {"families": ["straight"], "start_height_m": 6.0, "duration_s": [3, 3],
                        "touchdown_height_m": 1.0, "lateral_offset_m": [0.3, 0.3]}}
    said = {}
    for blur in (True, False):
        generate(_spec(_merge(d, {"degradations.motion_blur": blur})), tmp_path / str(blur), show_progress=False)
        assert verify_dataset(tmp_path / str(blur)) == []
        seq = Dataset(tmp_path / str(blur))[0]
        said[blur] = (seq.exposure_s, float(np.nanmax(seq.columns["blur_px"])))
    assert said[True][0] == 0.03 and said[True][1] > 0.3, said  # (a descent of 5 m in 3 s moves the pad)
    assert said[False] == (0.0, 0.0), said


# ----------------------------------------------------------------------------- a ship's deck

def _deck_spec(**over) -> DatasetSpec:
    d = {"name": "deck", "seed": 5, "sequences": 1, "pad_ppm": 500,
         "camera": {"width": 240, "height": 240, "hfov_deg": 60, "fps": 3, "exposure_s": 0.004},
         "platform": {"height_m": 1.5, "size_m": 1.4, "roll_deg": 10.0, "pitch_deg": 6.0, "heave_m": 0.4,
                      "yaw_deg": 4.0, "roll_period_s": 7.0, "pitch_period_s": 5.0, "heave_period_s": 6.0,
                      "yaw_period_s": 9.0},
         "environment": {"distractors": {"boxes": [0, 0]}},
         "trajectory": {"families": ["straight"], "start_height_m": 5.0, "duration_s": [10, 10],
                        "touchdown_height_m": 0.3, "lateral_offset_m": [0.0, 0.5]}}
    return _spec(_merge(d, over))


def test_a_rolling_pitching_yawing_heaving_deck_is_rendered_and_labelled_where_it_is(tmp_path):
    """A ship's deck: the pad's world pose rolls, pitches, yaws and heaves as the spec says (each a
    sinusoid of its period), the descent follows the heave but not the tilt, frames.csv's pad
    velocity is the heave's rate, and the image shows the pad where T_P_C says (verify's image
    check, and the cells of the pad at every near frame)."""
    from hvloc.geometry import transform_from_tum
    from render.scene import PAD_THICKNESS_M

    spec = _deck_spec()
    generate(spec, tmp_path / "ds", show_progress=False)
    assert verify_dataset(tmp_path / "ds") == []
    seq = Dataset(tmp_path / "ds")[0]
    c = seq.columns
    t = np.asarray(c["t"])
    T_W_P = [transform_from_tum([c[f"pad2world_{q}"][k] for q in ("tx", "ty", "tz", "qx", "qy", "qz", "qw")])
             for k in range(len(seq))]
    # roll about the pad's x, pitch about its y, yaw about its normal: R = R_z(yaw) R_y(pitch) R_x(roll)
    roll = np.degrees([math.atan2(T[2, 1], T[2, 2]) for T in T_W_P])
    pitch = np.degrees([math.asin(-T[2, 0]) for T in T_W_P])
    yaw = np.degrees([math.atan2(T[1, 0], T[0, 0]) for T in T_W_P])
    heave = np.array([T[2, 3] for T in T_W_P]) - (1.5 + PAD_THICKNESS_M)
    for series, amp, period in ((roll, 10.0, 7.0), (pitch, 6.0, 5.0), (yaw, 4.0, 9.0), (heave, 0.4, 6.0)):
        # a sinusoid of that amplitude and period: a least-squares fit of sin and cos explains it exactly
        w = 2 * np.pi / period
        A = np.column_stack([np.sin(w * t), np.cos(w * t)])
        ab = np.linalg.lstsq(A, series, rcond=None)[0]
        assert np.abs(series - A @ ab).max() < 1e-6 * max(amp, 1.0)
        assert abs(np.hypot(*ab) - amp) < 1e-6 * max(amp, 1.0), (np.hypot(*ab), amp)
    np.testing.assert_allclose(c["pad_vel_z"], w * (ab[0] * np.cos(w * t) - ab[1] * np.sin(w * t)), atol=1e-6)
    # the descent follows the heave: the camera's height above the pad's centre is the planned one,
    # smooth, and ends at the touchdown height
    h = np.array([seq.frame(k).cam2pad[2, 3] for k in range(len(seq))])
    body_z = np.array([c["body2world_tz"][k] for k in range(len(seq))])
    assert np.corrcoef(np.diff(body_z), np.diff(heave))[0, 1] > 0.3  # the body rises and falls with the deck
    assert abs(h[-1] - 0.3) < 0.06 and np.all(np.diff(h) < 0.05)
    # the tilt is not followed: the camera sees the pad tilted as the deck is
    tilt_seen = [math.degrees(math.acos(np.clip(seq.frame(k).cam2pad[2, 2] * -1, -1, 1))) for k in range(len(seq))]
    assert max(tilt_seen) > 6.0
    for k in range(len(seq)):
        np.testing.assert_allclose(invert(T_W_P[k]) @ transform_from_tum(
            [c[f"body2world_{q}"][k] for q in ("tx", "ty", "tz", "qx", "qy", "qz", "qw")]) @ seq.T_B_C,
            seq.frame(k).cam2pad, atol=1e-9)
    checked = 0
    with SequenceRenderer(spec, 0) as r:
        for k in range(len(r)):
            T = r.cam2pad(k)
            if not 1.0 < T[2, 3] < 3.0:
                continue
            layers = r.render(k)
            matched, cells, required = check_image(r.camera, r.pad, T, layers.rgb, layers.labels["pad_visible_fraction"])
            assert matched >= required and cells >= 8, (k, matched, cells, required)
            checked += 1
    assert checked >= 3


def test_a_tilted_deck_is_lit_as_it_faces_the_sun():
    """The renders are flat-shaded and lit as a level surface is; a deck rolled toward the sun gets
    more of it and one rolled away less, by ambient + direct * (n . sun) over a level surface's.
    Seen from a camera rigid with the pad (the same image of it), tilted and level: the pad's
    linear light differs by that factor, and the drone's shadow lies where its square falls along
    the sun onto the deck's plane."""
    from render.imaging import SRGB_GAMMA

    spec = _deck_spec(**{"environment.sun_elevation_deg": [55.0, 55.0], "environment.shadows": False,
                         "degradations.shot_noise": [0.0, 0.0], "degradations.read_noise": [0.0, 0.0],
                         "degradations.motion_blur": False, "camera.vignetting": [0.0, 0.0]})
    with SequenceRenderer(spec, 0) as r:
        e = SRGB_GAMMA * r.plan.imaging.gamma
        draw = r.plan.scene_draw
        sun = draw.sun_dir_W
        k = int(np.argmin([abs(r.cam2pad(i)[2, 3] - 1.5) for i in range(len(r))]))
        level = make_transform(np.eye(3), r.pad2world[k][:3, 3])
        B = r.body2world[k]
        # roll about the axis across the sun: toward it (+) and away (-)
        axis = np.cross([0.0, 0.0, 1.0], [sun[0], sun[1], 0.0])
        axis /= np.linalg.norm(axis)
        ratios = []
        for sign in (1.0, -1.0):
            Rt = so3_exp(axis * math.radians(12.0) * sign)
            tilted = level @ make_transform(level[:3, :3].T @ Rt, (0.0, 0.0, 0.0))
            B_t = tilted @ invert(level) @ B  # the camera rigid with the pad
            a = r.render_at(k, float(r.times[k]), B, level)
            b = r.render_at(k, float(r.times[k]), B_t, tilted)
            np.testing.assert_allclose(invert(tilted) @ B_t, invert(level) @ B, atol=1e-12)
            px = r.camera.project_from(invert(level) @ B @ r.T_B_C, r.pad.outer_corners_P * 0.8)
            mask = np.zeros(a.rgb.shape[:2], np.uint8)
            cv2.fillConvexPoly(mask, np.round(px).astype(np.int32), 1)
            la = (a.rgb.astype(np.float64) / 255.0) ** e
            lb = (b.rgb.astype(np.float64) / 255.0) ** e
            ok = (mask > 0)[..., None] & (a.rgb > 20) & (a.rgb < 235) & (b.rgb < 250)
            ratios.append(float(np.median(lb[ok] / la[ok])))
            n = Rt[:, 2]
            horizontal = draw.ambient + draw.sun_intensity * max(sun[2], 0.0)
            want = (draw.ambient + draw.sun_intensity * max(n @ sun, 0.0)) / horizontal
            assert abs(ratios[-1] - want) < 0.02, (sign, ratios[-1], want)
        assert ratios[0] > 1.03 and ratios[1] < 0.97, ratios


@pytest.mark.parametrize("motion", [{}, {"platform.roll_deg": 0.0, "platform.pitch_deg": 0.0}],
                         ids=["rolling_heaving", "heaving_only"])
def test_the_drones_shadow_lies_in_a_moving_decks_plane(motion):
    """With shadows on, the drone's shadow on a rolling or heaving deck darkens the pad where the
    drone's square, cast from the body along the sun, meets the deck's plane where it is now: the
    pixels it darkens (against the same frame without shadows) are the projection of that square.
    (On a deck that only heaved, the square was laid at the deck's mean height.)"""
    over = {"environment.sun_elevation_deg": [75.0, 75.0], "degradations.shot_noise": [0.0, 0.0],
            "degradations.read_noise": [0.0, 0.0], "degradations.motion_blur": False, **motion}
    lit, shaded = _deck_spec(**over, **{"environment.shadows": False}), _deck_spec(**over)
    checked = 0
    with SequenceRenderer(lit, 0) as a, SequenceRenderer(shaded, 0) as b:
        sun, half = b.plan.scene_draw.sun_dir_W, b.scene.drone_size / 2
        for k in range(len(b)):
            T = b.cam2pad(k)
            if not 0.8 < T[2, 3] < 2.5:
                continue
            P = invert(b.pad2world[k])
            body = P @ b.body2world[k]
            s_P = P[:3, :3] @ sun
            centre = body[:3, 3][:2] - s_P[:2] * body[2, 3] / s_P[2]
            if np.abs(centre).max() > 0.5:  # the square well on the pad's 1.4 m platform
                continue
            yaw = math.atan2(body[1, 0], body[0, 0])
            sq = np.array([[-half, -half], [half, -half], [half, half], [-half, half]]) @ rotation_z(yaw)[:2, :2].T + centre
            corners = np.column_stack([sq, np.zeros(4)])
            px = b.camera.project_from(T, corners)
            want = np.zeros((b.camera.height, b.camera.width), np.uint8)
            cv2.fillConvexPoly(want, np.round(px * 16).astype(np.int32), 1, cv2.LINE_AA, shift=4)
            onpad = np.zeros_like(want)
            cv2.fillConvexPoly(onpad, np.round(b.camera.project_from(T, b.pad.outer_corners_P) * 16).astype(np.int32),
                               1, shift=4)
            ra, rb = a.render(k).rgb.astype(float), b.render(k).rgb.astype(float)
            dark = (rb.sum(axis=2) < 0.8 * ra.sum(axis=2)) & (ra.sum(axis=2) > 60)
            region = (onpad > 0) & (ra.sum(axis=2) > 60)
            w = (want > 0) & region
            got = dark & region
            if w.sum() < 200:
                continue
            iou = (w & got).sum() / (w | got).sum()
            assert iou > 0.9, (k, iou, w.sum(), got.sum())
            checked += 1
    assert checked >= 2, checked


def _surface_points_W(cam, cam2world: np.ndarray, z: np.ndarray) -> np.ndarray:
    """``(H * W, 3)``: the world points a render shows at each pixel, from its depth ``z`` (H, W)."""
    v, u = np.mgrid[0:cam.height, 0:cam.width]
    return transform_points(cam2world, cam.unproject(np.column_stack([u.ravel(), v.ravel()]).astype(np.float64),
                                                     z.reshape(-1).astype(np.float64)))


@pytest.mark.parametrize("deck", [False, True], ids=["level", "rolling"])
def test_the_drones_shadow_falls_past_a_platforms_edge_to_the_ground(deck):
    """A low sun casts the drone's square shadow across a platform's edge: the part that meets the
    platform's top lies there (in the deck's plane, on a rolling deck), the rest falls past the edge
    to the ground, further along the sun, outside the platform's own shadow.  The pixels it darkens
    (against the drone far away) are the surface points, from the rendered depth, whose ray to the
    sun meets the drone's square.  (The whole square used to be laid on the top when its centre fell
    there, hanging in the air past the edge, and on the ground when the centre fell beyond.)"""
    over = {"environment.sun_elevation_deg": [45.0, 45.0], "degradations.shot_noise": [0.0, 0.0],
            "degradations.read_noise": [0.0, 0.0], "degradations.motion_blur": False,
            "camera.width": 480, "camera.height": 480, "camera.hfov_deg": 100.0}
    if not deck:
        over.update({"platform.roll_deg": 0.0, "platform.pitch_deg": 0.0, "platform.yaw_deg": 0.0,
                     "platform.heave_m": 0.0})
    with SequenceRenderer(_deck_spec(**over), 0) as r, \
            SequenceRenderer(_deck_spec(**over, **{"environment.shadows": False}), 0) as r_lit:
        sc, cam = r.scene, r.scene.camera
        sun, half, edge = r.plan.scene_draw.sun_dir_W, sc.drone_size / 2, sc.platform_size / 2
        T_W_P = r.pad2world[0]
        sc.set_platform(T_W_P)
        r_lit.scene.set_platform(T_W_P)
        away = make_transform(np.eye(3), (200.0, 200.0, 10.0))
        sun_P = T_W_P[:3, :3].T @ sun
        u = -sun_P[:2] / np.linalg.norm(sun_P[:2])  # the way shadows fall, in the pad's frame
        checked, parts = [], []  # IoU; pixels of the shadow on the top and on the ground
        for along in (edge - 0.1, edge + 0.1):  # the square's centre on the top's plane, inside and past the edge
            centre_P = along * u / np.abs(u).max()  # (the top's edge lies at the square's max norm)
            body_P = np.array([*centre_P, 0.0]) + sun_P / sun_P[2]
            body = make_transform(np.eye(3), T_W_P[:3, :3] @ body_P + T_W_P[:3, 3])
            look = make_transform(np.diag([1.0, -1.0, -1.0]), (*(T_W_P[:2, 3] - sun[:2] / np.linalg.norm(sun[:2]) * (edge + 0.6)),
                                                               T_W_P[2, 3] + 2.5))
            sc.set_drone(away)
            ref = display_bytes(sc.render_with_depth(look)[0])  # (thresholds in display values)
            unshaded = display_bytes(r_lit.scene.render(look)).astype(float).sum(axis=2).reshape(-1)
            sc.set_drone(body)
            img, z = sc.render_with_depth(look)
            img = display_bytes(img)
            q = _surface_points_W(cam, look, z)
            q_P = (T_W_P[:3, :3].T @ (q - T_W_P[:3, 3]).T).T
            up = (np.abs(q[:, 2]) < 0.02) | ((np.abs(q_P[:, 2]) < 0.03) & (np.abs(q_P[:, :2]).max(axis=1) < edge))
            t = (body[2, 3] - q[:, 2]) / sun[2]  # along the sun, to the body's height
            hit = np.abs(q[:, :2] + sun[:2] * t[:, None] - body[:2, 3]).max(axis=1) <= half
            # unless the platform stands in the way (its box: the top's square, down to the ground)
            k = np.flatnonzero(hit)
            x_P = (q_P[k, None, :] + sun_P * (t[k, None, None] * np.linspace(0.0, 1.0, 48)[None, :, None]))
            inside = (np.abs(x_P[..., :2]).max(axis=2) < edge - 1e-3) & (x_P[..., 2] < -0.005)
            hit[k[inside.any(axis=1)]] = False
            # lit, and in no other shadow (the platform's own on the ground: the sun does not reach there)
            lit = (ref.astype(float).sum(axis=2).reshape(-1) > 60) & (ref.astype(float).sum(axis=2).reshape(-1)
                                                                     > 0.9 * unshaded)
            dark = img.astype(float).sum(axis=2).reshape(-1) < 0.8 * ref.astype(float).sum(axis=2).reshape(-1)
            region = up & lit & np.isfinite(z).reshape(-1)
            want, got = hit & region, dark & region
            on_top = want & (np.abs(q_P[:, 2]) < 0.03)
            parts.append((int(on_top.sum()), int((want & ~on_top).sum())))
            iou = (want & got).sum() / (want | got).sum()
            checked.append(round(float(iou), 3))
        assert min(p[0] for p in parts) > 300 and max(p[1] for p in parts) > 100, parts
        assert min(checked) > 0.9, checked


def test_a_turning_decks_platform_casts_its_shadow_as_it_stands():
    """A deck rolled, pitched and yawed: the platform's shadow on the ground is its box as it stands
    (its top's corners, and its sides down to the ground) cast along the sun.  The ground pixels
    it darkens (against a render without shadows) are the ground points, from the rendered depth,
    whose ray to the sun meets the box.  (It was a level box's, turned with nothing.)"""
    over = {"environment.sun_elevation_deg": [40.0, 40.0], "degradations.shot_noise": [0.0, 0.0],
            "degradations.read_noise": [0.0, 0.0], "degradations.motion_blur": False,
            "camera.width": 480, "camera.height": 480, "camera.hfov_deg": 100.0}
    ious = []
    with SequenceRenderer(_deck_spec(**over), 0) as r, \
            SequenceRenderer(_deck_spec(**over, **{"environment.shadows": False}), 0) as r_lit:
        sc, cam, sun = r.scene, r.scene.camera, r.plan.scene_draw.sun_dir_W
        edge = sc.platform_size / 2
        for rpy in ((12.0, 0.0, 0.0), (-6.0, 9.0, 25.0)):
            T_W_P = make_transform(so3_exp(np.radians([0.0, 0.0, rpy[2]])) @ so3_exp(np.radians([0.0, rpy[1], 0.0]))
                                   @ so3_exp(np.radians([rpy[0], 0.0, 0.0])), (0.3, -0.2, sc.pad_surface_z))
            for s in (sc, r_lit.scene):
                s.set_platform(T_W_P)
                s.set_drone(make_transform(np.eye(3), (200.0, 200.0, 10.0)))
            look = make_transform(np.diag([1.0, -1.0, -1.0]), (*(T_W_P[:2, 3] - sun[:2] / np.linalg.norm(sun[:2])),
                                                               T_W_P[2, 3] + 3.5))
            img, z = sc.render_with_depth(look)
            img = display_bytes(img)  # (thresholds in display values)
            unshaded = display_bytes(r_lit.scene.render(look)).astype(float).sum(axis=2).reshape(-1)
            q = _surface_points_W(cam, look, z)
            ground = (np.abs(q[:, 2]) < 0.02) & np.isfinite(z).reshape(-1) & (unshaded > 60)
            k = np.flatnonzero(ground)
            t = np.linspace(0.0, (T_W_P[2, 3] + 0.5) / sun[2], 96)
            x = q[k, None, :] + sun * t[None, :, None]
            x_P = (x - T_W_P[:3, 3]) @ T_W_P[:3, :3]
            want = np.zeros(len(q), bool)
            want[k] = ((np.abs(x_P[..., :2]).max(axis=2) < edge) & (x_P[..., 2] < -0.005)).any(axis=1)
            got = ground & (img.astype(float).sum(axis=2).reshape(-1) < 0.8 * unshaded)
            assert want.sum() > 2000, want.sum()
            ious.append(round(float((want & got).sum() / (want | got).sum()), 3))
    assert min(ious) > 0.95, ious


def test_a_deck_that_would_reach_the_ground_or_the_camera_is_refused():
    from pad_design.errors import InputError, validate_model

    with pytest.raises(InputError, match="raise platform.height_m"):
        validate_model(DatasetSpec, {"platform": {"height_m": 0.0, "heave_m": 0.3}})
    with pytest.raises(InputError, match="raise platform.height_m"):
        validate_model(DatasetSpec, {"platform": {"height_m": 0.3, "size_m": 2.0, "roll_deg": 15.0, "pitch_deg": 10.0}})
    # a deck that only yaws drops nothing: the message says what it needs (it said "0.00 m down, into the ground")
    with pytest.raises(InputError, match=r"yaw 5.0 deg\).* raise platform.height_m from 0.0 to more than 0.02 m, or keep"):
        validate_model(DatasetSpec, {"platform": {"height_m": 0.0, "yaw_deg": 5.0}})
    validate_model(DatasetSpec, {"platform": {"height_m": 0.03, "yaw_deg": 5.0}})
    with pytest.raises(InputError, match="touchdown_height_m"):
        validate_model(DatasetSpec, {"platform": {"height_m": 1.0, "roll_deg": 15.0},
                                     "trajectory": {"touchdown_height_m": 0.1, "final_offset_m": [0.0, 0.3]}})
    validate_model(DatasetSpec, {"platform": {"height_m": 1.0, "roll_deg": 5.0, "heave_m": 0.2}})
