"""The renderer's labels agree with its images; datasets are deterministic, resumable, verified."""
import hashlib
import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from hvloc.features import refine_quad
from hvloc.geometry import invert, rotation_angle, so3_exp, transform_points
from render.dataset import Dataset, read_tum, verify_dataset
from render.generate import generate, plan_sequence
from render.spec import DatasetSpec, load_dataset_spec
from tests.conftest import assert_input_error, run_cli

SPECS = Path(__file__).parent / "specs"
REPO = Path(__file__).parent.parent


def spec_from(path, **over):
    d = yaml.safe_load(Path(path).read_text())
    for k, v in over.items():
        cur = d
        keys = k.split(".")
        for kk in keys[:-1]:
            cur = cur.setdefault(kk, {})
        cur[keys[-1]] = v
    return DatasetSpec.model_validate(d)


@pytest.fixture(scope="module")
def sharp_datasets(tmp_path_factory):
    root = tmp_path_factory.mktemp("sharp")
    plain = spec_from(SPECS / "sharp.yaml")
    dist = spec_from(SPECS / "sharp.yaml", **{"camera.dist": [-0.22, 0.06, 0.001, -0.0007, -0.005], "name": "sharpdist",
                                              "camera.supersample": 2})
    # a fisheye (OpenCV's Kannala-Brandt model) seeing 90 degrees across
    fish = spec_from(SPECS / "sharp.yaml", **{"camera.model": "fisheye", "camera.hfov_deg": 90.0,
                                              "camera.dist": [0.03, -0.012, 0.002, -0.0002], "name": "sharpfish",
                                              "camera.supersample": 2})
    # the whole chain mixed in 8-bit display values (camera.mix_in_light: false, as revisions up to
    # 11 rendered), through the barrel lens, supersampled
    display = spec_from(SPECS / "sharp.yaml", **{"camera.dist": [-0.22, 0.06, 0.001, -0.0007, -0.005],
                                                 "name": "sharpdisplay", "camera.supersample": 2,
                                                 "camera.mix_in_light": False})
    out = {}
    for s in (plain, dist, fish, display):
        generate(s, root / s.name, show_progress=False)
        out[s.name] = Dataset(root / s.name)
    return out


def _corner_errors(seq, light: bool = False):
    """Errors (px) of refined corners against projected labels: marker squares where their
    modules are >= 4 px, the pad outline where it is fully in view.  ``light``: edges found in
    linear light (a frame whose pixels summed light has its 50 % crossings there, not in the
    display values)."""
    from hvloc.features import srgb_to_linear

    as_fitted = srgb_to_linear if light else (lambda v: v)
    cam = seq.camera
    pad = seq.pad
    errs = {"markers": [], "outline": []}
    for k in range(len(seq)):
        f = seq.frame(k)
        pad2cam = invert(f.cam2pad)
        rgb = f.rgb
        rng = np.random.default_rng(k)
        jobs = []
        if f.markers_visible == 3:
            gray = as_fitted(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)).astype(np.float32)
            sq = [s.corners for m in pad.markers("corner") for s in m.squares]
            module = min(np.linalg.norm(np.diff(cam.project(transform_points(pad2cam, q)), axis=0), axis=1).min()
                         for q in sq[::3]) / 7
            if module >= 4:
                jobs += [("markers", q, gray, min(3.0, 0.45 * module)) for q in sq]
        if f.pad_fully_visible:
            # magenta against the grey platform: the green channel has the contrast
            jobs.append(("outline", pad.outer_corners_P, as_fitted(rgb[..., 1]).astype(np.float32), 2.0))
        for kind, P, img, hw in jobs:
            truth = cam.project(transform_points(pad2cam, P))
            found, _ = refine_quad(img, truth + rng.uniform(-0.7, 0.7, truth.shape), half_width=hw, camera=cam)
            assert found is not None, f"frame {k}: no {kind} corners found"
            errs[kind] += list(np.linalg.norm(found - truth, axis=1))
    return {k: np.array(v) for k, v in errs.items()}


@pytest.mark.parametrize("name", ["sharp", "sharpdist", "sharpfish", "sharpdisplay"])
def test_projection_consistency(sharp_datasets, name):
    """Corners found in rendered images agree with pad.json projected by the labels.  A frame mixed
    in light (``camera.mix_in_light``, the default) has its edges where the labels say in light: its
    display values put them 0.34-0.55 px off (the dark side's share of a mixed pixel reads darker
    than its share of light), as they do a real camera's frame; and a frame mixed in display values
    (``mix_in_light: false``) has them there, 0.34-0.45 px off in light."""
    seq = sharp_datasets[name][0]
    light = name != "sharpdisplay"
    errs = _corner_errors(seq, light=light)
    for kind, e in errs.items():
        assert len(e) >= 40, f"{name}: only {len(e)} {kind} corners checked"
    e = np.concatenate(list(errs.values()))
    med, worst = float(np.median(e)), float(e.max())
    detail = ", ".join(f"{k}: median {np.median(v):.3f} max {v.max():.3f}" for k, v in errs.items())
    assert med <= 0.1 and worst <= 0.25, f"{name}: {detail} px"
    if name in ("sharp", "sharpdisplay"):  # measured in the other space, the same frames' corners are off
        other = np.concatenate(list(_corner_errors(seq, light=not light).values()))
        assert np.median(other) > 0.2, (name, np.median(other))


@pytest.mark.parametrize("name", ["sharpdist", "sharpfish"])
def test_frames_csv_corners_match_independent_projection(sharp_datasets, name):
    seq = sharp_datasets[name][0]
    info = json.loads((seq.root / "camera.json").read_text())
    assert info["model"] == ("fisheye" if name == "sharpfish" else "pinhole")
    K = np.array([[info["fx"], 0, info["cx"]], [0, info["fy"], info["cy"]], [0, 0, 1]])
    pad_doc = json.loads((seq.root / "pad.json").read_text())
    P = np.asarray(pad_doc["outer_corners"], float)
    gt = read_tum(seq.root / "groundtruth.tum")
    for k in range(len(seq)):
        T = seq.cam2pad[k]
        R_C_P = T[:3, :3].T
        t_C_P = -R_C_P @ T[:3, 3]
        if info["model"] == "fisheye":
            # points moved into the camera here: cv2.fisheye's own rvec conversion errs ~2e-3 px on some poses
            Pc = P @ R_C_P.T + t_C_P
            px, _ = cv2.fisheye.projectPoints(Pc[:, None, :], np.zeros(3), np.zeros(3), K, np.array(info["dist"]))
        else:
            px, _ = cv2.projectPoints(P, cv2.Rodrigues(R_C_P)[0], t_C_P, K, np.array(info["dist"]))
        px = px[:, 0, :]
        inside = (px[:, 0] >= -0.5) & (px[:, 0] <= info["width"] - 0.5) & (px[:, 1] >= -0.5) & (px[:, 1] <= info["height"] - 0.5)
        lab = seq.frame(k).corners_px
        assert np.array_equal(np.isnan(lab).any(axis=1), ~inside)
        np.testing.assert_allclose(lab[inside], px[inside], atol=1e-3)  # cv2.Rodrigues is float-exact to ~1e-7
        np.testing.assert_allclose(gt[k, 1:4], T[:3, 3], atol=1e-9)


def test_dataset_verifies_and_reads_back(sharp_datasets):
    ds = sharp_datasets["sharp"]
    assert verify_dataset(ds.root) == []
    seq = ds[0]
    assert len(seq) == len(list((seq.root / "images").glob("*.png")))
    assert seq.image(0).shape == (480, 480, 3) and seq.image(0).dtype == np.uint8
    assert set(seq.phase_gt) <= {"approaching", "adjustment", "touchdown"}
    # heights decrease from the start to the end, and height_above_pad is tz of T_P_C
    assert seq.columns["tz"][0] > 3.0 and seq.columns["tz"][-1] < 0.7
    from render.dataset import frame_dataset

    fd = frame_dataset(ds.root)
    item = fd[3]
    assert tuple(item["image"].shape) == (3, 480, 480) and item["cam2pad"].shape == (4, 4)


def test_tampering_is_caught(sharp_datasets, tmp_path):
    src = sharp_datasets["sharp"].root
    dst = tmp_path / "copy"
    shutil.copytree(src, dst)
    p = dst / "seq_0000" / "frames.csv"
    text = p.read_text().splitlines()
    text[3] = text[3].replace(",", ",9", 1)
    p.write_text("\n".join(text) + "\n")
    (dst / "seq_0000" / "images" / "000001.png").unlink()
    problems = verify_dataset(dst)
    assert any("frames.csv: checksum" in x for x in problems)
    assert any("000001.png" in x for x in problems)
    r = subprocess.run([sys.executable, "-m", "hvloc.cli", "dataset", "verify", str(dst)], capture_output=True, text=True)
    assert r.returncode == 1 and "problem" in r.stdout


def _tiny(**over):
    return spec_from(REPO / "data_specs" / "tiny.yaml", **{"camera.width": 96, "camera.height": 96,
                                                             "trajectory.start_height_m": 2.5,
                                                             "trajectory.duration_s": [2.0, 2.0],
                                                             "trajectory.lateral_offset_m": [0.0, 0.2],
                                                             "degradations.blur_subframes": 2, **over})


def _dataset_digest(root):
    m = json.loads((Path(root) / "manifest.json").read_text())
    return m["files"]


def test_determinism_and_single_sequence_regeneration(tmp_path):
    spec = _tiny()
    generate(spec, tmp_path / "a", show_progress=False)
    generate(spec, tmp_path / "b", show_progress=False)
    fa, fb = _dataset_digest(tmp_path / "a"), _dataset_digest(tmp_path / "b")
    assert fa == fb and len(fa) > 10
    # sequence 1 alone equals sequence 1 of the full run
    generate(spec, tmp_path / "c", show_progress=False, only=[1])
    fc = _dataset_digest(tmp_path / "c")
    assert {k: v for k, v in fa.items() if k.startswith("seq_0001/") or k == "pad.png"} == fc


def test_resume_after_interruption_equals_uninterrupted(tmp_path):
    spec = _tiny()
    full = tmp_path / "full"
    generate(spec, full, show_progress=False)
    part = tmp_path / "part"
    generate(spec, part, show_progress=False, only=[0])
    # an interrupted sequence leaves a .tmp- folder, which verify does not accept
    (part / ".tmp-seq_0001" / "images").mkdir(parents=True)
    (part / ".tmp-seq_0001" / "images" / "000000.png").write_bytes(b"partial")
    problems = verify_dataset(part)
    assert any("seq_0001: missing" in p for p in problems) and any(".tmp-seq_0001" in p for p in problems)
    res = generate(spec, part, show_progress=False)
    assert res.skipped == ["seq_0000"] and res.rendered == ["seq_0001"]
    assert verify_dataset(part) == []
    assert _dataset_digest(part) == _dataset_digest(full)


def test_a_renderer_keeps_the_memory_a_frame_frees():
    """A frame is made from dozens of full-size temporaries.  With glibc's defaults every round of
    them faults its pages in afresh (the heap is trimmed, big blocks are unmapped); once a renderer
    exists the process keeps freed memory, and the next round reuses it.  (Linux, glibc: CI's.)"""
    code = """
import resource, numpy as np
def faults():
    f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(10):
        a = [np.ones((800, 800, 3), np.float32) for _ in range(8)]
        del a
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0
faults()
before = faults()
from render.frames import SequenceRenderer
from tests.test_render import _tiny
SequenceRenderer(_tiny(), 0).close()
faults()
print(before, faults())
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 0, r.stderr
    before, after = map(int, r.stdout.split())
    pages = 10 * 8 * 800 * 800 * 3 * 4 // 4096
    assert before > pages // 10 and after < pages // 100, (before, after, pages)


def test_body_poses_are_the_states_poses():
    """``Trajectory.body_poses`` skips the rates :meth:`state` also computes; the poses are the same
    to the bit (a rolling shutter asks for many)."""
    from hvloc.geometry import make_transform

    for fam, mount in (("straight", [180.0, 0.0, -90.0]), ("spiral", [180.0, 0.0, -90.0]),
                       ("hover_correct", [205.0, 0.0, -90.0]), ("manoeuvres", [205.0, 0.0, -90.0])):
        spec = _tiny(**{"trajectory.families": [fam], "trajectory.gust_accel_mps2": [0.3, 0.4],
                        "camera.mount": {"rpy_deg": mount}})
        traj = plan_sequence(spec, 0).trajectory
        t = np.linspace(0.0, traj.duration, 37)
        s = traj.state(t)
        want = np.stack([make_transform(R, p) for R, p in zip(s.R_W_B, s.pos_W)])
        assert np.array_equal(traj.body_poses(t), want)


def test_other_spec_in_out_dir_is_refused(tmp_path):
    from pad_design.errors import InputError

    generate(_tiny(), tmp_path / "d", show_progress=False, only=[0])
    with pytest.raises(InputError, match="another spec"):
        generate(_tiny(seed=99), tmp_path / "d", show_progress=False)


def test_imu_consistency():
    """Integrated gyro reproduces the labelled attitude change over 1 s within the noise model;
    accelerometer minus gravity matches the trajectory's second derivative."""
    spec = load_dataset_spec(REPO / "data_specs" / "sim800.yaml")
    from render.trajectory import GRAVITY

    for index in range(4):
        plan = plan_sequence(spec, index)
        imu = plan.imu
        traj = plan.trajectory
        dt = 1.0 / spec.imu.rate_hz
        for t0 in (5.0, 20.0):
            sel = (imu[:, 0] >= t0 - 1e-9) & (imu[:, 0] <= t0 + 1.0 + 1e-9)
            rows = imu[sel]
            R = np.eye(3)
            for a, b in zip(rows[:-1], rows[1:]):
                R = R @ so3_exp(0.5 * (a[1:4] + b[1:4]) * dt)
            s = traj.state([rows[0, 0], rows[-1, 0]])
            truth = s.R_W_B[0].T @ s.R_W_B[1]
            err = rotation_angle(R, truth)
            # noise: random walk of white noise over 1 s, plus bias (~3 sigma)
            bound = 3 * (spec.imu.gyro_noise_rad_s * math.sqrt(dt * 1.0) + spec.imu.gyro_bias_rad_s * math.sqrt(3)
                         + spec.imu.gyro_bias_walk_rad_s2)
            assert err < bound, f"seq {index} t0 {t0}: gyro integration off by {err:.4f} rad (bound {bound:.4f})"
        # accelerometer: rotate to the world, remove gravity, compare with the trajectory's acceleration
        s = traj.state(imu[:, 0])
        a_W = np.einsum("nij,nj->ni", s.R_W_B, imu[:, 4:7]) - [0, 0, GRAVITY]
        resid = a_W - s.acc_W
        assert np.abs(resid.mean(axis=0)).max() < 4 * spec.imu.accel_bias_mps2 + 0.01
        assert resid.std(axis=0).max() < 3 * spec.imu.accel_noise_mps2 + 0.02


def test_imu_vibration_is_the_stated_rms_and_leaves_the_rest_of_the_imu_alone():
    """The airframe's vibration is added to each sample at its stated rms; it is mostly a tone that
    averages out over a frame's worth of samples, and the attitude, biases and every other draw
    are those of the same spec without it (a spec that does not ask for it is unchanged)."""
    spec = load_dataset_spec(REPO / "data_specs" / "sim800.yaml")
    still = plan_sequence(spec, 1).imu
    unasked = spec.model_copy(update={"imu": spec.imu.model_copy(update={"vibration_hz": (30.0, 31.0)})})
    assert np.array_equal(plan_sequence(unasked, 1).imu, still)  # nothing drawn for a zero vibration
    shaken_spec = spec.model_copy(update={"imu": spec.imu.model_copy(
        update={"vibration_accel_mps2": 2.0, "vibration_gyro_rad_s": 0.1, "vibration_hz": (120.0, 120.0)})})
    shaken = plan_sequence(shaken_spec, 1).imu
    assert np.array_equal(shaken[:, [0, *range(7, 17)]], still[:, [0, *range(7, 17)]])  # time, AHRS, biases
    d_gyro, d_accel = shaken[:, 1:4] - still[:, 1:4], shaken[:, 4:7] - still[:, 4:7]
    assert np.allclose(d_gyro.std(axis=0), 0.1, rtol=0.1) and np.allclose(d_accel.std(axis=0), 2.0, rtol=0.1)
    # a 120 Hz tone sampled at 200 Hz reads as 80 Hz: most of the variance sits there
    spectrum = np.abs(np.fft.rfft(d_accel[:, 2] - d_accel[:, 2].mean())) ** 2
    freqs = np.fft.rfftfreq(len(d_accel), 1.0 / spec.imu.rate_hz)
    assert spectrum[np.abs(freqs - 80.0) < 8.0].sum() > 0.5 * spectrum.sum()
    # over a frame (0.1 s, 20 samples) it averages out: what a velocity integrated from it keeps is small
    n = 20
    means = d_accel[: len(d_accel) // n * n].reshape(-1, n, 3).mean(axis=1)
    assert means.std() < 0.3 * 2.0


BAD = [
    ("camerra: {}\n", "camerra: unknown key"),
    ("trajectory: {duration_s: [40, 30]}\n", "trajectory.duration_s"),
    ("camera: {width: 64, height: 64}\n", "camera"),
    ("trajectory: {lateral_offset_m: [0, 30]}\n", "lateral_offset_m"),
    ("camera: {fps: 30, exposure_s: 0.5}\n", "exposure_s"),
    ("environment: {ground: [lava]}\n", "environment.ground.0"),
    # 20 m in 3 s: downward faster than gravity, the drone upside down (its labels and IMU would say so)
    ("trajectory: {start_height_m: 20.0, duration_s: [3.0, 3.0]}\n", "trajectory.duration_s"),
]


@pytest.mark.parametrize("text,names", BAD)
def test_bad_dataset_spec_exits_2_naming_the_field(tmp_path, text, names):
    p = tmp_path / "bad.yaml"
    p.write_text(text)
    out = tmp_path / "out"
    assert_input_error(run_cli("generate", p, "--out", out), names)
    assert not out.exists()


def test_spec_identity_ignores_defaults_and_sees_every_change():
    """A spec's hash names the dataset folder and freezes suites: writing a default value out, or a
    future field arriving with its default, must not change it; changing any value must."""
    base = load_dataset_spec(REPO / "data_specs" / "tiny.yaml")
    raw = json.loads(base.canonical_json())  # every field written out, defaults included
    assert DatasetSpec.model_validate(raw).sha256() == base.sha256()
    raw2 = json.loads(base.canonical_json())
    raw2["imu"]["gyro_noise_rad_s"] += 0.001  # a nested field
    assert DatasetSpec.model_validate(raw2).sha256() != base.sha256()
    raw3 = json.loads(base.canonical_json())
    raw3["seed"] = raw3["seed"] + 1
    assert DatasetSpec.model_validate(raw3).sha256() != base.sha256()


def test_a_lens_that_folds_back_before_the_corners_is_refused():
    from pad_design.errors import InputError
    from pad_design.errors import validate_model

    d = {"camera": {"hfov_deg": 94, "dist": [-0.28, 0.09, 0.0008, -0.0005, -0.012]}}
    with pytest.raises(InputError, match="camera: dist: the radial distortion .* folds back"):
        validate_model(DatasetSpec, d)
    # a fisheye must reach the image corners within 80 degrees of its axis, and has 4 coefficients
    d = {"camera": {"model": "fisheye", "hfov_deg": 150, "width": 640, "height": 480, "dist": [0.02, 0, 0, 0]}}
    with pytest.raises(InputError, match="camera: dist: the fisheye distortion .* passes 80 degrees"):
        validate_model(DatasetSpec, d)
    d["camera"].update(hfov_deg=120)
    assert validate_model(DatasetSpec, d).camera.to_camera().model == "fisheye"
    with pytest.raises(InputError, match="camera: dist: the fisheye model has 4 coefficients"):
        validate_model(DatasetSpec, {"camera": {"model": "fisheye", "dist": [0, 0, 0, 0, 0]}})
    # the lens model is part of a spec's identity; a pinhole without distortion is the default spec,
    # whose identity is the renderer's revision alone (RENDER_REVISION: what an old cache was made by;
    # revision 14 flies every spec's descent otherwise)
    plain = validate_model(DatasetSpec, {}).sha256()
    assert plain == validate_model(DatasetSpec, {"camera": {"model": "pinhole", "dist": [0, 0, 0, 0, 0]}}).sha256()
    assert plain == hashlib.sha256(json.dumps({"render_revision": 14}, separators=(",", ":")).encode()).hexdigest()
    display = {"camera": {"mix_in_light": False}}  # a field away from its default is in it, sorted
    assert validate_model(DatasetSpec, display).sha256() == hashlib.sha256(json.dumps(
        {"camera": {"mix_in_light": False}, "render_revision": 14}, sort_keys=True, separators=(",", ":")).encode()).hexdigest()
    assert plain != validate_model(DatasetSpec, {"camera": {"model": "fisheye", "hfov_deg": 60}}).sha256()


def test_translucent_meshes_never_hide_the_ground():
    """Shadows and the soft-edged pad are drawn after every opaque mesh: the sky colour never
    shows through the ground (it did where a shadow texture was drawn before the ground)."""
    spec = load_dataset_spec(REPO / "data_specs" / "sim800.yaml")
    spec = DatasetSpec.model_validate({**spec.model_dump(mode="json"), "camera": {
        **spec.model_dump(mode="json")["camera"], "width": 200, "height": 200, "supersample": 1}})
    from render.generate import camera_from_spec, mount_from_spec, pad_for
    from render.scene import LandingScene

    pad = pad_for(spec)
    cam = camera_from_spec(spec.camera)
    for index in range(4):
        plan = plan_sequence(spec, index)
        sc = LandingScene(pad, plan.scene_draw, spec.platform.height_m, spec.platform.size_m, cam,
                          pad.spec.border_color, np.random.default_rng(0), shadows=True)
        try:
            transparent = {n.name.split("_")[0] for n in sc.scene.mesh_nodes if n.mesh.is_transparent}
            assert "shadow" in transparent
            img = sc.render(plan.trajectory.body_poses([0.0])[0] @ mount_from_spec(spec.camera.mount))
        finally:
            sc.close()
        sky = np.all(np.abs(img.astype(int) - [153, 178, 217]) <= 3, axis=2).mean()
        assert sky < 0.01, f"sequence {index}: {100 * sky:.1f} % of a nadir view at 20 m is sky"


def test_readme_documents_every_frames_csv_column():
    from render.dataset import COLUMN_DOCS

    readme = (REPO / "README.md").read_text()
    for k, v in COLUMN_DOCS.items():
        assert f"| `{k}` | {v.replace('|', '/')} |" in readme, f"README.md: column {k} is not documented as in COLUMN_DOCS"
    # the pose columns say what they hold (the quaternion's were once documented as a translation)
    for c in ("tx", "ty", "tz"):
        assert "translation (m)" in COLUMN_DOCS[c] and "quaternion" not in COLUMN_DOCS[c], c
    for c in ("qx", "qy", "qz", "qw"):
        assert "quaternion" in COLUMN_DOCS[c] and "translation" not in COLUMN_DOCS[c], c


def _halve(item):
    """A module-level transform (spawned workers must unpickle it): half-resolution images."""
    item["image"] = item["image"][:, ::2, ::2]
    return item


def test_frame_dataset_loads_in_spawned_workers(sharp_datasets):
    """The torch Dataset pickles under ``spawn`` (the default start method on macOS and Windows):
    two workers deliver every frame with its labels, the transform applied."""
    import torch
    from torch.utils.data import DataLoader

    from render.dataset import frame_dataset

    ds = sharp_datasets["sharpdist"]
    fd = frame_dataset(ds.root, transform=_halve)
    loader = DataLoader(fd, batch_size=4, num_workers=2, multiprocessing_context="spawn")
    seen = []
    for batch in loader:
        assert batch["image"].shape[1:] == (3, 240, 240) and batch["image"].dtype == torch.float32
        assert batch["K"].shape[1:] == (3, 3) and batch["dist"].shape[1:] == (5,)
        assert batch["corners_px"].shape[1:] == (4, 2) and batch["corners_visible"].dtype == torch.bool
        seen += list(zip(batch["sequence"], batch["frame"].tolist(), batch["height_m"].tolist(), batch["phase_gt"]))
    assert len(seen) == len(fd) == sum(len(s) for s in ds)
    seq = ds[0]
    for sid, k, h, phase in seen[:len(seq)]:
        assert sid == seq.id and h == pytest.approx(seq.frame(k).height_above_pad) and phase == seq.phase_gt[k]
    assert np.allclose(fd[0]["dist"].numpy(), seq.camera.dist)


def test_blur_flow_of_a_ray_leaving_a_strong_lens_does_not_run_away():
    """Over the exposure a ray at the image corner can leave the field of a strong barrel lens,
    past the radius where its polynomial stops growing: the flow must stay the lens's first-order
    step (hundreds of pixels), not the polynomial's 1e8 px, while rays in the field keep the exact
    polynomial."""
    from hvloc.geometry import Camera, make_transform, so3_exp
    from render import motion

    cam = Camera.from_hfov(160, 120, np.radians(100), dist=(-0.25, 0.05, 0, 0, 0.02))
    px = np.array([[0.0, 0.0], [159.0, 119.0], [80.0, 60.0], [150.0, 10.0]])
    n = cam.normalized_from_pixels(px)
    M = make_transform(so3_exp([0, np.radians(35), 0]), [0.1, 0, 0])
    u, v = motion._project(cam, n[:, 0], n[:, 1], np.full(4, 5.0), M)
    P = (M[:3, :3] @ (np.column_stack([n, np.ones(4)]) * 5.0).T).T + M[:3, 3]
    raw = cam.project(P)
    assert np.abs(raw[1]).max() > 1e6  # the polynomial runs away for the corner that leaves the field
    assert np.all(np.isfinite(u)) and np.abs(np.column_stack([u, v]) - px).max() < 3000
    kept = [0, 2]  # rays that stay in the field: exactly the lens model
    assert np.allclose(np.column_stack([u, v])[kept], raw[kept], atol=1e-9)


@pytest.mark.parametrize("kind", ["asphalt", "concrete"])
def test_pavement_shows_stones_that_average_out_higher_up(kind):
    """Real pavement at 3.5 mm per pixel is full of strong corners (about 1,500 per 256 px patch on
    the quay's asphalt, 770 on its concrete) and loses most of its Laplacian variance by 17.5 mm:
    its stones have a size.  The scale-free mottle these kinds were had no corner at all and the
    same detail at both."""
    from benchmarks.realism import rendered_statistics

    near = rendered_statistics("sim800", kind, 0.0035, views=1)
    far = rendered_statistics("sim800", kind, 0.0175, views=1)
    assert near["patches"] and far["patches"]
    assert near["corners"] > 100, near
    assert near["laplacian_var"] > 2 * far["laplacian_var"], (near, far)


def test_asphalt_has_no_stones_larger_than_its_aggregate():
    """Real asphalt's stones are under 2 cm across: from 15 m (15.6 mm per pixel) the quay's shows
    about 3 strong corners per 256 px patch.  Up to render revision 7 its detail tile was copied
    at 1-8 m per tile too, stones of 1-28 cm, and sim800's camera saw 264 there (three draws)."""
    from benchmarks.realism import rendered_statistics

    far = rendered_statistics("sim800", "asphalt", 0.0156, seeds=range(3))
    assert far["patches"] >= 9 and far["corners"] < 20, far


@pytest.mark.parametrize("kind", ["grass", "asphalt"])
def test_ground_detail_does_not_jump_where_the_mipmap_level_changes(kind):
    """A camera descending through an octave of height sees the ground's detail change smoothly:
    the two mipmap levels around the pixels' footprint are blended (trilinear).  Read from the
    finer level alone, the Laplacian variance of grass fell 1.8x and of asphalt 2.8x within a
    quarter of an octave, where the level changed: a pulse in the ground's sharpness at every
    doubling of the height.  Detail finer than a pixel may fall as fast as the pixel's area grows
    (2^(2/4) = 1.41x a quarter octave: revision 8's asphalt, whose aggregate is finer than these
    4-7 mm pixels, falls 1.14-1.35x a step), never in a step of 1.8x."""
    from benchmarks.realism import rendered_statistics

    lap = [rendered_statistics("tiny", kind, 0.004 * 2 ** (i / 4), views=2)["laplacian_var"] for i in range(5)]
    steps = [max(a, b) / min(a, b) for a, b in zip(lap, lap[1:])]
    assert max(steps) < 1.5, lap


def test_ground_detail_levels_blend_in_place():
    """The coarser level, upsampled onto the finer level's texels to be blended with it, lies where
    the finer one does (a shift would move the ground's detail as the camera descends), and a
    blend toward past the last level fades to the tile's mean."""
    import cv2

    from render.ground import GroundDetail

    n = 64
    yy, xx = np.mgrid[0:n, 0:n].astype(np.float32)
    fine = np.exp(-((xx - 20.3) ** 2 + (yy - 37.6) ** 2) / 18.0).astype(np.float32)
    mip = [fine]
    while mip[-1].shape[0] > 4:
        mip.append(cv2.resize(mip[-1], None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA))
    g = GroundDetail.__new__(GroundDetail)
    g._blend_cache, g._toward = {}, {}
    texel = 0.001
    for steps in (2, 4, 7):  # footprints between the finest level's texel and twice it, past the LOD bias
        fp = texel * 2 ** (steps / GroundDetail.BLEND_STEPS - GroundDetail.LOD_BIAS)
        level, tile = g._blended(0, fp, texel, mip)
        assert level == 0 and tile.shape == fine.shape
        m = cv2.moments(tile)
        assert abs(m["m10"] / m["m00"] - 20.3) < 0.05 and abs(m["m01"] / m["m00"] - 37.6) < 0.05
        assert np.isclose(tile.sum(), fine.sum(), rtol=1e-3)  # a blend of two levels of one mean
    # past the last level worth reading (over 16 texels: here the 32-texel one) the blend fades to 0
    level, tile = g._blended(0, texel * 2 ** (1.5 - GroundDetail.LOD_BIAS), texel, mip)
    assert level == 1 and np.allclose(tile, 0.5 * mip[1])


def test_every_shipped_flight_is_one_a_multirotor_can_fly():
    """Every sequence of every shipped spec and suite keeps the body within MAX_TILT_DEG of level
    (the steepest suite flight, a manoeuvre under gusts, tilts 42 degrees; tiny.yaml's 2 s spiral
    79); a descent that must fall faster than gravity turns the thrust axis over, and is refused
    before anything is rendered."""
    from benchmarks.suite import load_suite
    from render.plan import check_flyable, _sequence_trajectory
    from render.trajectory import MAX_TILT_DEG, steepest_tilt

    specs = [load_dataset_spec(p) for p in sorted((REPO / "data_specs").glob("*.yaml"))]
    for p in sorted((REPO / "data_specs" / "suites").glob("*.yaml")):
        specs += load_suite(p)[1]
    for spec in specs:
        check_flyable(spec)
    check_flyable(spec_from(REPO / "data_specs" / "tiny.yaml", sequences=4))  # as the tests render it
    steep = spec_from(REPO / "data_specs" / "tiny.yaml", **{"trajectory.start_height_m": 20.0,
                                                          "trajectory.duration_s": [3.0, 3.0]})
    tilt, t = steepest_tilt(_sequence_trajectory(steep, 0)[2])
    assert tilt > MAX_TILT_DEG, (tilt, t)


@pytest.mark.parametrize("light", [False, True])
def test_a_fine_pattern_seen_from_afar_is_as_bright_as_its_light(light):
    """A pad printed with a one-texel black-and-white checker, seen from 3 and 8 m (about 9 and 25
    texels to a pixel).  A camera's pixel sums light: half white is half the light (a display value
    of 186 through the 2.2 tone curve).  Mixed in display values (``camera.mix_in_light: false``, as
    revisions up to 11 rendered) the mipmaps make it 128, a fifth of the light; mixed in light (the
    default since revision 12, the render then float32 light) it is half.  (The shipped pad's white field from 4-20 m: 0.73-0.78 of full light where
    its texture averages 0.84; in light 0.84-0.85.)"""
    from hvloc.geometry import Camera, look_at_cam2world
    from pad_design import make_pad
    from render.scene import PAD_THICKNESS_M, LandingScene, SceneDraw

    pad = make_pad(ppm=500)
    # 480 texels and the soft edge's 2 x 16: a power of two, whose mipmaps halve exactly (Mesa's
    # mipmaps of other sizes alias a one-texel checker into bright and dark blotches)
    n = 480
    checker = np.where((np.add.outer(np.arange(n), np.arange(n)) % 2)[..., None] == 0, 255, 0).astype(np.uint8)
    checker = np.ascontiguousarray(np.repeat(checker, 3, axis=2))
    draw = SceneDraw("concrete", math.radians(60.0), 0.0, 3.0, 0.35, [], [], [])
    cam = Camera.from_hfov(200, 200, math.radians(60))
    scene = LandingScene(pad, draw, 0.0, 0.0, cam, (255, 48, 224), np.random.default_rng(0), shadows=False,
                         pad_texture=checker, light=light)
    try:
        for h in (3.0, 8.0):
            T_W_C = look_at_cam2world((0.0, 0.0, h), (0.0, 0.0, 0.0))
            img = scene.render(T_W_C)
            assert img.dtype == (np.float32 if light else np.uint8)
            lin = img.astype(np.float64) if light else (img / 255.0) ** 2.2
            u, v = np.round(cam.project_from(T_W_C, [[0.0, 0.0, PAD_THICKNESS_M]])[0]).astype(int)
            centre = lin[v - 4:v + 5, u - 4:u + 5]
            want = 0.5 if light else 0.5 ** 2.2  # half the light, or half the display value: a fifth of it
            assert np.abs(centre - want).max() < 0.01, (h, float(centre.min()), float(centre.max()))
    finally:
        scene.close()


def test_an_opengl_without_a_float_framebuffer_is_named_not_drawn_black(monkeypatch):
    """Mixing in light (the default since render revision 12) draws into a float framebuffer.  An
    OpenGL that cannot (an incomplete framebuffer) gets an error that says so and how to render
    without one (``camera.mix_in_light: false``), not frames of black; the display-value scene
    still renders there."""
    from OpenGL import GL

    from hvloc.geometry import Camera
    from pad_design import make_pad
    from render.scene import LandingScene, SceneDraw

    draw = SceneDraw("concrete", math.radians(60.0), 0.0, 3.0, 0.35, [], [], [])
    cam = Camera.from_hfov(64, 64, math.radians(60))
    pad = make_pad(ppm=200)
    monkeypatch.setattr(GL, "glCheckFramebufferStatus", lambda target: 0)
    with pytest.raises(RuntimeError, match="cannot draw into a float framebuffer.*mix_in_light: false"):
        LandingScene(pad, draw, 0.0, 0.0, cam, (255, 48, 224), np.random.default_rng(0), shadows=False, light=True)
    scene = LandingScene(pad, draw, 0.0, 0.0, cam, (255, 48, 224), np.random.default_rng(0), shadows=False, light=False)
    try:
        assert scene.render(np.eye(4)).dtype == np.uint8
    finally:
        scene.close()


def test_the_cameras_sharpening_clips_at_black_and_moves_only_the_specs_that_sharpen():
    """The camera's unsharp mask undershoots beside a bright edge; a camera clips that at black.
    Written as its absolute value (OpenCV's convertScaleAbs), a black pixel beside white read 38
    of 255 under a 0.5 mask: a grey halo on the dark side of every strong edge.  Where nothing
    undershoots, the sharpening is as it was (render revision 13)."""
    from hvloc.geometry import Camera
    from render.imaging import WHITE_LEVEL, ImageFormation, ImagingParams

    cam = Camera(64, 24, 60.0, 60.0, 31.5, 11.5)

    def written(left, right, sharpen):
        p = ImagingParams(exposure_gain=1.0, gamma=1.0, defocus_sigma_px=0.0, shot_noise=0.0, read_noise=0.0,
                          jpeg_quality=None, sharpen=sharpen)
        light = np.full((24, 64, 3), left, np.float32)
        light[:, 32:] = right
        return ImageFormation(cam, 1, p, 1.0 / WHITE_LEVEL, seed=0).finish(light, 0)[12, :, 1].astype(int)

    row = written(0.0, 1.0, 0.5)
    assert (row[:32] == 0).all() and (row[32:] == 255).all(), row  # clipped both ways: no halo
    # grey to grey: nothing undershoots black, the mask's overshoot as a camera writes it
    row, soft = written(0.05, 0.4, 0.5), written(0.05, 0.4, 0.0)
    disp = soft[[0, 31, 32, 63]] / 255.0
    step = 0.5 * (disp[2] - disp[1]) * 0.5 * math.erfc(0.5 / math.sqrt(2.0))  # a 1 px Gaussian's share across
    assert row[31] < soft[31] - 10 and row[32] > soft[32] + 10 and row[31] > 0, (row, soft)
    assert abs(row[31] - 255.0 * (disp[1] - step)) <= 1.5 and abs(row[32] - 255.0 * (disp[2] + step)) <= 1.5, (row, soft, step)
    assert (row[:20] == soft[:20]).all() and (row[44:] == soft[44:]).all()  # far from the edge: untouched


def test_a_known_camera_response_is_written_with_the_frames_it_made_and_read_back(tmp_path):
    """``camera.response_known``: each sequence's camera.json says how its camera wrote light (the
    tone curve's exponent and the sharpening drawn for it, meta.json's imaging), as a photometric
    calibration does; the frames are the same as without it.  A response no camera has is named."""
    from pad_design.errors import InputError
    from render.dataset import Sequence

    over = {"degradations.gamma": [0.9, 1.1], "degradations.sharpen": [0.2, 0.5]}
    generate(_tiny(**over, **{"camera.response_known": True}), tmp_path / "known", show_progress=False, only=[0])
    generate(_tiny(**over), tmp_path / "plain", show_progress=False, only=[0])
    known, plain = Dataset(tmp_path / "known")[0], Dataset(tmp_path / "plain")[0]
    drawn = json.loads((known.root / "meta.json").read_text())["imaging"]
    assert known.response == pytest.approx((2.2 * drawn["gamma"], drawn["sharpen"], 1.0))
    assert 0.2 <= drawn["sharpen"] <= 0.5 and drawn["gamma"] != 1.0
    assert plain.response is None and "response" not in plain.camera_info
    assert all((known.root / f"images/{k:06d}.png").read_bytes() == (plain.root / f"images/{k:06d}.png").read_bytes()
               for k in range(len(known)))
    info = json.loads((known.root / "camera.json").read_text())
    for bad, field in (({"gamma": -2.2}, "response.gamma"), ({"gamma": 2.2, "sharpen": float("nan")}, "response.sharpen"),
                       ("sRGB", "response must be an object")):
        (known.root / "camera.json").write_text(json.dumps({**info, "response": bad}))
        with pytest.raises(InputError, match=field.replace(".", r"\.")):
            Sequence(known.root)


def test_the_pads_window_holds_a_side_a_barrel_lens_bows_past_its_corners():
    """The renderer adds the pad's glare, relief shading and deck light over a window of the image
    around the pad (:func:`render.frames.pad_window`).  It was its corners' box: through a barrel
    lens (k1 -0.25, 100 degrees) a side running near the image's edge bows out past it, and the
    sliver between got none of that light.  Every pixel whose ray meets the pad now lies in the
    window, over views with a side near each edge (356 of them were not).  A pad partly out of view
    gives the whole image: a corner near the camera's plane projected past any integer (numpy's
    cast warned, and the window came out empty), and a lens folds points far out of view back in."""
    from hvloc.geometry import Camera, make_transform
    from render.frames import pad_window

    cam = Camera.from_hfov(640, 480, math.radians(100.0), dist=(-0.25, 0.05, 0.0, 0.0, 0.0))
    s = 0.5
    corners = np.array([[-s, -s, 0.0], [s, -s, 0.0], [s, s, 0.0], [-s, s, 0.0]])
    u, v = np.meshgrid(np.arange(640.0), np.arange(480.0))
    rays = cam.normalized_from_pixels(np.column_stack([u.ravel(), v.ravel()]))
    missed_before = 0
    for dx, dy in ((0.0, 0.9), (0.0, -0.9), (1.2, 0.0), (-1.2, 0.0)):
        T = make_transform(np.diag([1.0, -1.0, -1.0]), [dx, dy, 1.4])  # looking down from 1.4 m
        R, t = T[:3, :3], T[:3, 3]
        d = rays @ R[:, :2].T + R[:, 2]  # each pixel's ray in the pad's frame
        P = t + d * (-t[2] / d[:, 2])[:, None]
        on = (np.abs(P[:, 0]) < s) & (np.abs(P[:, 1]) < s)
        rows, cols = np.divmod(np.flatnonzero(on), 640)
        assert len(rows) > 1000
        r0, r1, c0, c1 = pad_window(cam, T, corners)
        assert (rows >= r0).all() and (rows < r1).all() and (cols >= c0).all() and (cols < c1).all(), (dx, dy)
        box = cam.project_from(T, corners)  # (the corners' box, as before)
        lo, hi = np.floor(box.min(axis=0)) - 2, np.ceil(box.max(axis=0)) + 3
        missed_before += int(((rows < lo[1]) | (rows >= hi[1]) | (cols < lo[0]) | (cols >= hi[0])).sum())
    assert missed_before > 50, missed_before  # (the premise)
    # a pad partly out of view: the whole image (a lens folds points far out of view back in)
    T = make_transform(np.diag([1.0, -1.0, -1.0]), [0.0, 1.3, 1.4])
    assert not cam.in_image(cam.project_from(T, corners)).all()
    assert pad_window(cam, T, corners) == (0, 480, 0, 640)
