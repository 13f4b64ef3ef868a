"""How far a blur that the localizer does not model moves what it measures: the pad's outline
(its corners, hence the height) and the texture's drawing (:mod:`hvloc.synthesis`, its scale).

    python -m benchmarks.blur_bias [--sizes 40 80 150 250] [--sigmas 0 1 2 3] [--smears 8 16]
                                   [--views 4] [--json OUT]

A soft lens (defocus) blurs every edge alike, by a Gaussian; motion by a box along its direction.
Past 5 px of smear (:data:`hvloc.phases.SMEARED_PX`, read in luma as the field edge's width, about
3 times a Gaussian's sigma) the outline's sides are placed by the border's blurred profile, fitted
where the border is smeared over no more than its width, else by its centroid; below, by an edge
fit (in light past 3 px).  Each row: exact views (``render.planar.warp_pad_view``, a 1280x720 90 degree
pinhole, the pad nadir within 3 degrees, random yaw and offset) at one pad size (px across) under
one Gaussian blur, then

- the outline (:func:`hvloc.phases.find_outline`): the mean of its corners' radial errors over the
  views (% of the half side: a pad read that much larger puts the camera that much lower), their
  spread over the views, the smear it read and how many views it placed as smeared;
- the drawing, predicted 7 % too near and 7 % too far (the drone's velocity unknown: no smear
  drawn): its scale error (%, median over the poses given) and how many of the tries were refused.

The same rows for motion (``--smears``): a straight smear of that many px (a box along one
direction, 30 degrees from the image's rows), so that the placement is held against both kernels.  Deterministic (a seed per row).  A few
seconds per row on one core.
"""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

import cv2
import numpy as np

from pad_design.errors import ArgumentParser

SIZES_PX = (40, 80, 150, 250)
SIGMAS_PX = (0.0, 1.0, 2.0, 3.0)
SMEARS_PX = (8.0, 16.0)
SMEAR_ANGLE_DEG = 30.0
PREDICTION_OFF = 0.07  # the drawing's predictions: this share too near, and too far


def _views(pad, camera, side_px: float, n: int, seed: int) -> list:
    """``[cam2pad, ...]``: ``n`` nadir views (within 3 degrees) whose pad spans ``side_px`` at its centre."""
    from hvloc.geometry import so3_exp
    from render.planar import nadir_cam2pad

    rng = np.random.default_rng(seed)
    h = camera.fx * pad.side_m / side_px
    out = []
    for _ in range(n):
        G = nadir_cam2pad(rng.uniform(-0.1, 0.1) * h, rng.uniform(-0.1, 0.1) * h, h, rng.uniform(0.0, 2 * math.pi))
        G[:3, :3] = G[:3, :3] @ so3_exp(np.radians(rng.uniform(-3.0, 3.0, 3)))
        out.append(G)
    return out


def in_linear_light(img: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """8-bit sRGB ``img`` filtered by ``kernel`` in linear light (a lens and an exposure both mix
    light, not encoded values; :mod:`render.imaging` blurs its frames so), back to 8-bit sRGB."""
    from hvloc.features import linear_to_srgb, srgb_to_linear

    return linear_to_srgb(cv2.filter2D(srgb_to_linear(img), -1, kernel / kernel.sum(), borderType=cv2.BORDER_REPLICATE))


def defocused(img: np.ndarray, sigma_px: float) -> np.ndarray:
    """``img`` under a Gaussian lens blur of ``sigma_px`` (in linear light, as rendered)."""
    g = cv2.getGaussianKernel(2 * int(math.ceil(3 * sigma_px)) + 1, sigma_px)
    return in_linear_light(img, g @ g.T)


def smeared(img: np.ndarray, length_px: float, angle_deg: float = SMEAR_ANGLE_DEG) -> np.ndarray:
    """``img`` smeared along a line ``length_px`` long at ``angle_deg`` from its rows (a box kernel,
    in linear light, as motion during an exposure averages light)."""
    n = int(math.ceil(length_px)) * 2 + 3
    k = np.zeros((n, n), np.float32)
    d = np.array([math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))])
    for t in np.linspace(-length_px / 2, length_px / 2, 8 * n):  # (the kernel drawn with subpixel weights)
        x, y = n // 2 + t * d
        x0, y0 = int(math.floor(x)), int(math.floor(y))
        fx, fy = x - x0, y - y0
        k[y0, x0] += (1 - fx) * (1 - fy)
        k[y0, x0 + 1] += fx * (1 - fy)
        k[y0 + 1, x0] += (1 - fx) * fy
        k[y0 + 1, x0 + 1] += fx * fy
    return in_linear_light(img, k)


def radial_error_pct(quad_px: np.ndarray, truth_px: np.ndarray) -> float:
    """Mean over the corners of ``quad_px`` of how much further from the true quad's centre each lies
    than the true corner nearest it, in % of half the true quad's mean side."""
    c = truth_px.mean(axis=0)
    r = [np.linalg.norm(p - c) - np.linalg.norm(truth_px[np.argmin(np.linalg.norm(truth_px - p, axis=1))] - c)
         for p in quad_px]
    half = 0.5 * float(np.mean(np.linalg.norm(np.roll(truth_px, -1, axis=0) - truth_px, axis=1)))
    return 100.0 * float(np.mean(r)) / half


def drawn_scale(det, camera, cam2pad) -> float:
    """How much larger than at the true pose the drawing's points lie (spread about their centre)."""
    truth = camera.project_from(cam2pad, det.pts_P)
    return float(np.mean(np.linalg.norm(det.px - det.px.mean(axis=0), axis=1))
                 / np.mean(np.linalg.norm(truth - truth.mean(axis=0), axis=1)))


def measure(side_px: float, sigma_px: float, views: int = 4, pad=None, camera=None, smear_px: float = 0.0) -> dict:
    """One row (see the module's doc) for pads ``side_px`` across under a Gaussian blur of ``sigma_px``
    (and a straight smear of ``smear_px``, :func:`smeared`, when given)."""
    from hvloc.geometry import Camera
    from hvloc.phases import SMEARED_PX, find_outline
    from hvloc.synthesis import PadSynthesis
    from pad_design import make_pad
    from render.planar import warp_pad_view

    pad = pad or make_pad()
    camera = camera or Camera.from_hfov(1280, 720, math.radians(90.0))
    geo = pad.geometry
    synth = PadSynthesis(pad)
    errs, smears, refused, scales, why = [], [], 0, [], {}
    for G in _views(pad, camera, side_px, views, seed=int(1000 * side_px + 10 * sigma_px + smear_px)):
        img = warp_pad_view(pad, camera, G, (110, 105, 90))
        if sigma_px > 0:
            img = defocused(img, sigma_px)
        if smear_px > 0:
            img = smeared(img, smear_px)
        found, _ = find_outline(img, geo, camera)
        if found is not None:
            used, P = (found.field_px, geo.field_corners) if found.field_px is not None else (found.quad_px,
                                                                                               geo.outer_corners)
            errs.append(radial_error_pct(used, camera.project_from(G, np.c_[P[:, :2], np.zeros(4)])))
            smears.append(found.smear_px)
        gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
        for s in (1.0 - PREDICTION_OFF, 1.0 + PREDICTION_OFF):
            pred = G.copy()
            pred[:3, 3] *= s
            det, reason = synth.locate(gray, camera, pred, None, None, 0.0)
            if det is None:
                refused += 1
                key = re.sub(r"\d+(\.\d+)?", "#", reason.split("(")[0].strip())  # (by kind, not by number)
                why[key] = why.get(key, 0) + 1
            else:
                scales.append(100.0 * (drawn_scale(det, camera, G) - 1.0))
    e = np.array(errs)
    return {"side_px": side_px, "sigma_px": sigma_px, "smear_px": smear_px, "views": views, "outlines": len(errs),
            "outline_radial_pct_mean": float(e.mean()) if len(e) else None,
            "outline_radial_pct_spread": float(e.max() - e.min()) if len(e) else None,
            "smear_px_median": float(np.median(smears)) if smears else None,
            "smear_placed": int(np.sum(np.array(smears) > SMEARED_PX)),
            "drawn": len(scales), "drawn_scale_pct_median": float(np.median(scales)) if scales else None,
            "drawn_scale_pct_worst": float(max(scales, key=abs)) if scales else None,
            "drawing_refused": refused, "drawing_refused_why": why}


def _f(v, fmt="{:+.2f}") -> str:
    return "-" if v is None else fmt.format(v)


def main(argv=None) -> int:
    p = ArgumentParser(prog="python -m benchmarks.blur_bias", description=__doc__)
    p.add_argument("--sizes", nargs="+", type=float, default=list(SIZES_PX), help="pad sizes, px across")
    p.add_argument("--sigmas", nargs="+", type=float, default=list(SIGMAS_PX), help="Gaussian blurs, px")
    p.add_argument("--smears", nargs="+", type=float, default=list(SMEARS_PX),
                   help="straight motion smears, px (0 for none)")
    p.add_argument("--views", type=int, default=4, help="views per row")
    p.add_argument("--json", help="also write the rows here")
    a = p.parse_args(argv)
    if a.views < 1 or any(s <= 0 for s in a.sizes) or any(s < 0 for s in a.sigmas + a.smears):
        p.error("--views must be at least 1, --sizes positive, --sigmas and --smears not negative")
    print("| pad px | blur | outlines | outline radial error % (mean) | spread over views | smear read px "
          "| placed as smeared | drawn | drawn scale error % (median, worst) | drawing refused |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    blurs = [(s, 0.0) for s in a.sigmas] + [(0.0, m) for m in a.smears if m > 0]
    for size in a.sizes:
        for sigma, smear in blurs:
            r = measure(size, sigma, a.views, smear_px=smear)
            rows.append(r)
            refused = ", ".join(f"{n} {k}" for k, n in sorted(r["drawing_refused_why"].items())) or "0"
            kind = f"smear {smear:g} px" if smear else f"Gaussian {sigma:g} px"
            print(f"| {size:g} | {kind} | {r['outlines']}/{r['views']} | {_f(r['outline_radial_pct_mean'])} | "
                  f"{_f(r['outline_radial_pct_spread'], '{:.2f}')} | {_f(r['smear_px_median'], '{:.1f}')} | "
                  f"{r['smear_placed']} | {r['drawn']}/{2 * r['views']} | {_f(r['drawn_scale_pct_median'])}, "
                  f"{_f(r['drawn_scale_pct_worst'])} | {refused} |", flush=True)
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
