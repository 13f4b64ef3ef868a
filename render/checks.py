"""Images checked against their labels: does the labelled pose explain the pixels?

For a frame, every pixel's ray is intersected with the pad plane at the labelled pose, and the
pad texture (``pad.png``, prefiltered to about one texel per pixel) is read there: that is what
the image must show where the pad is.  The pad is split into cells; in each cell the image's luma
is correlated (normalised cross-correlation, so lighting, gain and tone curve do not matter) with
the template at integer shifts of up to ``MAX_SHIFT_PX``.  A cell *matches* when its best
correlation is high and its best shift is zero: the labels are right to about half a pixel
there.  Cells hidden by something (occlusion) or in shadow edges may fail; a frame fails when
fewer cells match than its visible share of the pad allows for.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

CELLS = 4                 # the pad is split into CELLS x CELLS cells
MAX_SHIFT_PX = 2
MIN_NCC = 0.6
MIN_CELL_PX = 150         # a cell needs this many pixels (inside the image, away from the pad's edge)
MIN_PAD_PX = 60           # frames where the pad is smaller than this across are not tested
MAX_BLUR_PX = 1.5         # nor frames blurred more than this


class _TexturePyramid:
    def __init__(self, rgb: np.ndarray, ppm: float):
        gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(np.float32)
        self.levels, self.ppm = [gray], ppm
        while min(self.levels[-1].shape) > 16:
            g = self.levels[-1]
            h2, w2 = g.shape[0] // 2, g.shape[1] // 2
            self.levels.append(cv2.resize(g[:2 * h2, :2 * w2], (w2, h2), interpolation=cv2.INTER_AREA))

    def sample(self, x_m: np.ndarray, y_m: np.ndarray, side_m: float, texels_per_px: float) -> np.ndarray:
        level = int(np.clip(math.floor(math.log2(max(texels_per_px, 1.0))), 0, len(self.levels) - 1))
        ppm = self.ppm / 2**level
        u = ((x_m + side_m / 2) * ppm - 0.5).astype(np.float32)
        v = ((side_m / 2 - y_m) * ppm - 0.5).astype(np.float32)
        return cv2.remap(self.levels[level], u, v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def pad_template(camera, pad, cam2pad: np.ndarray, pyramid: _TexturePyramid | None = None, row_pose=None,
                 band: int = 8) -> tuple:
    """``(template luma (H, W) float32, pad x (H, W), pad y (H, W))``: what a camera at ``cam2pad``
    sees of the pad at each pixel (NaN coordinates where the ray misses the pad plane).  With a
    rolling shutter, ``row_pose(row) -> T_P_C`` gives each band of ``band`` rows its own pose."""
    H, W = camera.height, camera.width
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    xy = camera.normalized_from_pixels(np.column_stack([u.ravel(), v.ravel()])).reshape(H, W, 2)
    X, Y = np.full((H, W), np.nan), np.full((H, W), np.nan)
    for r0 in range(0, H, band if row_pose is not None else H):
        r1 = min(H, r0 + (band if row_pose is not None else H))
        T = row_pose((r0 + r1 - 1) / 2) if row_pose is not None else cam2pad
        R, t = T[:3, :3], T[:3, 3]
        d = np.concatenate([xy[r0:r1], np.ones((r1 - r0, W, 1))], axis=2) @ R.T
        with np.errstate(divide="ignore", invalid="ignore"):
            s = -t[2] / d[..., 2]
        s[~(s > 0)] = np.nan
        X[r0:r1] = t[0] + s * d[..., 0]
        Y[r0:r1] = t[1] + s * d[..., 1]
    pyramid = pyramid or _TexturePyramid(pad.texture_rgb, pad.ppm)
    gsd = max(float(t[2]), 1e-3) / min(camera.fx, camera.fy)  # metres per pixel below the camera
    tmpl = pyramid.sample(np.nan_to_num(X), np.nan_to_num(Y), pad.side_m, gsd * pad.ppm)
    return tmpl, X, Y


def cell_matches(gray: np.ndarray, tmpl: np.ndarray, X: np.ndarray, Y: np.ndarray, side_m: float,
                 margin_m: float) -> list:
    """``[(best ncc, best shift (dx, dy)), ...]`` for each testable cell of the pad."""
    h = side_m / 2 - margin_m
    inside = np.isfinite(X) & (np.abs(X) < h) & (np.abs(Y) < h)
    b = MAX_SHIFT_PX
    inside[:b, :] = inside[-b:, :] = False
    inside[:, :b] = inside[:, -b:] = False
    cell = np.full(X.shape, -1, np.int32)
    ix = np.floor((X + h) / (2 * h) * CELLS)
    iy = np.floor((Y + h) / (2 * h) * CELLS)
    cell[inside] = (np.clip(iy[inside], 0, CELLS - 1) * CELLS + np.clip(ix[inside], 0, CELLS - 1)).astype(np.int32)
    g = gray.astype(np.float32)
    out = []
    for c in range(CELLS * CELLS):
        ys, xs = np.nonzero(cell == c)
        if len(ys) < MIN_CELL_PX:
            continue
        if np.mean(g[ys, xs] >= 250) > 0.3:  # blown out (glare): nothing left to correlate with
            continue
        t = tmpl[ys, xs]
        t = t - t.mean()
        tn = float(np.sqrt(t @ t))
        if tn < 1e-6 * len(t) or t.std() < 2.0:  # no texture to correlate with
            continue
        best = (-1.0, (0, 0))
        for dy in range(-b, b + 1):
            for dx in range(-b, b + 1):
                a = g[ys + dy, xs + dx]
                a = a - a.mean()
                an = float(np.sqrt(a @ a))
                ncc = float(a @ t) / (an * tn) if an > 1e-6 else 0.0
                if ncc > best[0]:
                    best = (ncc, (dx, dy))
        out.append(best)
    return out


def check_image(camera, pad, cam2pad: np.ndarray, rgb: np.ndarray, visible_fraction: float, pyramid=None,
                row_pose=None) -> tuple:
    """``(matched cells, tested cells, required)``: does ``rgb`` show ``pad`` as a camera at
    ``cam2pad`` would see it?  ``visible_fraction``: the share of the pad the labels say is seen;
    ``row_pose``: each row's pose, for a rolling shutter."""
    tmpl, X, Y = pad_template(camera, pad, cam2pad, pyramid, row_pose)
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    px_per_m = min(camera.fx, camera.fy) / max(float(cam2pad[2, 3]), 1e-3)
    res = cell_matches(gray, tmpl, X, Y, pad.side_m, margin_m=3.0 / px_per_m)
    matched = sum(1 for ncc, s in res if ncc >= MIN_NCC and s == (0, 0))
    return matched, len(res), math.ceil(0.5 * visible_fraction * len(res))


def frame_check(seq, k: int, pyramid=None) -> tuple:
    """:func:`check_image` for frame ``k`` of a dataset sequence."""
    f = seq.frame(k)
    row_pose = None
    if seq.line_s > 0:
        row_pose = lambda r: seq.pose_at(f.t + (r - seq.ref_row) * seq.line_s)  # noqa: E731
    return check_image(seq.camera, seq.pad, f.cam2pad, seq.image(k), float(seq.columns["pad_visible_fraction"][k]),
                       pyramid, row_pose)


def testable_frames(seq, max_frames: int = 6) -> list:
    """Frames sharp and near enough for the check, spread over the sequence."""
    c = seq.columns
    px_across = seq.pad.side_m * min(seq.camera.fx, seq.camera.fy) / np.maximum(c["height_above_pad"], 1e-3)
    ok = (c["blur_px"] <= MAX_BLUR_PX) & (c["pad_visible_fraction"] >= 0.5) & (px_across >= MIN_PAD_PX)
    idx = np.nonzero(ok)[0]
    if len(idx) <= max_frames:
        return [int(i) for i in idx]
    return [int(idx[i]) for i in np.linspace(0, len(idx) - 1, max_frames).round().astype(int)]


def image_label_problems(seq, max_frames: int = 6) -> list:
    """Frames whose image does not show the pad where its labels put it (empty: all agree)."""
    from pad_design.errors import InputError

    out = []
    pyramid = _TexturePyramid(seq.pad.texture_rgb, seq.pad.ppm)
    for k in testable_frames(seq, max_frames):
        try:
            matched, tested, required = frame_check(seq, k, pyramid)
        except InputError as err:
            out.append(f"frame {k}: {err}")
            continue
        if tested and matched < required:
            out.append(f"frame {k}: the image does not show the pad at its labelled pose "
                       f"({matched} of {tested} pad cells match, {required} needed)")
    return out

