"""Render labelled landing sequences: one sequence per unit of work, on any executor.

The run owns its dataset folder (a lock held throughout).  Workers render a sequence into
``.tmp-<id>/`` and return its record; this process alone moves it into place and updates the
manifest, so the manifest lists exactly the sequences that are complete.
"""
from __future__ import annotations

import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pad_design.errors import InputError, progress_bar

from . import dataset as ds
from .executor import report_progress, run_units
from .imaging import camera_response
from .plan import camera_from_spec, check_flyable, mount_from_spec, pad_for, plan_sequence  # noqa: F401  (re-exported)
from .spec import DatasetSpec


def camera_info(spec: DatasetSpec, r) -> dict:
    """What a sequence's ``camera.json`` says (``r``: its :class:`render.frames.SequenceRenderer`)."""
    cam = spec.camera
    info = r.camera.to_dict()
    # the exposure the frames show: an instant where motion blur is not rendered (the spec's exposure_s
    # then smears nothing, and a localizer that read it predicted smear on sharp frames: fzu11's 20 ms)
    info.update({"fps": cam.fps, "exposure_s": cam.exposure_s if r.blur else 0.0, "T_B_C": r.T_B_C.tolist(),
                 "supersample": cam.supersample, "rolling_shutter_line_s": cam.rolling_shutter_line_s,
                 "rolling_shutter_ref_row": r.ref_row, "imu_time_offset_s": spec.imu.time_offset_s,
                 "frame_time_jitter_s": cam.frame_time_jitter_s, "frame_drop_rate": cam.frame_drop_rate, "mono": cam.mono,
                 "conventions": r.camera.conventions})
    if cam.response_known:  # a photometric calibration: written = light ** (1 / gamma), then sharpened
        info["response"] = camera_response(r.plan.imaging)
    return info


def render_sequence(spec: DatasetSpec, index: int, out_root, progress=None) -> dict:
    """Render sequence ``index`` of ``spec`` into ``out_root/.tmp-<id>/``, complete and checksummed.
    Returns its record; :func:`generate` moves it into place.  The pad's texture is read from
    ``out_root/pad.png`` (the dataset's one copy) when it is there."""
    from .frames import SequenceRenderer
    from .imu import IMU_FILE_COLUMNS

    out_root = Path(out_root)
    sid = ds.sequence_id(index)
    texture = out_root / ds.PAD_TEXTURE
    with SequenceRenderer(spec, index, texture if texture.is_file() else None) as r:
        writer = ds.SequenceWriter(out_root / f".tmp-{sid}")
        for k in range(len(r)):
            writer.add(r.render(k))
            (progress or report_progress)(1)
        cam = spec.camera
        info = camera_info(spec, r)
        plan = r.plan
        meta = {"sequence": sid, "index": index, "seed": plan.seed, "dataset_seed": spec.seed, "family": plan.family,
                "duration_s": float(plan.trajectory.duration), "frames": len(r), "blur_method": spec.degradations.blur_method,
                "scene": plan.scene_draw.to_dict(), "imaging": plan.imaging.to_dict(),
                "spec_excerpt": {"camera": cam.model_dump(mode="json"),
                                 "trajectory": spec.trajectory.model_dump(mode="json"),
                                 "platform": spec.platform.model_dump(mode="json")},
                "phase_rule": "render/phase.py", "min_module_px": spec.phase_rule.min_module_px}
        relief = r.relief_report()
        if relief is not None:
            meta["pad_relief"] = relief
        files = writer.close(camera_info=info, pad_document=r.pad.document(f"../{ds.PAD_TEXTURE}"),
                             imu_columns=IMU_FILE_COLUMNS, imu_rows=plan.imu.tolist(), meta=meta)
    return {"id": sid, "index": index, "seed": plan.seed, "family": plan.family, "frames": len(r.times),
            "files": {f"{sid}/{k}": v for k, v in files.items()}}


def _render_unit(spec_json: str, index: int, out_root: str) -> dict:
    return render_sequence(DatasetSpec.model_validate_json(spec_json), index, out_root)


# ----------------------------------------------------------------------------- the dataset

@dataclass
class GenerateResult:
    root: Path
    rendered: list
    skipped: list
    frames: int
    seconds: float


def _kept_sequences(root: Path, manifest: dict) -> set:
    """Indices of listed sequences whose every file is there and matches its checksum (a resume
    re-checks what it keeps)."""
    done = set()
    for s in manifest.get("sequences", []):
        files = {k: v for k, v in manifest["files"].items() if k.startswith(s["id"] + "/")}
        if files and (root / s["id"] / "meta.json").is_file() and not ds.files_differing(root, files):
            done.add(s["index"])
    return done


def _prepare_texture(spec: DatasetSpec, root: Path, manifest: dict) -> None:
    """The dataset's one copy of the pad texture: kept when it matches its checksum, else written."""
    listed = manifest["files"].get(ds.PAD_TEXTURE)
    path = root / ds.PAD_TEXTURE
    if listed and path.is_file() and ds.sha256_file(path) == listed:
        return
    if manifest["sequences"]:  # sequences were made with a texture we no longer have
        raise InputError(f"{path}: the dataset's pad texture is missing or damaged; its sequences cannot be kept "
                         "(regenerate with --overwrite)")
    manifest["files"][ds.PAD_TEXTURE] = ds.write_image(path, pad_for(spec).texture_rgb)


def generate(spec: DatasetSpec, out, workers: int = 1, overwrite: bool = False, show_progress: bool = True,
             only: list | None = None, executor: str = "local", ray_address: str | None = None) -> GenerateResult:
    """Render every sequence of ``spec`` into ``out``, resuming a previous run of the same spec."""
    root = Path(out)
    check_flyable(spec, only)  # before anything is written
    with ds.FolderLock(root, "writing"):
        try:
            existing = ds.load_manifest(root)
        except InputError:
            if not overwrite:
                raise
            existing = {"spec_sha256": None}
        if existing is not None and existing.get("spec_sha256") != spec.sha256():
            if not overwrite:
                raise InputError(f"{root}: holds a dataset of another spec ({existing.get('name')}); "
                                 "choose another --out or pass --overwrite")
            for p in root.iterdir():
                if p.name in ("manifest.json", ds.PAD_TEXTURE) or p.name.startswith(("seq_", ".tmp-")):
                    shutil.rmtree(p) if p.is_dir() else p.unlink()
            existing = None
        for p in root.glob(".tmp-*"):
            shutil.rmtree(p, ignore_errors=True)
        manifest = existing or ds.new_manifest(spec)
        done = _kept_sequences(root, manifest)
        manifest["sequences"] = [s for s in manifest["sequences"] if s["index"] in done]
        keep = {s["id"] for s in manifest["sequences"]}
        manifest["files"] = {k: v for k, v in manifest["files"].items() if k.split("/")[0] in keep or "/" not in k}
        for p in root.glob("seq_*"):  # unlisted: left by a run that was killed before it recorded them
            if p.name not in keep:
                shutil.rmtree(p, ignore_errors=True) if p.is_dir() else p.unlink()
        _prepare_texture(spec, root, manifest)
        ds.save_manifest(root, manifest)
        todo = [i for i in (only if only is not None else range(spec.sequences)) if i not in done]
        t0 = time.time()
        bar = progress_bar(show_progress, lambda: sum(len(plan_sequence(spec, i).frame_times) for i in todo),
                           f"render {spec.name}", smoothing=0.1)
        rendered = []
        units = [(spec.canonical_json(), i, str(root)) for i in todo]
        try:
            for rec in run_units(_render_unit, units, workers, executor, ray_address,
                                 progress=bar.update if bar else None):
                sid = rec["id"]
                ds.finalize_sequence(root / f".tmp-{sid}", root / sid)
                manifest["sequences"].append({k: rec[k] for k in ("id", "index", "seed", "family", "frames")})
                manifest["files"].update(rec["files"])
                ds.save_manifest(root, manifest)
                rendered.append(sid)
                if bar and executor == "ray":
                    bar.update(rec["frames"])
        finally:
            if bar:
                bar.close()
    frames = sum(s["frames"] for s in manifest["sequences"] if s["id"] in rendered)
    return GenerateResult(root, rendered, sorted(ds.sequence_id(i) for i in done), frames, time.time() - t0)


def plan_frames(spec: DatasetSpec, index: int) -> np.ndarray:
    """Frame times of one sequence, without rendering (cheap: the trajectory only)."""
    return plan_sequence(spec, index).frame_times


__all__ = ["generate", "render_sequence", "plan_sequence", "plan_frames", "camera_from_spec", "mount_from_spec",
           "pad_for", "GenerateResult"]
