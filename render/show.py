"""Contact sheets: frames of a sequence with the projected pad outline and the phase drawn on."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from .dataset import Dataset

PHASE_COLORS = {"approaching": (255, 160, 0), "adjustment": (0, 200, 255), "touchdown": (80, 255, 80)}


def annotate(rgb: np.ndarray, corners_px: np.ndarray, text: str, color=(255, 160, 0)) -> np.ndarray:
    img = rgb.copy()
    pts = np.asarray(corners_px, float)
    ok = np.isfinite(pts).all(axis=1)
    s = 16  # drawing with 4 fractional bits keeps sub-pixel positions
    for i in range(4):
        a, b = pts[i], pts[(i + 1) % 4]
        if ok[i] and ok[(i + 1) % 4]:
            cv2.line(img, tuple(np.round(a * s).astype(int)), tuple(np.round(b * s).astype(int)), color, 1,
                     cv2.LINE_AA, shift=4)
    if ok[0]:
        cv2.circle(img, tuple(np.round(pts[0] * s).astype(int)), 3 * s, (255, 0, 0), 1, cv2.LINE_AA, shift=4)
    cv2.putText(img, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 3, cv2.LINE_AA)
    cv2.putText(img, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def contact_sheet(root, seq_id: str | None = None, n_frames: int = 12, out=None, tile_px: int = 320) -> Path:
    ds = Dataset(root)
    seq = ds[seq_id or ds.sequence_ids[0]]
    idx = np.unique(np.linspace(0, len(seq) - 1, n_frames).round().astype(int))
    tiles = []
    for k in idx:
        f = seq.frame(k)
        img = annotate(f.rgb, f.corners_px, f"{seq.id} #{k} t={f.t:.2f}s h={f.height_above_pad:.2f}m {f.phase_gt}",
                       PHASE_COLORS.get(f.phase_gt, (255, 255, 255)))
        scale = tile_px / max(img.shape[:2])
        tiles.append(cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA))
    h = max(t.shape[0] for t in tiles)
    w = max(t.shape[1] for t in tiles)
    cols = 4
    rows = (len(tiles) + cols - 1) // cols
    sheet = np.full((rows * h, cols * w, 3), 30, np.uint8)
    for i, t in enumerate(tiles):
        r, c = divmod(i, cols)
        sheet[r * h:r * h + t.shape[0], c * w:c * w + t.shape[1]] = t
    out = Path(out) if out else Path(root) / "show" / f"{seq.id}.png"
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    return out
