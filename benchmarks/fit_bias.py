"""How far the design fit (:func:`hvloc.texfit.fit_pose_to_design`) puts a dataset's pads from where
they are, started from their labelled poses: its model of the camera alone, without the outline's
start, the gates or the IMU's tilt.

    python -m benchmarks.fit_bias DATASET [--every N] [--response known|unknown] [--json OUT]

Each frame whose whole pad is in view at 16-140 px (the sizes the localizer fits) is fitted from its
labelled ``T_P_C`` with the tilt held there; one row per pad size (:data:`benchmarks.metrics.PAD_PX_BINS`):
the fitted height's signed error (median, % of the height: negative is too near, a pad drawn too
large), its lateral error (median, % of the height), and the blur (px) and sharpening fitted.  What a
row shows is what the fit cannot tell from the camera: its pixel filter, its tone curve and
sharpening (``--response unknown`` fits as if ``camera.json`` gave none), its codec.  A renderer's
pixels that average 3 x 3 samples come out within 0.06 % at every size; ``supersample: 1`` renders,
whose texels OpenGL filters between two mipmap levels, 0.3-0.4 % off at 16-45 px.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from pad_design.errors import ArgumentParser

from benchmarks.metrics import PAD_PX_BINS, pad_px

BINS = tuple(zip(PAD_PX_BINS[:-1], PAD_PX_BINS[1:]))  # 16-20, ..., 64-140 px


def fit_rows(dataset, every: int = 1, response: str = "known") -> list:
    """Per frame fitted: ``(sequence, frame, pad px, height error %, lateral error %, blur px,
    sharpening)``; a frame the fit refused is left out (its reason is not a bias)."""
    from hvloc.synthesis import PadSynthesis
    from hvloc.texfit import HALVED_MAX_SIDE_PX, fit_pose_to_design
    from render.dataset import Dataset

    rows = []
    for seq in dataset if isinstance(dataset, Dataset) else Dataset(dataset):
        px = pad_px(seq.columns)
        drawing = PadSynthesis(seq.pad)
        known = seq.response if response == "known" else None
        for k in range(0, len(seq), max(1, int(every))):
            if not BINS[0][0] <= px[k] < BINS[-1][1]:
                continue
            G = seq.cam2pad_at(k)
            fitted, info = fit_pose_to_design(seq.image(k), seq.camera, drawing, G, known, HALVED_MAX_SIDE_PX)
            if fitted is None:
                continue
            h = float(G[2, 3])
            rows.append((seq.id, k, float(px[k]), 100.0 * (fitted[2, 3] - h) / h,
                         100.0 * float(np.linalg.norm(fitted[:2, 3] - G[:2, 3])) / h,
                         info["blur_px"], info["sharpen"]))
    return rows


def by_size(rows: list) -> list:
    """One dict per :data:`BINS` row with frames: its frames and the medians above."""
    out = []
    for lo, hi in BINS:
        r = [x for x in rows if lo <= x[2] < hi]
        if r:
            a = np.array([x[3:] for x in r], float)
            out.append({"pad_px": f"{lo:g}-{hi:g}", "frames": len(r),
                        "height_err_pct_median": float(np.median(a[:, 0])),
                        "lateral_err_pct_median": float(np.median(a[:, 1])),
                        "blur_px_median": float(np.median(a[:, 2])), "sharpen_median": float(np.median(a[:, 3]))})
    return out


def main(argv=None) -> int:
    p = ArgumentParser(prog="python -m benchmarks.fit_bias", description=__doc__)
    p.add_argument("dataset", help="a generated (or imported) dataset folder")
    p.add_argument("--every", type=int, default=1, help="fit every Nth frame")
    p.add_argument("--response", choices=("known", "unknown"), default="known",
                   help="the camera's response as camera.json gives it (known), or fitted as if it gave none")
    p.add_argument("--json", help="also write the rows here")
    a = p.parse_args(argv)
    if a.every < 1:
        p.error("--every must be at least 1")
    rows = by_size(fit_rows(a.dataset, a.every, a.response))
    print("| pad px | frames | height error % (median) | lateral error % (median) | blur px | sharpening |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['pad_px']} | {r['frames']} | {r['height_err_pct_median']:+.3f} | "
              f"{r['lateral_err_pct_median']:.3f} | {r['blur_px_median']:.2f} | {r['sharpen_median']:.2f} |")
    if not rows:
        print(f"(no frame with the whole pad in view at {BINS[0][0]:g}-{BINS[-1][1]:g} px)")
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
