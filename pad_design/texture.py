"""Rasterise a pad to an RGB texture with exact, antialiased edges.

Every geometric feature (border, cue, marker squares, checker cells) is an axis-aligned
rectangle painted by its exact area coverage of each pixel, so edges land where ``pad.json``
says to a small fraction of a pixel.  The random field texture (multi-scale polygons) is drawn
supersampled; its black blobs have their holes filled, so it never forms a contour nest.

Pixel convention (OpenCV): pixel (col j, row i) has its centre at pad coordinates
``x = (j + 0.5) / ppm - side/2``, ``y = side/2 - (i + 0.5) / ppm``.
"""
from __future__ import annotations

import math
import os

import cv2
import numpy as np

from .geometry import Marker, PadGeometry
from .spec import PadSpec

WHITE = (255.0, 255.0, 255.0)
BLACK = (0.0, 0.0, 0.0)
TEXTURE_SUPERSAMPLE = 3


def pad_to_pixels(xy, side_m: float, ppm: float) -> np.ndarray:
    """Pad-frame ``(N, 2)`` metres -> texture pixel coordinates (OpenCV convention)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    h = side_m / 2.0
    return np.column_stack([(xy[:, 0] + h) * ppm - 0.5, (h - xy[:, 1]) * ppm - 0.5])


def texture_to_pad(side_m: float, ppm: float) -> np.ndarray:
    """3x3 affine: texture pixel (OpenCV centres) -> pad-frame (x, y) metres (:func:`pad_to_pixels`'
    inverse as a matrix; ``ppm`` of a pyramid level maps that level's texels)."""
    h = side_m / 2.0
    return np.array([[1.0 / ppm, 0.0, 0.5 / ppm - h], [0.0, -1.0 / ppm, h - 0.5 / ppm], [0.0, 0.0, 1.0]])


def pixels_to_pad(px, side_m: float, ppm: float) -> np.ndarray:
    """Texture pixel coordinates ``(N, 2)`` (OpenCV convention) -> pad-frame metres; the inverse of
    :func:`pad_to_pixels`."""
    px = np.asarray(px, dtype=np.float64).reshape(-1, 2)
    h = side_m / 2.0
    return np.column_stack([(px[:, 0] + 0.5) / ppm - h, h - (px[:, 1] + 0.5) / ppm])


class _Canvas:
    def __init__(self, side_m: float, ppm: float):
        self.n = int(round(side_m * ppm))
        self.ppm = self.n / side_m
        self.h = side_m / 2.0
        self.img = np.zeros((self.n, self.n, 3), np.float32)

    def _cov(self, a0: float, a1: float):
        """1D coverage of [a0, a1] (metres from the left/top edge) -> (start index, weights)."""
        p0, p1 = a0 * self.ppm, a1 * self.ppm
        i0, i1 = max(int(math.floor(p0)), 0), min(int(math.ceil(p1)), self.n)
        idx = np.arange(i0, i1, dtype=np.float64)
        w = np.clip(np.minimum(idx + 1, p1) - np.maximum(idx, p0), 0.0, 1.0)
        return i0, w.astype(np.float32)

    def rect(self, x0: float, y0: float, x1: float, y1: float, color) -> None:
        """Paint the pad-frame rectangle [x0, x1] x [y0, y1] with exact coverage."""
        c0, wx = self._cov(x0 + self.h, x1 + self.h)
        r0, wy = self._cov(self.h - y1, self.h - y0)
        if wx.size == 0 or wy.size == 0:
            return
        a = wy[:, None, None] * wx[None, :, None]
        view = self.img[r0:r0 + wy.size, c0:c0 + wx.size]
        view *= 1.0 - a
        view += a * np.asarray(color, np.float32)

    def square(self, cx: float, cy: float, side: float, color) -> None:
        self.rect(cx - side / 2, cy - side / 2, cx + side / 2, cy + side / 2, color)

    def blend(self, alpha: np.ndarray, color) -> None:
        a = alpha[..., None].astype(np.float32)
        self.img *= 1.0 - a
        self.img += a * np.asarray(color, np.float32)


def _random_texture_alpha(spec: PadSpec, geometry: PadGeometry, canvas: _Canvas) -> np.ndarray:
    """Coverage (0-1) of the black field texture, on the canvas grid."""
    ss = TEXTURE_SUPERSAMPLE
    n = canvas.n * ss
    sppm = canvas.ppm * ss
    h = canvas.h
    rng = np.random.default_rng(spec.texture_seed)
    f = geometry.field_side_m / 2.0
    margin = spec.texture_min_feature_m

    def to_px(x, y):
        return (x + h) * sppm, (h - y) * sppm

    allowed = np.zeros((n, n), np.uint8)
    lo_px, hi_px = int(round((h - f + margin) * sppm)), int(round((h + f - margin) * sppm))
    allowed[lo_px:hi_px, lo_px:hi_px] = 1
    for m in geometry.markers:
        cx, cy = m.center[:2]
        half = m.size_m / 2 + m.quiet_zone_m
        (u0, v0), (u1, v1) = to_px(cx - half, cy + half), to_px(cx + half, cy - half)
        allowed[max(int(math.floor(v0)), 0):int(math.ceil(v1)), max(int(math.floor(u0)), 0):int(math.ceil(u1))] = 0

    lo, hi = math.log(spec.texture_min_feature_m), math.log(spec.texture_max_feature_m)
    mean_area = (spec.texture_max_feature_m**2 - spec.texture_min_feature_m**2) / (2 * (hi - lo))
    count = int(spec.texture_density * (2 * f) ** 2 / mean_area)
    mask = np.zeros((n, n), np.uint8)
    shift = 4
    for _ in range(count):
        size = math.exp(rng.uniform(lo, hi))
        cx, cy = rng.uniform(-f, f, size=2)
        ang = rng.uniform(0, math.pi)
        kind = rng.integers(0, 3)
        if kind == 0:  # square
            pts = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * size / 2
        elif kind == 1:  # rectangle 1:2.5
            pts = np.array([[-1.25, -0.5], [1.25, -0.5], [1.25, 0.5], [-1.25, 0.5]], float) * size / 2
        else:  # triangle
            pts = np.array([[-1, -0.8], [1, -0.8], [0.1, 1.0]], float) * size / 2
        c, s = math.cos(ang), math.sin(ang)
        pts = pts @ np.array([[c, s], [-s, c]])
        u, v = to_px(cx + pts[:, 0], cy + pts[:, 1])
        poly = np.round(np.column_stack([u, v]) * (1 << shift)).astype(np.int32)
        cv2.fillPoly(mask, [poly], 255, lineType=cv2.LINE_8, shift=shift)
    mask &= allowed * 255
    # Merge blobs closer than half the smallest feature, so no thin white channel survives to make
    # a hole at lower resolution, then fill every hole: black blobs are simply connected.
    k = max(3, int(round(spec.texture_min_feature_m / 2 * sppm)) | 1)
    mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
    mask &= allowed * 255
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    cv2.drawContours(mask, contours, -1, 255, thickness=cv2.FILLED)
    mask &= allowed * 255
    return cv2.resize(mask.astype(np.float32) / 255.0, (canvas.n, canvas.n), interpolation=cv2.INTER_AREA)


def _paint_finder(canvas: _Canvas, marker: Marker) -> None:
    cx, cy = marker.center[:2]
    canvas.square(cx, cy, marker.size_m + 2 * marker.quiet_zone_m, WHITE)
    for sq in marker.squares:
        canvas.square(cx, cy, sq.side_m, BLACK if sq.color_inside == "black" else WHITE)


def _paint_aruco(canvas: _Canvas, marker: Marker, dictionary: str) -> None:
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    nbits = d.markerSize + 2
    bits = cv2.aruco.generateImageMarker(d, marker.aruco_id, nbits, borderBits=1)
    cx, cy = marker.center[:2]
    size = marker.size_m
    mod = size / nbits
    canvas.square(cx, cy, size + 2 * marker.quiet_zone_m, WHITE)
    canvas.square(cx, cy, size, BLACK)
    x0, y1 = cx - size / 2, cy + size / 2
    for r in range(nbits):
        for c in range(nbits):
            if bits[r, c] > 127:
                canvas.rect(x0 + c * mod, y1 - (r + 1) * mod, x0 + (c + 1) * mod, y1 - r * mod, WHITE)


def _paint_apriltag(canvas: _Canvas, marker: Marker) -> None:
    from .apriltag import BORDER_CELLS, TOTAL_CELLS, tag_cells

    cells = tag_cells(marker.aruco_id)
    cx, cy = marker.center[:2]
    cell = marker.size_m / BORDER_CELLS
    total = cell * TOTAL_CELLS
    canvas.square(cx, cy, marker.size_m + 2 * marker.quiet_zone_m, WHITE)  # the margin (none for a nested tag)
    x0, y1 = cx - total / 2, cy + total / 2
    for r in range(TOTAL_CELLS):
        for c in range(TOTAL_CELLS):
            canvas.rect(x0 + c * cell, y1 - (r + 1) * cell, x0 + (c + 1) * cell, y1 - r * cell,
                        WHITE if cells[r, c] else BLACK)


def _intersect(a, b):
    r = (max(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), min(a[3], b[3]))
    return r if r[0] < r[2] and r[1] < r[3] else None


def _subtract(a, b) -> list:
    """Rectangle ``a`` minus rectangle ``b`` as up to four disjoint rectangles (x0, y0, x1, y1)."""
    i = _intersect(a, b)
    if i is None:
        return [a]
    out = [(a[0], a[1], a[2], i[1]), (a[0], i[3], a[2], a[3]), (a[0], i[1], i[0], i[3]), (i[2], i[1], a[2], i[3])]
    return [r for r in out if r[0] < r[2] and r[1] < r[3]]


def render_texture(spec: PadSpec, geometry: PadGeometry, ppm: float) -> np.ndarray:
    """The pad as an ``(n, n, 3)`` uint8 RGB image, ``n = round(side * ppm)``."""
    if not ppm > 0:
        raise ValueError(f"ppm must be positive, got {ppm}")
    if spec.variant == "artwork":
        return artwork_texture(spec, ppm)
    cv = _Canvas(spec.side_m, ppm)
    h, b = cv.h, spec.border_m
    border = geometry.border
    light, dark = border.color_rgb, border.dark_color_rgb
    cv.rect(-h, -h, h, h, light)
    cue = (h - b, -h, h, -h + b)  # the bottom-right border square
    cue_dark = [round(c * spec.border_dark_factor) for c in spec.cue_color]
    cv.rect(*cue, spec.cue_color)
    # checker in the inner three quarters of the border (and cue square); the outer band stays solid
    band, cell = border.solid_band_m, border.checker_m
    inner = h - band
    ncell = int(math.floor((2 * inner) / cell + 1e-9))
    start = -ncell * cell / 2.0
    f = h - b
    for i in range(ncell):
        for j in range(ncell):
            if (i + j) % 2:
                continue
            x0, y0 = start + i * cell, start + j * cell
            x1, y1 = x0 + cell, y0 + cell
            if x0 >= -f - 1e-12 and x1 <= f + 1e-12 and y0 >= -f - 1e-12 and y1 <= f + 1e-12:
                continue  # inside the field
            r = (max(x0, -inner), max(y0, -inner), min(x1, inner), min(y1, inner))
            inside = _intersect(r, cue)
            for part in _subtract(r, cue):
                cv.rect(*part, dark)
            if inside is not None:
                cv.rect(*inside, cue_dark)
    cv.rect(-f, -f, f, f, WHITE)
    cv.blend(_random_texture_alpha(spec, geometry, cv), BLACK)
    for m in geometry.markers:  # in order: a nested tag after the one it sits in
        if m.kind == "finder":
            _paint_finder(cv, m)
        elif m.kind == "apriltag":
            _paint_apriltag(cv, m)
        else:
            from .layout import aruco_dictionary_of

            _paint_aruco(cv, m, aruco_dictionary_of(spec.to_jsonable(), m))
    return np.clip(np.round(cv.img), 0, 255).astype(np.uint8)


def artwork_texture(spec: PadSpec, ppm: float) -> np.ndarray:
    """The user's image resampled to the pad's texture grid (``n = round(side * ppm)`` pixels a side,
    pixel-area averaging when shrinking), or :class:`InputError` naming ``pad.artwork_image``."""
    from .errors import InputError

    path = spec.artwork_image
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR) if path and os.path.isfile(path) else None
    if bgr is None:
        raise InputError(f"pad.artwork_image: {path!r} is missing or not a readable image")
    h, w = bgr.shape[:2]
    if abs(w - h) > 0.01 * max(w, h):
        raise InputError(f"pad.artwork_image: {path} is {w}x{h} px; the artwork covers the square pad, so it must be "
                         "square (within 1 %)")
    n = int(round(spec.side_m * ppm))
    interp = cv2.INTER_AREA if n < w else cv2.INTER_LINEAR
    return cv2.cvtColor(cv2.resize(bgr, (n, n), interpolation=interp), cv2.COLOR_BGR2RGB)


def artwork_sha256(path) -> str:
    """The artwork file's SHA-256 (part of a dataset spec's identity: its pixels, not only its path)."""
    import hashlib

    from .errors import InputError

    try:
        return hashlib.sha256(open(path, "rb").read()).hexdigest()
    except (OSError, TypeError) as err:
        raise InputError(f"pad.artwork_image: {path!r} cannot be read ({err})") from None
