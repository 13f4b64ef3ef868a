"""``hvloc import``: a real flight (a video or a folder of images, a calibration, optionally an IMU
log and ground truth) as an hvloc dataset, so that ``localize``, ``bench score`` and the report work
on it as on a rendered one.

* Frames: every image of a folder (sorted by name; PNG, JPEG, BMP, TIFF) or every frame of a video
  (what OpenCV's ``VideoCapture`` reads), stored losslessly as PNG; frame ``k`` at ``k / fps``
  (DESIGN.md), ``fps`` given or the video's.  Images named by their frame number (``000123.png``)
  keep it, so a recording that dropped frames keeps its gaps and its times.  Or a timestamps file
  (one capture time per frame): the times are kept as they are (jitter too) and the frame numbers
  recovered from them (``round(t * fps)``), so gaps come back whatever the files are called; every
  clock (frames, ground truth, IMU, all on the same one) is re-zeroed to the first frame.
* Camera: a calibration file (:mod:`render.calibration`); the mount ``T_B_C`` as roll/pitch/yaw in
  degrees (default: hvloc's downward camera).
* Ground truth (optional): TUM poses ``t tx ty tz qx qy qz qw`` of the camera in the pad frame
  (``T_P_C``), or of the body (``T_P_B``; the mount gives the camera), on the frames' clock (shifted
  by ``--gt-time-offset``), interpolated to each frame time (position linearly, rotation along the
  shortest arc; frames outside the ground truth's time span have none).  The labels (corner pixels,
  visibility, ground-truth phase) come from it by the same rule as for rendered data, from the
  geometry alone (what hides the pad in a real image is not known: visibility means in view).
* IMU (optional): an ``imu.csv`` with hvloc's columns (``t, gyro_*, accel_*, q*``) on the same clock.

Frames without ground truth have NaN poses and an empty ``phase_gt``; the metrics that need ground
truth skip them, and say so.  ``meta.json`` records where everything came from (paths and SHA-256).
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from hvloc.geometry import continuous_quaternions, invert, transform_from_tum, tum_from_transform
from pad_design.errors import InputError, validate_model

from . import dataset as ds

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


def _natural_key(p: Path):
    return [int(s) if s.isdigit() else s for s in re.split(r"(\d+)", p.name)]


def frame_source(path) -> tuple:
    """``(frame indices, fps or None, iterator of RGB uint8 frames)`` of an image folder or a video
    file; an image folder whose names are all frame numbers gives those numbers."""
    import cv2

    p = Path(path)
    if p.is_dir():
        files = sorted((f for f in p.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES), key=_natural_key)
        if not files:
            raise InputError(f"{p}: no images ({', '.join(IMAGE_SUFFIXES)}) in this folder")

        def images():
            for f in files:
                img = cv2.imread(str(f), cv2.IMREAD_COLOR)
                if img is None:
                    raise InputError(f"{f}: not an image OpenCV can read")
                yield cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
        stems = [f.stem for f in files]
        numbered = all(s.isdigit() and len(s) < 10 for s in stems) and len(set(map(int, stems))) == len(stems)
        return (np.array([int(s) for s in stems]) if numbered else np.arange(len(files))), None, images()
    if not p.is_file():
        raise InputError(f"{p}: no such video file or image folder")
    cap = cv2.VideoCapture(str(p))
    if not cap.isOpened():
        raise InputError(f"{p}: not a video OpenCV can read")
    fps = cap.get(cv2.CAP_PROP_FPS)
    frames = []
    while True:
        ok, img = cap.read()
        if not ok:
            break
        frames.append(cv2.cvtColor(img, cv2.COLOR_BGR2RGB))
    cap.release()
    if not frames:
        raise InputError(f"{p}: the video has no frame OpenCV can decode")
    return np.arange(len(frames)), (float(fps) if fps and math.isfinite(fps) and fps > 0 else None), iter(frames)


def read_pose_tum(path) -> np.ndarray:
    """``(N, 8)`` rows of a TUM file, sorted by time, with unit quaternions; an :class:`InputError` names
    what is wrong."""
    rows = ds.read_tum(path) if Path(path).is_file() else None
    if rows is None:
        raise InputError(f"{path}: no such ground-truth file")
    if rows.ndim != 2 or rows.shape[1] != 8 or len(rows) < 2:
        raise InputError(f"{path}: a TUM file has rows 't tx ty tz qx qy qz qw' (at least two)")
    if not np.all(np.isfinite(rows)):
        raise InputError(f"{path}: a value is not finite")
    if np.any(np.diff(rows[:, 0]) <= 0):
        raise InputError(f"{path}: times must increase from row to row")
    n = np.linalg.norm(rows[:, 4:], axis=1)
    if np.any(np.abs(n - 1) > 1e-3):
        raise InputError(f"{path}: row {int(np.argmax(np.abs(n - 1)))}: the quaternion is not of unit length")
    rows[:, 4:] /= n[:, None]
    return rows


def interpolate_poses(rows: np.ndarray, t: np.ndarray) -> list:
    """The pose of ``rows`` (TUM, sorted) at each time ``t``: ``None`` outside their span."""
    out = []
    times = rows[:, 0]
    for ti in t:
        if ti < times[0] - 1e-9 or ti > times[-1] + 1e-9:
            out.append(None)
            continue
        out.append(ds.interpolate_pose(times, lambda k: transform_from_tum(rows[k, 1:]), ti))
    return out


def blur_bound_px(poses: list, index: np.ndarray, camera, half_side_m: float) -> np.ndarray:
    """Per frame, the largest image motion of the pad in view over one frame interval, toward
    either neighbour (:func:`render.phase.pad_image_motion_px`): an upper bound of the motion blur,
    as no exposure can be longer than a frame.  NaN where a neighbour or the pose is missing, or no
    part of the pad is in view (such frames are not image-checked)."""
    from .phase import pad_image_motion_px

    out = np.full(len(poses), np.nan)
    for k in range(len(poses)):
        if poses[k] is None:
            continue
        steps = [pad_image_motion_px(camera, poses[k], poses[j], half_side_m, (poses[k],)) / abs(int(index[j]) - int(index[k]))
                 for j in (k - 1, k + 1) if 0 <= j < len(poses) and poses[j] is not None]
        steps = [s for s in steps if np.isfinite(s)]
        if steps:
            out[k] = max(steps)
    return out


def _label_row(k: int, t: float, cam2pad, camera, pad, min_module_px: float) -> dict:
    """Frame ``k``'s frames.csv row (its own index: gaps kept)."""
    from .phase import phase_gt, view_facts

    nan7 = [math.nan] * 7
    row = {"frame": k, "t": t, "image": f"images/{k:06d}.png", "blur_px": math.nan, "blur_subframes": 1}
    if cam2pad is None or cam2pad[2, 3] <= 0:
        row.update(dict(zip(ds.POSE, nan7)), height_above_pad=math.nan, phase_gt="", pad_fully_visible=False,
                   markers_visible=0, module_px=0.0, pad_visible_fraction=math.nan)
        row.update({f"c{i}{a}": math.nan for i in range(4) for a in "uv"})
        row.update({f"c{i}_visible": False for i in range(4)})
        row.update({f"marker_{n}_visible": False for n in ("top", "right", "bottom")})
    else:
        facts = view_facts(camera, cam2pad, pad.geometry)
        pose = tum_from_transform(cam2pad)
        px = facts["corners_px"].copy()
        px[~camera.in_image(px)] = np.nan
        row.update(dict(zip(ds.POSE, pose)), height_above_pad=pose[2],
                   phase_gt=phase_gt(camera, cam2pad, pad.geometry, min_module_px, facts),
                   pad_fully_visible=facts["pad_fully_visible"], markers_visible=facts["markers_visible"],
                   module_px=facts["module_px"], pad_visible_fraction=facts["pad_visible_fraction"])
        for i in range(4):
            row[f"c{i}u"], row[f"c{i}v"] = px[i]
            row[f"c{i}_visible"] = bool(facts["corner_visible"][i])
        for name, vis in facts["marker_visible"].items():
            row[f"marker_{name.lower()}_visible"] = vis
    # what a recording does not know: the world poses and velocities
    row.update({f"{w}_{c}": math.nan for w in ("pad2world", "body2world") for c in ds.POSE})
    row.update({f"{w}_{c}": math.nan for w in ("body_vel", "pad_vel") for c in "xyz"})
    return row


def read_timestamps(path, count: int) -> tuple:
    """``(times (count,), frame numbers (count,) or None)`` from a file of one capture time per
    frame in frame order (``t``), or ``frame t`` per line; blank lines and ``#`` comments skipped, a
    CSV header allowed.  Times must be finite and increasing, one per frame."""
    rows = []
    for n, line in enumerate(Path(path).read_text().splitlines(), 1):
        line = line.split("#", 1)[0].replace(",", " ").strip()
        if not line:
            continue
        try:
            rows.append([float(v) for v in line.split()])
        except ValueError:
            if rows:  # only a first line may be a header
                raise InputError(f"--timestamps {path}: line {n} is not numbers: {line!r}") from None
    if not rows or len({len(r) for r in rows}) != 1 or len(rows[0]) not in (1, 2):
        raise InputError(f"--timestamps {path}: want one time per line, or 'frame t' per line")
    a = np.array(rows, np.float64)
    if len(a) != count:
        raise InputError(f"--timestamps {path}: {len(a)} times for {count} frames")
    t = a[:, -1]
    if not np.all(np.isfinite(a)) or np.any(np.diff(t) <= 0):
        raise InputError(f"--timestamps {path}: times must be finite and increasing")
    if a.shape[1] == 1:
        return t, None
    k = a[:, 0]
    if np.any(k != np.round(k)) or np.any(np.diff(k) <= 0):
        raise InputError(f"--timestamps {path}: frame numbers must be whole and increasing")
    return t, (k - k[0]).astype(np.int64)


def frame_numbers_from_times(t: np.ndarray, fps: float, source) -> np.ndarray:
    """Frame numbers ``round(t * fps)`` of capture times ``t`` (from 0): a dropped frame leaves its gap.
    Refused when two frames fall on one number (times jitter by half a frame, or ``fps`` is wrong)."""
    k = np.round(np.asarray(t) * fps).astype(np.int64)
    if np.any(np.diff(k) <= 0):
        i = int(np.argmax(np.diff(k) <= 0))
        raise InputError(f"--timestamps {source}: frames {i} and {i + 1} ({t[i]:.4f} and {t[i + 1]:.4f} s) fall on "
                         f"one frame number at {fps:g} fps: give --fps, or 'frame t' lines")
    return k


def import_recording(out, frames, calibration, *, calibration_name: str | None = None, fps: float | None = None,
                     timestamps=None, groundtruth=None, gt_body: bool = False, gt_time_offset_s: float = 0.0, imu=None,
                     mount_rpy_deg=None, pad_spec=None, name: str = "imported", line_s: float = 0.0,
                     ref_row: float | None = None, exposure_s: float | None = None, response=None,
                     show_progress: bool = False) -> dict:
    """Write the recording as a one-sequence dataset in ``out`` (a new folder, written whole or not at
    all).  ``line_s``, ``ref_row``: the camera's rolling shutter (``camera.json``): the time between
    its rows' exposures, and the row a frame's time is (default: the middle one).  ``exposure_s``:
    how long each frame is exposed, where the camera says (its metadata; how far motion smears a
    frame, which the localizer draws: hvloc.synthesis); ``None``: not known.  ``response``: the
    camera's photometric calibration, ``(gamma[, sharpen[, sharpen_sigma_px]])`` (``camera.json``'s
    ``response``: each channel written as ``light ** (1 / gamma)``, then sharpened by an unsharp mask;
    the far pad's design fit then draws the pad as the camera writes it); ``None``: not known.
    Returns ``{"root", "frames", "with_ground_truth", "with_imu"}``."""
    import yaml

    from pad_design.spec import PadSpec

    from .calibration import read_calibration
    from .plan import pad_for
    from .spec import DatasetSpec, MountSpec

    root = Path(out)
    if root.exists() and any(root.iterdir()):
        raise InputError(f"--out {root}: not empty; an import writes a new dataset")
    cal = read_calibration(calibration, calibration_name)
    index, video_fps, images = frame_source(frames)
    count = len(index)
    zero = 0.0  # the first frame's time on the recording's clock (with --timestamps)
    stamps = None
    if timestamps is not None:
        stamps, stamped_index = read_timestamps(timestamps, count)
        zero, stamps = float(stamps[0]), stamps - stamps[0]
    # the rate given, else the video's, else the timestamps' median
    fps = fps or video_fps or (float(1.0 / np.median(np.diff(stamps))) if stamps is not None and count > 1 else None)
    if not fps:
        raise InputError("--fps: needed for an image folder (frame k is at k / fps)")
    if stamps is not None:
        index = stamped_index if stamped_index is not None else frame_numbers_from_times(stamps, fps, timestamps)
    shutter = _rolling_shutter(line_s, ref_row, cal.camera.height, fps)
    if exposure_s is not None and not (math.isfinite(float(exposure_s)) and 0.0 < float(exposure_s) <= 1.0 / fps):
        raise InputError(f"--exposure-s {exposure_s:g}: an exposure lasts more than 0 s and at most a frame interval "
                         f"({1.0 / fps:g} s at {fps:g} fps)")
    response = _response(response)
    mount = MountSpec() if mount_rpy_deg is None else validate_model(MountSpec, {"rpy_deg": list(mount_rpy_deg)},
                                                                       "--mount-rpy")
    pad_doc = {} if pad_spec is None else (yaml.safe_load(Path(pad_spec).read_text()) or {})
    spec = validate_model(DatasetSpec, {
        "name": name, "seed": 0, "sequences": 1,
        "camera": {**cal.spec_fields(), "fps": float(fps), "exposure_s": float(exposure_s or 0.0),
                   "mount": mount.model_dump(mode="json"),
                   "rolling_shutter_line_s": shutter[0]},  # (the manifest's spec says what camera.json does)
        "pad": validate_model(PadSpec, pad_doc, str(pad_spec or "pad")).model_dump(mode="json"),
        "trajectory": {"start_height_m": 3.0, "lateral_offset_m": [0.0, 0.0]}}, "the recording's spec")
    camera, T_B_C = cal.camera, mount.transform()
    pad = pad_for(spec)
    t = index / float(fps) if stamps is None else stamps
    jitter = 0.0
    if stamps is not None:  # frames.csv holds each frame's own time; its spread around k / fps is the jitter
        off = stamps - index / float(fps)
        if np.abs(off).max() > 0.4 / fps:
            i = int(np.argmax(np.abs(off)))
            raise InputError(f"--timestamps {timestamps}: frame {int(index[i])} at {stamps[i]:.4f} s is "
                             f"{off[i] * fps:+.2f} frame intervals from {int(index[i])} / {fps:g} fps (at most 0.4): "
                             "a wrong --fps or frame numbers")
        jitter = max(float(np.std(off)), 1e-9)
    poses = [None] * count
    if groundtruth is not None:
        rows = read_pose_tum(groundtruth)
        rows[:, 0] += gt_time_offset_s - zero
        poses = interpolate_poses(rows, t)
        if gt_body:  # T_P_B -> T_P_C
            poses = [None if p is None else p @ T_B_C for p in poses]
        if not any(p is not None for p in poses):
            raise InputError(f"{groundtruth}: its times ({rows[0, 0]:.3f} to {rows[-1, 0]:.3f} s after the offset) "
                             f"miss every frame (0 to {t[-1]:.3f} s); see --gt-time-offset")
    imu_rows = []
    if imu is not None:
        imu_rows = ds.read_imu_csv(Path(imu))[0]
        imu_rows[:, 0] -= zero
        if not np.all(np.isfinite(imu_rows)) or np.any(np.diff(imu_rows[:, 0]) <= 0):
            raise InputError(f"{imu}: values must be finite and times increasing")
        imu_rows = imu_rows.tolist()
    good = [i for i, p in enumerate(poses) if p is not None]
    if good:  # one quaternion hemisphere from row to row (DESIGN.md)
        q = continuous_quaternions(np.array([tum_from_transform(poses[i])[3:] for i in good]))
    root.mkdir(parents=True, exist_ok=True)
    try:
        return _write(root, spec, camera, T_B_C, pad, images, index, frames, t, poses, good,
                      q if good else None, imu_rows, fps, cal, calibration, groundtruth, gt_body,
                      gt_time_offset_s, imu, pad_spec, show_progress, timestamps, zero, jitter, shutter, response)
    except BaseException:  # nothing half-written: the folder was new (or empty)
        import shutil

        for p in root.iterdir():
            shutil.rmtree(p) if p.is_dir() else p.unlink()
        raise


def _response(values) -> dict | None:
    """``--response GAMMA [SHARPEN [SIGMA_PX]]`` as ``camera.json``'s ``response``, or ``None``; an
    :class:`InputError` naming the option where no camera writes so."""
    from hvloc.texfit import RESPONSE_FIELDS, parse_response

    if values is None:
        return None
    v = list(values)
    if not 1 <= len(v) <= 3:
        raise InputError(f"--response {' '.join(map(str, v))}: give GAMMA [SHARPEN [SIGMA_PX]]")
    try:
        parsed = parse_response(v + [0.0] if len(v) == 1 else v)
    except ValueError as err:
        raise InputError(f"--response {' '.join(map(str, v))}: {err}") from None
    return {key: value for (key, *_), value in zip(RESPONSE_FIELDS, parsed)}


def _rolling_shutter(line_s, ref_row, height: int, fps: float) -> tuple:
    """``(line_s, ref_row)`` checked: a time between rows that reads the frame within a frame
    interval, a reference row inside the frame."""
    line_s = float(line_s)
    if not math.isfinite(line_s) or line_s < 0.0 or line_s * height > 1.0 / fps:
        raise InputError(f"--line-time-s {line_s:g}: the time between rows must be at least 0 and read the "
                         f"{height} rows within a frame interval (1/{fps:g} s)")
    if ref_row is None:
        return line_s, (height - 1) / 2.0
    if line_s == 0.0:
        raise InputError("--ref-row: goes with --line-time-s (a global shutter exposes every row at once)")
    if not (math.isfinite(float(ref_row)) and 0.0 <= float(ref_row) <= height - 1):
        raise InputError(f"--ref-row {ref_row:g}: must be a row of the image (0 to {height - 1})")
    return line_s, float(ref_row)


def _write(root, spec, camera, T_B_C, pad, images, index, frames, t, poses, good, q, imu_rows, fps, cal,
           calibration, groundtruth, gt_body, gt_time_offset_s, imu, pad_spec, show_progress, timestamps=None,
           zero=0.0, jitter=0.0, shutter=(0.0, None), response=None) -> dict:
    from pad_design.errors import progress_bar

    from .imu import IMU_COLUMNS

    with ds.FolderLock(root, "writing"):
        manifest = ds.new_manifest(spec)
        manifest["files"][ds.PAD_TEXTURE] = ds.write_image(root / ds.PAD_TEXTURE, pad.texture_rgb)
        sid = ds.sequence_id(0)
        writer = ds.SequenceWriter(root / f".tmp-{sid}")
        count = len(index)
        blur = blur_bound_px(poses, index, camera, pad.geometry.half_side_m)
        bar = progress_bar(show_progress, count, "import")
        qi = iter(q if q is not None else ())

        class _Layers:  # what the writer takes from a renderer
            airframe_mask = None

        for k, rgb in enumerate(images):
            if rgb.shape[:2] != (camera.height, camera.width):
                raise InputError(f"{frames}: frame {k} is {rgb.shape[1]}x{rgb.shape[0]}, the calibration is "
                                 f"{camera.width}x{camera.height}")
            row = _label_row(int(index[k]), float(t[k]), poses[k], camera, pad, spec.phase_rule.min_module_px)
            row["blur_px"] = float(blur[k])
            if poses[k] is not None:
                row.update(dict(zip(("qx", "qy", "qz", "qw"), next(qi))))
            layers = _Layers()
            layers.labels, layers.rgb = row, rgb
            writer.add(layers)
            if bar:
                bar.update(1)
        if bar:
            bar.close()
        info = camera.to_dict()
        info.update({"fps": float(fps), "exposure_s": spec.camera.exposure_s or None,  # (None: not known)
                     "T_B_C": T_B_C.tolist(), "supersample": 1,
                     "frame_time_jitter_s": jitter,
                     "rolling_shutter_line_s": shutter[0],
                     "rolling_shutter_ref_row": (camera.height - 1) / 2 if shutter[1] is None else shutter[1],
                     "conventions": camera.conventions})
        if response is not None:
            info["response"] = response
        sources = {"frames": str(frames), "calibration": f"{calibration} ({cal.source})"}
        for key, p in (("groundtruth", groundtruth), ("imu", imu), ("pad_spec", pad_spec), ("timestamps", timestamps)):
            if p is not None:
                sources[key] = str(p)
        checks = {k: ds.sha256_file(v) for k, v in (("calibration", calibration), ("groundtruth", groundtruth),
                                                     ("imu", imu), ("timestamps", timestamps)) if v is not None}
        meta = {"sequence": sid, "index": 0, "family": "imported", "frames": count,
                "imported": {"sources": sources, "sha256": checks, "ground_truth": "body" if gt_body else
                             ("camera" if groundtruth is not None else "none"), "gt_time_offset_s": gt_time_offset_s,
                             "time_zero_s": zero,  # the first frame's time on the recording's clock (--timestamps)
                             "frames_with_ground_truth": len(good), "imu": imu is not None},
                "phase_rule": "render/phase.py (visibility from the geometry alone)",
                "min_module_px": spec.phase_rule.min_module_px}
        files = writer.close(camera_info=info, pad_document=pad.document(f"../{ds.PAD_TEXTURE}"),
                             imu_columns=IMU_COLUMNS, imu_rows=imu_rows, meta=meta)
        ds.finalize_sequence(root / f".tmp-{sid}", root / sid)
        manifest["sequences"].append({"id": sid, "index": 0, "seed": 0, "family": "imported", "frames": count})
        manifest["files"].update({f"{sid}/{k}": v for k, v in files.items()})
        manifest["imported"] = True
        ds.save_manifest(root, manifest)
    return {"root": root, "frames": count, "with_ground_truth": len(good), "with_imu": imu is not None}
