"""How much detail the rendered ground shows, against real downward frames at the same ground
sampling distance (GSD).

    python -m benchmarks.realism --real DIR [--real-mask MASK.png] [--real-gsd-mm 3.5]
                                 [--kinds grass dry_grass asphalt ...] [--out FILE.json]

Statistics per 256 x 256 ground-only patch (luma 0-255), medians over patches:

* ``laplacian_var``: variance of the 3x3 Laplacian;
* ``gradient_mean``: mean Sobel gradient magnitude;
* ``corners``: strong corners per 256 x 256 px: local maxima (5 x 5) of the minimum eigenvalue
  (``cv2.cornerMinEigenVal``, block 3, aperture 3, luma in [0, 1]) above 0.01.

Real frames: any folder of downward images of ground (patches holding bright paper, or pixels
outside ``--real-mask``, e.g. the airframe, are skipped), taken at ``--real-gsd-mm``.  Their
statistics at coarser GSDs come from the same frames box-downsampled (what a camera higher up
would see, noise apart).  Rendered frames: a camera of a shipped spec looking straight down
from the height that gives each GSD, far from the pad, with the spec's own image formation.

The frames this was built against: the 76 frames of ``vision-agh/drone_landing_static`` (a small
drone over dry grass at 0.2 to 1.5 m, 1280x720, its ``uav_mask.png``).  They are not shipped
with hvloc (they are not ours); fetch that repository to rerun.
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import cv2
import numpy as np

PATCH = 256
SCALES = (1, 5, 15)  # GSD multiples: the real frames' ~1 m, and 5 m and 15 m equivalents


def ground_stats(gray: np.ndarray) -> dict:
    """The three statistics of one patch (uint8 or float luma, 0-255)."""
    g = gray.astype(np.float32)
    lap = float(cv2.Laplacian(g, cv2.CV_32F).var())
    gx, gy = cv2.Sobel(g, cv2.CV_32F, 1, 0), cv2.Sobel(g, cv2.CV_32F, 0, 1)
    grad = float(np.sqrt(gx * gx + gy * gy).mean())
    e = cv2.cornerMinEigenVal(g / 255.0, 3, 3)
    peaks = (e >= cv2.dilate(e, np.ones((5, 5), np.uint8))) & (e > 0.01)
    return {"laplacian_var": lap, "gradient_mean": grad, "corners": float(peaks.sum()) * (PATCH * PATCH) / g.size}


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


def ratio_text(value: float, real: float) -> str:
    """``"0.49x"``, or ``"no real reference"`` where the real median is 0 or missing (the real
    frames box-downsampled 15x leave 24 px patches with no strong corner at all: no ratio to it)."""
    if not (math.isfinite(real) and real > 0 and math.isfinite(value)):
        return "no real reference"
    return f"{value / real:.2f}x"


def real_statistics(folder, mask_path=None, scales=SCALES) -> dict:
    """Medians of the statistics over every ground patch of the real frames, per GSD multiple."""
    paths = sorted(p for p in Path(folder).iterdir() if p.suffix.lower() in (".png", ".jpg", ".jpeg"))
    mask = cv2.imread(str(mask_path), cv2.IMREAD_GRAYSCALE) if mask_path else None
    rows = {s: [] for s in scales}
    for p in paths:
        img = cv2.imread(str(p), cv2.IMREAD_COLOR)
        if img is None or (mask is not None and img.shape[:2] != mask.shape):
            continue
        gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        # paper: large bright regions (thin bright straws are ground and stay)
        paper = cv2.morphologyEx((gray > 180).astype(np.uint8), cv2.MORPH_OPEN, np.ones((15, 15), np.uint8))
        valid = 1 - cv2.dilate(paper, np.ones((15, 15), np.uint8))
        if mask is not None:
            valid &= (mask >= 128).astype(np.uint8)
        for s in scales:
            g, v = gray, valid
            if s > 1:
                size = (gray.shape[1] // s, gray.shape[0] // s)
                g = cv2.resize(gray, size, interpolation=cv2.INTER_AREA)
                v = cv2.resize(valid, size, interpolation=cv2.INTER_AREA)
            size = min(PATCH, g.shape[0] // 2 if s > 1 else PATCH)
            rows[s] += [ground_stats(q) for q in _patches(g, v > 0.999, size)]
    return {s: _medians(r) for s, r in rows.items()}


def rendered_statistics(spec_name: str, kind: str, gsd_m: float, views: int = 4, seed: int = 0) -> dict:
    """Medians over ground patches of ``views`` nadir frames of a shipped spec's camera over
    ``kind`` at the height that gives ``gsd_m`` metres per pixel below the camera."""
    import yaml

    from hvloc.geometry import make_transform
    from render.frames import SequenceRenderer
    from render.spec import DatasetSpec

    from .suite import REPO

    d = yaml.safe_load((REPO / "data_specs" / f"{spec_name}.yaml").read_text())
    d.update(seed=seed, sequences=1)
    d.setdefault("environment", {}).update(ground=[kind], distractors={"boxes": [0, 0], "decoy_patches": [0, 0],
                                                                        "decoy_markers": [0, 0]})
    d.setdefault("degradations", {})["motion_blur"] = False
    spec = DatasetSpec.model_validate(d)
    rows = []
    with SequenceRenderer(spec, 0) as r:
        f = float(min(r.camera.fx, r.camera.fy))
        h = gsd_m * f
        R_W_C = np.array([[1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]])  # nadir, image top north
        for i in range(views):
            a = 2 * math.pi * i / views
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
    p.add_argument("--real", required=True, help="folder of real downward frames of ground")
    p.add_argument("--real-mask", help="mask image: pixels < 128 are not ground (the airframe)")
    p.add_argument("--real-gsd-mm", type=float, default=3.5, help="ground sampling distance of the real frames")
    p.add_argument("--kinds", nargs="+", default=["grass", "dry_grass", "asphalt", "gravel"])
    p.add_argument("--specs", nargs="+", default=["field1080", "sim800"])
    p.add_argument("--out", default="out/realism.json")
    a = p.parse_args(argv)
    real = real_statistics(a.real, a.real_mask)
    res = {"real": {str(k): v for k, v in real.items()}, "real_gsd_mm": a.real_gsd_mm, "rendered": {}}
    keys = ("laplacian_var", "gradient_mean", "corners")
    print(f"real frames ({a.real}): " + "; ".join(
        f"x{s}: " + ", ".join(f"{k} {real[s].get(k, float('nan')):.1f}" for k in keys) + f" ({real[s]['patches']} patches)"
        for s in SCALES))
    print("| camera | ground | GSD (mm) | " + " | ".join(f"{k} (ratio to real)" for k in keys) + " |")
    print("|---|---|---|" + "---|" * len(keys))
    for spec in a.specs:
        for kind in a.kinds:
            for s in SCALES:
                gsd = a.real_gsd_mm * s / 1000.0
                r = rendered_statistics(spec, kind, gsd)
                res["rendered"][f"{spec}/{kind}/x{s}"] = r
                cells = [f"{r.get(k, float('nan')):.1f} ({ratio_text(r.get(k, float('nan')), real[s].get(k, float('nan')))})"
                         for k in keys]
                print(f"| {spec} | {kind} | {1000 * gsd:.1f} | " + " | ".join(cells) + " |", flush=True)
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=1) + "\n")
    print(f"written {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
