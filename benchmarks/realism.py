"""How much detail the rendered ground shows, against real downward frames at the same ground
sampling distance (GSD).

    python -m benchmarks.realism --real DIR [--real-mask MASK.png] [--real-gsd-mm 3.5]
                                 [--heights 1 5 15 | --base-gsd-mm 3.5]
                                 [--kinds grass dry_grass asphalt ...] [--draws 8] [--processing]
                                 [--out FILE.json]

Statistics per 256 x 256 ground-only patch (luma 0-255), medians over patches:

* ``laplacian_var``: variance of the 3x3 Laplacian;
* ``gradient_mean``: mean Sobel gradient magnitude;
* ``corners``: strong corners per 256 x 256 px: local maxima (5 x 5) of the minimum eigenvalue
  (``cv2.cornerMinEigenVal``, block 3, aperture 3, luma in [0, 1]) above 0.01.

Real frames: a folder of downward images of ground taken at ``--real-gsd-mm``, or a list of
frames each with its own GSD and ground kind (``--real-list``, CSV ``path,gsd_mm,kind``, paths
relative to ``--real-root``).  Patches holding bright paper, or pixels outside ``--real-mask``
(e.g. the airframe), are skipped.  A frame counts at every GSD at least as coarse as its own
(within 10 %): box-downsampled to it, then blurred by the camera's own blur in the new pixels
(``--real-psf-px``, a Gaussian sigma), since a camera higher up keeps its blur while a box
average would drop it.  ``--real-psf-px fit`` measures that blur where the list holds frames of
one kind at two or more GSDs: the sigma with which the finer frames, so downsampled, show the
coarser frames' Laplacian variance.  Patches are 256 px, or half a frame's shorter side where
the frame is smaller (16 px at least); every statistic is taken 2 px inside the patch's border.
Smaller patches stand for a 256 px patch together: in the frames' order, they are pooled into
groups of a 256 px patch's area, each group's statistics the area-weighted means of its patches'
(a count per patch scaled up from 18 px patches is mostly 0 or hundreds, and its median 0 where
a 256 px patch of the same ground holds a few corners).  Rendered frames: a
camera of a shipped spec looking straight down from the height that gives each GSD, far from
the pad, with the spec's optics (lens, defocus, supersampling) and light, one view in each of
``--draws`` sequences (seeds 0..N-1: light, exposure and defocus are drawn per sequence, and one
draw is not the spec: field1080's sharpened revision 7 asphalt at 15.6 mm showed 175 to 1,259
strong corners per patch from one draw to the next), and without the camera's processing
(noise, sharpening, JPEG) unless ``--processing``: the real frames lose theirs where they are
box-downsampled.  The GSDs compared are ``--base-gsd-mm`` and 5 and 15 times it for every
camera, or with ``--heights`` the GSD each spec's camera has straight down from those heights
(its focal length in px: field1080 sees 1.04, 5.2 and 15.6 mm from 1, 5 and 15 m).

The frames this was built against (neither set is shipped: they are not ours; fetch them to rerun):

* ``vision-agh/drone_landing_static``: 75 frames of a small drone over dry and green grass at 0.15
  to 1.9 m, 1280x720, with its ``uav_mask.png``, listed with each frame's own GSD (0.45 to 3.17
  mm, from the 25 cm pad circle's size in px: ``benchmarks/real_ground/agh_grass.csv``;
  ``--real-list benchmarks/real_ground/agh_grass.csv --real-root DIR --real-mask uav_mask.png``,
  DIR holding the three test sets' frames as ``test_setN_image_XXXX.png``).  Earlier runs took
  them all at 3.5 mm (``--real DIR``), two to six times coarser than they are.
* ``omu-geolab/CrackImageDatasetForDeepLearning``: 294 native-resolution 256 px tiles of
  nadir photos of port quay pavement (Autel EVO II Pro, 5472 px wide, at 5, 10 and 15 m:
  1.1, 2.3 and 3.4 mm), listed with their GSDs in ``benchmarks/real_ground/omu_quay.csv``
  (``--real-list benchmarks/real_ground/omu_quay.csv --real-root REPO/BOX``): site h1 is
  asphalt-like aggregate, k1 and o6 concrete.  Every tile was chosen for holding a crack.
"""
from __future__ import annotations

import argparse
import copy
import json
import math
from pathlib import Path

import cv2
import numpy as np

PATCH = 256
SCALES = (1, 5, 15)  # GSD multiples: the real frames' ~1 m, and 5 m and 15 m equivalents


MARGIN = 2  # px inside a patch's border: the filters' reach (block 3 + aperture 3, 5 x 5 maxima)
MIN_PATCH = 16
FRAME_EXTS = (".png", ".jpg", ".jpeg")


def ground_stats(gray: np.ndarray) -> dict:
    """The three statistics of one patch (uint8 or float luma, 0-255), over its pixels at least
    ``MARGIN`` px inside its border (where every filter sees only the patch)."""
    g = gray.astype(np.float32)
    m = np.s_[MARGIN:-MARGIN, MARGIN:-MARGIN]
    lap = float(cv2.Laplacian(g, cv2.CV_32F)[m].var())
    gx, gy = cv2.Sobel(g, cv2.CV_32F, 1, 0), cv2.Sobel(g, cv2.CV_32F, 0, 1)
    grad = float(np.sqrt(gx * gx + gy * gy)[m].mean())
    e = cv2.cornerMinEigenVal(g / 255.0, 3, 3)
    peaks = ((e >= cv2.dilate(e, np.ones((5, 5), np.uint8))) & (e > 0.01))[m]
    return {"laplacian_var": lap, "gradient_mean": grad, "corners": float(peaks.sum()) * (PATCH * PATCH) / peaks.size}


def _patches(gray: np.ndarray, valid: np.ndarray, size: int) -> list:
    out = []
    h, w = gray.shape
    for y in range(0, h - size + 1, size):
        for x in range(0, w - size + 1, size):
            if valid[y:y + size, x:x + size].all():
                out.append(gray[y:y + size, x:x + size])
    return out


def _medians(rows: list) -> dict:
    if not rows:
        return {"patches": 0}
    return {"patches": len(rows), **{k: float(np.median([r[k] for r in rows])) for k in rows[0]}}


def _as_full_patches(patches: list) -> list:
    """Statistics of 256 px patches from ``patches`` of any size (2-D arrays, in frame order):
    each full-size patch as it is; smaller ones pooled in order into groups holding a full patch's
    area (measured ``MARGIN`` px inside each), every statistic the area-weighted mean over the
    group (a mean over a patch's pixels, or a count per 256 x 256 px: what the whole area shows).
    A last group under half that area is dropped."""
    def pooled(group, area):
        return {k: sum(g[k] * w for g, w in group) / area for k in group[0][0]}

    full_area = (PATCH - 2 * MARGIN) ** 2
    rows, group, area = [], [], 0.0
    for q in patches:
        s = ground_stats(q)
        if min(q.shape) >= PATCH:
            rows.append(s)
            continue
        a = float((q.shape[0] - 2 * MARGIN) * (q.shape[1] - 2 * MARGIN))
        group.append((s, a))
        area += a
        if area >= full_area:
            rows.append(pooled(group, area))
            group, area = [], 0.0
    if group and area >= 0.5 * full_area:
        rows.append(pooled(group, area))
    return rows


def ratio_text(value: float, real: float) -> str:
    """``"0.49x"``, or ``"no real reference"`` where the real median is 0 or missing."""
    if not (math.isfinite(real) and real > 0 and math.isfinite(value)):
        return "no real reference"
    return f"{value / real:.2f}x"


def frames_in_folder(folder, gsd_mm: float, kind: str = "") -> list:
    """``(path, gsd_mm, kind)`` of every image in ``folder``."""
    return [(p, float(gsd_mm), kind) for p in sorted(Path(folder).iterdir()) if p.suffix.lower() in FRAME_EXTS]


def frames_in_list(csv_path, root) -> list:
    """``(path, gsd_mm, kind)`` rows of a CSV ``path,gsd_mm,kind`` (a header line; paths relative to
    ``root``).  A missing frame or a bad GSD is an error that names the line."""
    rows = []
    lines = Path(csv_path).read_text().splitlines()
    if not lines or [c.strip() for c in lines[0].split(",")] != ["path", "gsd_mm", "kind"]:
        raise ValueError(f"{csv_path}:1: the first line must be the header path,gsd_mm,kind")
    for i, line in enumerate(lines[1:], start=2):
        if not line.strip() or line.startswith("#"):
            continue
        parts = [c.strip() for c in line.split(",")]
        if len(parts) != 3:
            raise ValueError(f"{csv_path}:{i}: expected path,gsd_mm,kind, got {line!r}")
        path = Path(root) / parts[0]
        try:
            gsd = float(parts[1])
        except ValueError:
            gsd = float("nan")
        if not (math.isfinite(gsd) and gsd > 0):
            raise ValueError(f"{csv_path}:{i}: gsd_mm must be a positive number, got {parts[1]!r}")
        if not path.is_file():
            raise ValueError(f"{csv_path}:{i}: no frame at {path} (is --real-root the folder the list is relative to?)")
        rows.append((path, gsd, parts[2]))
    if not rows:
        raise ValueError(f"{csv_path}: lists no frames")
    return rows


def _ground_gray(path, mask) -> tuple:
    """Luma and ground-validity of one real frame (``None`` if it cannot be read or does not fit the mask)."""
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None or (mask is not None and img.shape[:2] != mask.shape):
        return None
    gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    # paper: large bright regions (thin bright straws are ground and stay)
    paper = cv2.morphologyEx((gray > 180).astype(np.uint8), cv2.MORPH_OPEN, np.ones((15, 15), np.uint8))
    valid = 1 - cv2.dilate(paper, np.ones((15, 15), np.uint8))
    if mask is not None:
        valid &= (mask >= 128).astype(np.uint8)
    return gray, valid


def _at_gsd(gray, valid, gsd_mm: float, target_mm: float, psf_px: float):
    """A frame as a camera of ``target_mm`` would see it (``None`` where that needs finer pixels than
    the frame has): box-downsampled, then blurred by ``psf_px`` in the new pixels."""
    f = target_mm / gsd_mm
    if f < 1 / 1.1:
        return None
    if f < 1.1:
        return gray.astype(np.float32), valid
    size = (int(round(gray.shape[1] / f)), int(round(gray.shape[0] / f)))
    if min(size) < MIN_PATCH:
        return None
    g = cv2.resize(gray.astype(np.float32), size, interpolation=cv2.INTER_AREA)
    if psf_px > 0:
        g = cv2.GaussianBlur(g, (0, 0), psf_px)
    return g, cv2.resize(valid, size, interpolation=cv2.INTER_AREA) > 0.999


def _patch_size(shape) -> int:
    """256 px, or in a frame smaller than that half its shorter side (16 px at least, the whole
    frame at most): several patches per frame, so that a masked corner costs only its own."""
    short = min(shape)
    return PATCH if short >= PATCH else min(short, max(MIN_PATCH, short // 2))


def real_statistics(frames: list, targets_mm, mask_path=None, psf_px: float = 0.0) -> dict:
    """Medians of the statistics over every ground patch of the real ``frames`` (``(path, gsd_mm,
    kind)``), per target GSD (mm): ``{target: medians}``."""
    mask = cv2.imread(str(mask_path), cv2.IMREAD_GRAYSCALE) if mask_path else None
    patches = {t: [] for t in targets_mm}
    for path, gsd, _ in frames:
        gv = _ground_gray(path, mask)
        if gv is None:
            continue
        for t in targets_mm:
            at = _at_gsd(*gv, gsd, t, psf_px)
            if at is None:
                continue
            g, v = at
            patches[t] += _patches(g, v > 0, _patch_size(g.shape))
    return {t: _medians(_as_full_patches(p)) for t, p in patches.items()}


def fit_camera_psf(frames: list, sigmas=np.arange(0.0, 1.51, 0.05)) -> list:
    """The real camera's own blur, from frames of one kind at two or more GSDs: for each pair of
    GSDs at least 1.3x apart, the sigma (px) with which the finer frames, box-downsampled to the
    coarser GSD and blurred, show the coarser frames' median Laplacian variance.  ``[(kind,
    fine_mm, coarse_mm, sigma)]``."""
    out = []
    by = {}
    for p, g, k in frames:
        by.setdefault(k, {}).setdefault(round(g, 3), []).append((p, g, k))
    for kind, groups in sorted(by.items()):
        gsds = sorted(groups)
        for i, fine in enumerate(gsds):
            for coarse in gsds[i + 1:]:
                if coarse / fine < 1.3:
                    continue
                want = real_statistics(groups[coarse], [coarse])[coarse].get("laplacian_var")
                if not want:
                    continue
                got = [real_statistics(groups[fine], [coarse], psf_px=s)[coarse].get("laplacian_var", np.nan)
                       for s in sigmas]
                got = np.asarray(got, float)  # falls as sigma grows: the first sigma at or below the target
                k = int(np.argmax(got <= want)) if (got <= want).any() else len(sigmas) - 1
                if k > 0 and got[k - 1] > want:  # between the two sigmas, in log Laplacian variance
                    a, b = math.log(got[k - 1]), math.log(got[k])
                    s = sigmas[k - 1] + (sigmas[k] - sigmas[k - 1]) * (a - math.log(want)) / (a - b)
                else:
                    s = float(sigmas[k])
                out.append((kind, fine, coarse, float(s)))
    return out


def spec_focal_px(spec_name: str) -> float:
    """The focal length (px, the smaller of fx and fy) of a shipped spec's camera."""
    import yaml

    from render.spec import DatasetSpec

    from .suite import REPO

    d = yaml.safe_load((REPO / "data_specs" / f"{spec_name}.yaml").read_text())
    cam = DatasetSpec.model_validate(d).camera.to_camera()
    return float(min(cam.fx, cam.fy))


# the camera's own processing, left out of the rendered frames compared: the real frames' processing
# (their sensor's noise, sharpening, compression) is averaged away where they are box-downsampled to
# a coarser GSD, so only the optics (lens, defocus, supersampling) are the same on both sides
PROCESSING_OFF = {"shot_noise": [0.0, 0.0], "read_noise": [0.0, 0.0], "sharpen": [0.0, 0.0], "jpeg_quality": None}
DRAWS = 8  # sequences drawn per rendered statistic: a spec draws its light and defocus per sequence


def rendered_statistics(spec_name: str, kind: str, gsd_m: float, views: int = 1, seeds=(0,),
                        processing: bool = False) -> dict:
    """Medians over ground patches of ``views`` nadir frames per seed in ``seeds`` (each seed one
    draw of the spec's sequence: its light, exposure and defocus) of a shipped spec's camera over
    ``kind``, at the height that gives ``gsd_m`` metres per pixel below the camera.  The camera's
    processing (noise, sharpening, JPEG) is left out unless ``processing``: see PROCESSING_OFF."""
    import yaml

    from hvloc.geometry import make_transform
    from render.frames import SequenceRenderer
    from render.spec import DatasetSpec

    from .suite import REPO

    base = yaml.safe_load((REPO / "data_specs" / f"{spec_name}.yaml").read_text())
    rows = []
    for seed in seeds:
        d = copy.deepcopy(base)
        d.update(seed=int(seed), sequences=1)
        d.setdefault("environment", {}).update(ground=[kind], distractors={"boxes": [0, 0], "decoy_patches": [0, 0],
                                                                            "decoy_markers": [0, 0]})
        deg = d.setdefault("degradations", {})
        deg["motion_blur"] = False
        if not processing:
            deg.update(PROCESSING_OFF)
        spec = DatasetSpec.model_validate(d)
        with SequenceRenderer(spec, 0) as r:
            f = float(min(r.camera.fx, r.camera.fy))
            h = gsd_m * f
            R_W_C = np.array([[1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]])  # nadir, image top north
            for i in range(views):
                a = 2 * math.pi * (i / views + 0.37 * int(seed))
                xy = (4.0 + 1.5 * h) * np.array([math.cos(a), math.sin(a)])  # well away from the pad
                cam2world = make_transform(R_W_C, (xy[0], xy[1], h))
                body = cam2world @ np.linalg.inv(r.T_B_C)
                layers = r.render_at(i, 0.0, body, np.eye(4))
                gray = cv2.cvtColor(layers.rgb, cv2.COLOR_RGB2GRAY)
                valid = np.isfinite(layers.depth_m)
                rows += [ground_stats(q) for q in _patches(gray, valid, PATCH)]
    return _medians(rows)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.realism", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--real", help="folder of real downward frames of ground, all at --real-gsd-mm")
    src.add_argument("--real-list", help="CSV path,gsd_mm,kind of real frames (each compared with renders of its kind)")
    p.add_argument("--real-root", default=".", help="the folder --real-list's paths are relative to")
    p.add_argument("--real-mask", help="mask image: pixels < 128 are not ground (the airframe)")
    p.add_argument("--real-gsd-mm", type=float, default=3.5, help="ground sampling distance of the --real frames")
    p.add_argument("--real-psf-px", default="0", help="the real camera's own blur (Gaussian sigma, px) kept when its "
                   "frames are downsampled, or 'fit' (measured from frames of one kind at several GSDs)")
    p.add_argument("--base-gsd-mm", type=float, default=3.5, help="the finest GSD compared; also 5x and 15x it")
    p.add_argument("--heights", type=float, nargs="+", default=None,
                   help="compare at the GSD each spec's camera has from these heights (m) instead")
    p.add_argument("--kinds", nargs="+", default=None, help="rendered ground kinds (default: the list's kinds, "
                   "or grass dry_grass asphalt gravel)")
    p.add_argument("--specs", nargs="+", default=["field1080", "sim800"])
    p.add_argument("--draws", type=int, default=DRAWS, help="sequences of each spec drawn (seeds 0..N-1), one "
                   "view each: its light, exposure and defocus vary per sequence")
    p.add_argument("--processing", action="store_true", help="keep the spec camera's noise, sharpening and JPEG "
                   "in the rendered frames (left out by default: the downsampled real frames have lost theirs)")
    p.add_argument("--out", default="out/realism.json")
    a = p.parse_args(argv)
    try:
        frames = frames_in_list(a.real_list, a.real_root) if a.real_list else frames_in_folder(a.real, a.real_gsd_mm)
    except (OSError, ValueError) as e:
        p.error(str(e))
    if not frames:
        p.error(f"{a.real}: no .png or .jpg frames in it")
    if a.heights is not None and not all(math.isfinite(h) and h > 0 for h in a.heights):
        p.error(f"--heights: positive heights in metres, got {a.heights}")
    if a.heights:
        by_spec = {s: [round(1000.0 * h / spec_focal_px(s), 3) for h in a.heights] for s in a.specs}
    else:
        by_spec = {s: [a.base_gsd_mm * k for k in SCALES] for s in a.specs}
    targets = sorted({t for ts in by_spec.values() for t in ts})
    res = {"targets_mm": targets, "targets_mm_by_spec": by_spec, "heights_m": a.heights, "real": {}, "rendered": {}}
    if a.real_psf_px == "fit":
        fits = fit_camera_psf(frames)
        if not fits:
            p.error("--real-psf-px fit needs frames of one kind at two GSDs at least 1.3x apart")
        for kind, fine, coarse, sig in fits:
            print(f"camera blur ({kind or 'all'}): {fine:.2f} mm frames downsampled to {coarse:.2f} mm show the "
                  f"{coarse:.2f} mm frames' Laplacian variance with sigma {sig:.2f} px")
        psf = float(np.median([f[3] for f in fits]))
        res["psf_fits"] = fits
    else:
        try:
            psf = float(a.real_psf_px)
        except ValueError:
            psf = float("nan")
        if not (math.isfinite(psf) and psf >= 0):
            p.error(f"--real-psf-px: a blur in px (0 or more) or 'fit', got {a.real_psf_px!r}")
    res["real_psf_px"] = psf
    real_kinds = sorted({k for _, _, k in frames})
    kinds = a.kinds or ([k for k in real_kinds if k] or ["grass", "dry_grass", "asphalt", "gravel"])
    keys = ("laplacian_var", "gradient_mean", "corners")
    real = {}
    for rk in real_kinds:
        real[rk] = real_statistics([f for f in frames if f[2] == rk], targets, a.real_mask, psf)
        res["real"][rk or "all"] = {f"{t:g}": v for t, v in real[rk].items()}
        print(f"real frames, {rk or 'all'} (camera blur {psf:.2f} px): " + "; ".join(
            f"{t:g} mm: " + ", ".join(f"{k} {real[rk][t].get(k, float('nan')):.1f}" for k in keys)
            + f" ({real[rk][t]['patches']} patches)" for t in targets))
    print("| camera | ground | GSD (mm) | " + " | ".join(f"{k} (ratio to real)" for k in keys) + " |")
    print("|---|---|---|" + "---|" * len(keys))
    for spec in a.specs:
        for kind in kinds:
            ref = real.get(kind, real.get(""))
            for t in by_spec[spec]:
                r = rendered_statistics(spec, kind, t / 1000.0, seeds=range(a.draws), processing=a.processing)
                res["rendered"][f"{spec}/{kind}/{t:g}"] = r
                rt = ref[t] if ref is not None else {}
                cells = [f"{r.get(k, float('nan')):.1f} ({ratio_text(r.get(k, float('nan')), rt.get(k, float('nan')))})"
                         for k in keys]
                print(f"| {spec} | {kind} | {t:.2f} | " + " | ".join(cells) + " |", flush=True)
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=1) + "\n")
    print(f"written {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
