"""Render labelled landing sequences: one sequence per call, many in parallel processes."""
from __future__ import annotations

import json
import math
import multiprocessing as mp
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hvloc.geometry import Camera, compose, invert, make_transform, so3_exp, transform_points, tum_from_transform
from pad_design.errors import InputError

from . import dataset as ds
from .phase import phase_gt, view_facts
from .spec import DatasetSpec

IMAGE_BATCH = 8


def camera_from_spec(cam) -> Camera:
    f = (cam.width / 2.0) / math.tan(math.radians(cam.hfov_deg) / 2.0)
    return Camera(cam.width, cam.height, f, f * cam.fy_over_fx, (cam.width - 1) / 2.0 + cam.principal_offset_px[0],
                  (cam.height - 1) / 2.0 + cam.principal_offset_px[1], tuple(cam.dist))


def mount_from_spec(mount) -> np.ndarray:
    """``T_B_C`` from the spec: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = np.radians(mount.rpy_deg)
    R = so3_exp([0, 0, y]) @ so3_exp([0, p, 0]) @ so3_exp([r, 0, 0])
    return make_transform(R, mount.xyz_m)


_PAD_CACHE = {}


def pad_for(spec: DatasetSpec):
    from pad_design import make_pad

    key = (spec.pad.model_dump_json(), spec.pad_ppm)
    if key not in _PAD_CACHE:
        _PAD_CACHE[key] = make_pad(spec.pad, spec.pad_ppm)
    return _PAD_CACHE[key]


@dataclass
class SequencePlan:
    """Everything drawn for one sequence before rendering (reproducible from the seed alone)."""

    index: int
    seed: int
    family: str
    trajectory: object
    scene_draw: object
    imaging: object
    frame_times: np.ndarray
    imu: np.ndarray = field(repr=False)


def plan_sequence(spec: DatasetSpec, index: int) -> SequencePlan:
    from .imaging import ImagingParams
    from .imu import synthesize_imu
    from .scene import draw_scene
    from .trajectory import make_trajectory

    seed = ds.sequence_seed(spec.seed, index)
    rng = np.random.default_rng(seed)
    fams = spec.trajectory.families
    family = fams[index % len(fams)]
    T_B_C = mount_from_spec(spec.camera.mount)
    body_above_cam = -float(T_B_C[2, 3])
    pad_surface = spec.platform.height_m + 0.002  # the pad's 2 mm thickness (render.scene.PAD_THICKNESS_M)
    traj = make_trajectory(spec.trajectory, np.random.default_rng(rng.integers(2**63)), family, body_above_cam,
                           pad_surface, spec.platform.velocity_mps)
    cam = spec.camera
    view_radius = spec.trajectory.start_height_m * math.tan(math.radians(cam.hfov_deg) / 2) * 1.5 + \
        spec.trajectory.lateral_offset_m[1]
    draw = draw_scene(spec.environment, np.random.default_rng(rng.integers(2**63)), view_radius)
    d = spec.degradations
    r2 = np.random.default_rng(rng.integers(2**63))
    u = lambda r: float(r2.uniform(r[0], r[1])) if r[1] > r[0] else float(r[0])  # noqa: E731
    imaging = ImagingParams(u(d.exposure_gain), u(d.gamma), u(d.defocus_sigma_px), u(d.shot_noise),
                            u(d.read_noise), d.jpeg_quality)
    n = int(math.floor(traj.duration * cam.fps + 1e-9)) + 1
    times = np.arange(n) / cam.fps
    imu = synthesize_imu(traj, spec.imu, np.random.default_rng(rng.integers(2**63)), times[-1])
    return SequencePlan(index, seed, family, traj, draw, imaging, times, imu)


def render_sequence(spec: DatasetSpec, index: int, out_root, progress=None) -> dict:
    """Render sequence ``index`` of ``spec`` into ``out_root/<id>`` atomically.  Returns its record.

    ``progress(n_frames_done)`` is called as frames finish (for a progress bar)."""
    from .imaging import ImageFormation
    from .scene import PAD_THICKNESS_M, LandingScene

    out_root = Path(out_root)
    sid = ds.sequence_id(index)
    tmp = out_root / f".tmp-{sid}"
    if tmp.exists():
        shutil.rmtree(tmp)
    (tmp / "images").mkdir(parents=True)
    plan = plan_sequence(spec, index)
    pad = pad_for(spec)
    camera = camera_from_spec(spec.camera)
    cam_spec = spec.camera
    T_B_C = mount_from_spec(cam_spec.mount)
    traj = plan.trajectory
    rng_scene = np.random.default_rng(plan.seed ^ 0x5EED)
    imaging = ImageFormation(camera, cam_spec.supersample, plan.imaging, 1.0, plan.seed)
    touchdown = spec.trajectory.touchdown_height_m
    scene = LandingScene(pad, plan.scene_draw, spec.platform.height_m, spec.platform.size_m, imaging.render_camera,
                         pad.spec.border_color, rng_scene, shadows=spec.environment.shadows,
                         znear=min(0.05, 0.5 * touchdown))
    assert abs(scene.pad_surface_z - (spec.platform.height_m + PAD_THICKNESS_M)) < 1e-12

    exposure = cam_spec.exposure_s
    nsub = spec.degradations.blur_subframes if (spec.degradations.motion_blur and exposure > 0) else 1
    offsets = ((np.arange(nsub) + 0.5) / nsub - 0.5) * exposure if nsub > 1 else np.zeros(1)
    times = plan.frame_times
    sub_t = (times[:, None] + offsets[None, :]).ravel()
    T_W_B_sub = traj.body_poses(sub_t)
    # shutter open and close poses for every frame, for the blur_px label (computed once, not per frame)
    T_W_B_open = traj.body_poses(times - exposure / 2) if exposure > 0 else None
    T_W_B_close = traj.body_poses(times + exposure / 2) if exposure > 0 else None
    pin = camera.without_distortion()
    T_W_B = traj.body_poses(times)
    T_W_P = traj.pad_poses(times)
    corners_P = pad.outer_corners_P

    rows, gt, pending = [], [], []
    from concurrent.futures import ThreadPoolExecutor

    writer = ThreadPoolExecutor(max_workers=1)  # PNG encoding overlaps rendering (OpenCV drops the GIL)
    writes = []
    try:
        for k, t in enumerate(times):
            subs = []
            for j in range(nsub):
                i = k * nsub + j
                cam2world = T_W_B_sub[i] @ T_B_C
                scene.set_drone(T_W_B_sub[i])
                subs.append(scene.render(cam2world))
            pending.append(imaging.linear_average(subs))
            cam2pad = invert(T_W_P[k]) @ T_W_B[k] @ T_B_C
            facts = view_facts(camera, cam2pad, pad.geometry)
            phase = phase_gt(camera, cam2pad, pad.geometry, spec.phase_rule.min_module_px, facts)
            px = facts["corners_px"].copy()
            px[~camera.in_image(px)] = np.nan
            # blur: image motion of the pad corners over the exposure (ideal pinhole, any visibility)
            if exposure > 0:
                a = invert(T_W_P[k]) @ T_W_B_open[k] @ T_B_C
                b = invert(T_W_P[k]) @ T_W_B_close[k] @ T_B_C
                d = np.linalg.norm(pin.project_from(a, corners_P) - pin.project_from(b, corners_P), axis=1)
                blur = float(np.nanmax(d)) if np.isfinite(d).any() else float("nan")
            else:
                blur = 0.0
            pose7 = tum_from_transform(cam2pad)
            name = f"images/{k:06d}.png"
            rows.append([k, float(t), name, *pose7, pose7[2], phase, facts["pad_fully_visible"],
                         facts["markers_visible"], facts["module_px"], blur, *px.ravel()])
            gt.append(pose7)
            if len(pending) == IMAGE_BATCH or k == len(times) - 1:
                for j, img in enumerate(imaging.finish(pending)):
                    kk = k - len(pending) + 1 + j
                    writes.append(writer.submit(ds.write_image, tmp / f"images/{kk:06d}.png", img))
                if progress:
                    progress(len(pending))
                pending = []
        for w in writes:
            w.result()  # re-raise any write error
    finally:
        writer.shutdown(wait=True)
        scene.close()

    ds.write_csv(tmp / "frames.csv", ds.FRAME_COLUMNS, rows)
    ds.write_tum(tmp / "groundtruth.tum", times, gt, "t tx ty tz qx qy qz qw  (T_P_C: camera pose in the pad frame)")
    from .imu import IMU_COLUMNS

    ds.write_csv(tmp / "imu.csv", IMU_COLUMNS, plan.imu.tolist())
    info = camera.to_dict()
    info.update({"fps": cam_spec.fps, "exposure_s": exposure, "T_B_C": T_B_C.tolist(),
                 "supersample": cam_spec.supersample,
                 "conventions": "OpenCV pinhole + (k1 k2 p1 p2 k3); pixel centre of top-left pixel at (0,0); "
                                "T_B_C maps camera (OpenCV) to body (FLU)"})
    (tmp / "camera.json").write_text(json.dumps(info, indent=1) + "\n")
    (tmp / "pad.json").write_text(json.dumps(pad.document(), indent=1) + "\n")
    meta = {"sequence": sid, "index": index, "seed": plan.seed, "dataset_seed": spec.seed, "family": plan.family,
            "duration_s": float(traj.duration), "frames": len(times), "subframes": nsub,
            "scene": plan.scene_draw.to_dict(), "imaging": plan.imaging.to_dict(),
            "spec_excerpt": {"camera": spec.camera.model_dump(mode="json"),
                             "trajectory": spec.trajectory.model_dump(mode="json"),
                             "platform": spec.platform.model_dump(mode="json")},
            "phase_rule": "render/phase.py", "min_module_px": spec.phase_rule.min_module_px}
    files = ds.finalize_sequence(tmp, out_root / sid, meta)
    return {"id": sid, "index": index, "seed": plan.seed, "family": plan.family, "frames": len(times),
            "files": {f"{sid}/{k}": v for k, v in files.items()}}


# ----------------------------------------------------------------------------- the dataset

@dataclass
class GenerateResult:
    root: Path
    rendered: list
    skipped: list
    frames: int
    seconds: float


def _complete_sequences(root: Path, manifest: dict) -> set:
    done = set()
    for s in manifest.get("sequences", []):
        d = root / s["id"]
        if (d / "meta.json").exists() and all((root / rel).exists() for rel in manifest["files"] if rel.startswith(s["id"] + "/")):
            done.add(s["index"])
    return done


def _worker(args):
    spec_json, index, out_root, queue = args
    from .scene import import_pyrender  # noqa: F401  (sets the GL platform in this process)
    import torch

    torch.set_num_threads(1)
    spec = DatasetSpec.model_validate_json(spec_json)
    return render_sequence(spec, index, out_root, progress=(lambda n: queue.put(n)) if queue is not None else None)


def generate(spec: DatasetSpec, out, workers: int = 1, overwrite: bool = False, show_progress: bool = True,
             only: list | None = None) -> GenerateResult:
    """Render every sequence of ``spec`` into ``out``, resuming a previous run of the same spec."""
    root = Path(out)
    existing = ds.load_manifest(root) if root.exists() else None
    if existing is not None and existing.get("spec_sha256") != spec.sha256():
        if not overwrite:
            raise InputError(f"{root}: holds a dataset of another spec ({existing.get('name')}); "
                             "choose another --out or pass --overwrite")
        for p in root.iterdir():
            if p.name == "manifest.json" or p.name.startswith("seq_") or p.name.startswith(".tmp-"):
                shutil.rmtree(p) if p.is_dir() else p.unlink()
        existing = None
    root.mkdir(parents=True, exist_ok=True)
    for p in root.glob(".tmp-*"):
        shutil.rmtree(p, ignore_errors=True)
    manifest = existing or ds.new_manifest(spec)
    done = _complete_sequences(root, manifest)
    manifest["sequences"] = [s for s in manifest["sequences"] if s["index"] in done]
    manifest["files"] = {k: v for k, v in manifest["files"].items()
                         if any(k.startswith(s["id"] + "/") for s in manifest["sequences"])}
    ds.save_manifest(root, manifest)
    todo = [i for i in (only if only is not None else range(spec.sequences)) if i not in done]
    t0 = time.time()
    total_frames = sum(len(plan_frames(spec, i)) for i in todo)
    bar = None
    if show_progress:
        from tqdm import tqdm

        bar = tqdm(total=total_frames, unit="frame", desc=f"render {spec.name}", smoothing=0.1)
    rendered = []

    def record(rec):
        manifest["sequences"].append({k: rec[k] for k in ("id", "index", "seed", "family", "frames")})
        manifest["files"].update(rec["files"])
        ds.save_manifest(root, manifest)
        rendered.append(rec["id"])

    try:
        if workers <= 1 or len(todo) <= 1:
            for i in todo:
                record(render_sequence(spec, i, root, progress=bar.update if bar else None))
        else:
            ctx = mp.get_context("spawn")
            with mp.Manager() as manager:
                queue = manager.Queue()
                with ctx.Pool(min(workers, len(todo))) as pool:
                    results = pool.imap_unordered(_worker, [(spec.canonical_json(), i, str(root), queue) for i in todo])
                    pending = len(todo)
                    while pending:
                        try:
                            rec = results.next(timeout=0.2)
                            record(rec)
                            pending -= 1
                        except mp.TimeoutError:
                            pass
                        while not queue.empty():
                            n = queue.get()
                            if bar:
                                bar.update(n)
                    while not queue.empty():
                        n = queue.get()
                        if bar:
                            bar.update(n)
    finally:
        if bar:
            bar.close()
    frames = sum(s["frames"] for s in manifest["sequences"] if s["id"] in rendered)
    return GenerateResult(root, rendered, sorted(ds.sequence_id(i) for i in done), frames, time.time() - t0)


def plan_frames(spec: DatasetSpec, index: int) -> np.ndarray:
    """Frame times of one sequence, without rendering (cheap: the trajectory only)."""
    return plan_sequence(spec, index).frame_times
