"""Sub-pixel image features shared by the localizer's phases and by the tests.

:func:`refine_quad` places the corners of a dark-on-light (or light-on-dark) quadrilateral to
a small fraction of a pixel: along each side it finds where the intensity crosses halfway
between the two sides' plateaus (unbiased for any symmetric blur: defocus, texture filtering,
antialiasing), fits a straight line to those edge points (after undistorting them, so that
straight 3D edges stay straight under lens distortion), and intersects neighbouring lines.
"""
from __future__ import annotations

import cv2
import numpy as np

from .geometry import Camera


def _line_fit(pts: np.ndarray):
    """Total-least-squares line through points: (point, unit direction, rms residual)."""
    c = pts.mean(axis=0)
    u, s, vt = np.linalg.svd(pts - c, full_matrices=False)
    d = vt[0]
    resid = (pts - c) @ vt[1]
    return c, d, float(np.sqrt(np.mean(resid * resid)))


def _intersect(p1, d1, p2, d2):
    A = np.column_stack([d1, -d2])
    if abs(np.linalg.det(A)) < 1e-9:
        return None
    s = np.linalg.solve(A, p2 - p1)
    return p1 + s[0] * d1


def _distort_px(camera: Camera, px_und: np.ndarray) -> np.ndarray:
    xy = np.column_stack([(px_und[:, 0] - camera.cx) / camera.fx, (px_und[:, 1] - camera.cy) / camera.fy])
    xy = camera.distort_normalized(xy)
    return np.column_stack([xy[:, 0] * camera.fx + camera.cx, xy[:, 1] * camera.fy + camera.cy])


def side_samples(a, b, camera: Camera | None = None, n_max: int = 40, trim: float = 0.2):
    """Sample points and unit normals along the image of the straight segment a->b (pixels).

    Without distortion that is the segment itself; with it, the curve the straight 3D edge
    makes: points are spaced along the undistorted segment and mapped through the lens."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    L = float(np.linalg.norm(b - a))
    if not np.isfinite(L) or L < 3:
        return np.zeros((0, 2)), np.zeros((0, 2))
    m = int(np.clip(L * (1 - 2 * trim), 2, n_max))
    s = np.linspace(trim, 1 - trim, m)[:, None]
    if camera is None or not camera.has_distortion:
        d = (b - a) / L
        return a + s * (b - a), np.tile([-d[1], d[0]], (m, 1))
    ua, ub = camera.undistort_pixels(np.stack([a, b]))
    p = ua + s * (ub - ua)
    eps = 0.5 * (ub - ua) / max(np.linalg.norm(ub - ua), 1e-9)
    pts, p1, p0 = _distort_px(camera, p), _distort_px(camera, p + eps), _distort_px(camera, p - eps)
    d = p1 - p0
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return pts, np.column_stack([-d[:, 1], d[:, 0]])


def edge_points(gray: np.ndarray, pts: np.ndarray, normals: np.ndarray, half_width: float,
                step: float = 0.25) -> np.ndarray:
    """Sub-pixel edge points near ``pts`` along ``normals``: where each intensity profile crosses
    halfway between its two plateaus (the crossing nearest the start).  ``(M, 2)``, may be empty."""
    if len(pts) == 0:
        return np.zeros((0, 2))
    r = np.arange(-half_width, half_width + 1e-9, step)
    P = pts[:, None, :] + r[None, :, None] * normals[:, None, :]
    prof = cv2.remap(gray, P[..., 0].astype(np.float32), P[..., 1].astype(np.float32), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)
    k = max(1, len(r) // 6)
    lo = prof[:, :k].mean(axis=1)
    hi = prof[:, -k:].mean(axis=1)
    contrast = hi - lo
    mid = 0.5 * (lo + hi)
    thr = max(4.0, 0.25 * float(np.median(np.abs(contrast))))
    v = (prof - mid[:, None]) * np.sign(contrast)[:, None]
    # upward crossings of the mid level; keep the one nearest the profile's centre
    cross = (v[:, :-1] < 0) & (v[:, 1:] >= 0) & (np.abs(contrast) >= thr)[:, None]
    if not cross.any():
        return np.zeros((0, 2))
    dist = np.where(cross, np.abs(r[:-1])[None, :], np.inf)
    j = np.argmin(dist, axis=1)
    rows = np.nonzero(np.isfinite(dist[np.arange(len(j)), j]))[0]
    j = j[rows]
    a, b = v[rows, j], v[rows, j + 1]
    frac = a / (a - b)
    off = r[j] + frac * step
    return pts[rows] + off[:, None] * normals[rows]


def refine_quad(gray: np.ndarray, quad_px, half_width: float = 3.0, camera: Camera | None = None,
                min_points: int = 4):
    """Refine 4 corners (in order around the quad) of a quadrilateral seen in ``gray``.

    Returns ``(corners (4, 2) float64, rms line residual px)`` or ``(None, inf)`` when a side
    has too few edge points.  With ``camera``, lines are fitted in undistorted pixels and the
    intersections mapped back, so corners stay exact under lens distortion.
    """
    g = gray.astype(np.float32) if gray.dtype != np.float32 else gray
    q = np.asarray(quad_px, np.float64).reshape(4, 2)
    lines, res = [], []
    for i in range(4):
        pts = edge_points(g, *side_samples(q[i], q[(i + 1) % 4], camera), half_width)
        if len(pts) < min_points:
            return None, float("inf")
        if camera is not None and camera.has_distortion:
            pts = camera.undistort_pixels(pts)
        # reject outliers (a texture edge crossing the profile) by one re-fit
        c, d, r = _line_fit(pts)
        dist = np.abs((pts - c) @ np.array([-d[1], d[0]]))
        keep = dist < max(3 * np.median(dist) + 1e-3, 0.3)
        if keep.sum() >= min_points:
            c, d, r = _line_fit(pts[keep])
        lines.append((c, d))
        res.append(r)
    out = np.zeros((4, 2))
    for i in range(4):
        p = _intersect(*lines[(i - 1) % 4], *lines[i])
        if p is None:
            return None, float("inf")
        out[i] = p
    if camera is not None and camera.has_distortion:
        out = _distort_px(camera, out)
    return out, float(np.sqrt(np.mean(np.square(res))))
