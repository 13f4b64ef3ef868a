"""Finder markers: QR-style nests found through the contour hierarchy, and Top/Right/Bottom naming.

On a binary image where dark is foreground, a finder marker (black 7x7 ring, white 5x5 ring,
black 3x3 centre) is a chain of three nested contours: the ring's outline, its hole, and the
centre.  The paper counts six contours on an edge image (two per boundary, "a contour with
five children"); on a binary image the same boundaries give this chain of three, which we
check with area ratios (49 : 25 : 9), squareness and concentricity.
"""
from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass

import cv2
import numpy as np

MARKER_NAMES = ("Top", "Right", "Bottom")

# Ideal area ratios of a 7:5:3 nest, and accepted ranges (pixel-boundary bias at small sizes).
HOLE_RATIO = (0.30, 0.80)     # hole / outline, ideal 25/49 = 0.51
CENTRE_RATIO = (0.06, 0.36)   # centre / outline, ideal 9/49 = 0.18
CENTRE_IN_HOLE = (0.15, 0.62)  # centre / hole, ideal 9/25 = 0.36
MIN_OUTLINE_AREA_PX = 60.0
# A bound on the contour work: a binary image with more region boundaries than this (1-px
# checkerboards, speckle, fine texture binarised) has its specks removed first, and is given up on
# if it is still this cluttered (findContours(RETR_TREE) is superlinear in the contour count:
# ~3 s for the 258,000 contours of a 960x540 checkerboard).
MAX_REGIONS = 20000
CLUTTERED_TRANSITIONS = 0.04  # share of horizontal pixel pairs that differ, above which specks are removed


@dataclass
class FinderNest:
    """One finder-marker candidate in an image.  Contours are OpenCV ``(N, 1, 2)`` int32 arrays."""

    outline: np.ndarray
    hole: np.ndarray
    centre: np.ndarray
    center_px: np.ndarray  # (2,) centroid of the outline, float64
    area_px: float         # outline area

    @property
    def contours(self) -> tuple:
        return (self.outline, self.hole, self.centre)


def binarize_dark(gray: np.ndarray, method: str = "otsu", block: int = 0) -> np.ndarray:
    """uint8 image, 255 where dark.  ``otsu`` (global) or ``adaptive`` (local mean, ``block`` px)."""
    if method == "otsu":
        _, b = cv2.threshold(gray, 0, 255, cv2.THRESH_BINARY_INV | cv2.THRESH_OTSU)
        return b
    if method == "adaptive":
        if block <= 0:
            block = max(15, (min(gray.shape[:2]) // 16) | 1)
        return cv2.adaptiveThreshold(gray, 255, cv2.ADAPTIVE_THRESH_MEAN_C, cv2.THRESH_BINARY_INV, block | 1, 10)
    raise ValueError(f"unknown binarization method {method!r} (otsu, adaptive)")


def _children(hier: np.ndarray, i: int) -> list:
    out, j = [], hier[i, 2]
    while j != -1:
        out.append(j)
        j = hier[j, 0]
    return out


def _dominant_child(hier, areas, i, tiny_share=0.04):
    """The largest child of contour i, if every other child is tiny (noise specks)."""
    kids = _children(hier, i)
    if not kids:
        return -1
    k = max(kids, key=lambda c: areas[c])
    if any(areas[c] > tiny_share * areas[i] for c in kids if c != k):
        return -1
    return k


def _squarish(contour: np.ndarray, area: float) -> bool:
    (_, _), (w, h), _ = cv2.minAreaRect(contour)
    if w <= 0 or h <= 0:
        return False
    aspect = max(w, h) / min(w, h)
    fill = area / (w * h)
    return aspect < 2.2 and fill > 0.62


def despeckle(binary_dark: np.ndarray, min_area_px: float = MIN_OUTLINE_AREA_PX) -> np.ndarray | None:
    """``binary_dark`` itself when it is ordinary; when it is cluttered, a copy with the light and
    dark specks too small to be part of a finder marker (its centre is 9/49 of its area) removed;
    ``None`` when even then it has more than :data:`MAX_REGIONS` regions (no marker search is
    bounded on it).  Costs one pass over the image when the image is ordinary."""
    b = binary_dark
    if np.count_nonzero(b[:, 1:] != b[:, :-1]) <= CLUTTERED_TRANSITIONS * b.size:
        return b
    b = b.copy()
    speck = max(3, int(min_area_px * 9 / 49 / 3))
    regions = 0
    # light specks (4-connected, as findContours sees holes) filled, then dark specks (8-connected) cleared
    for value, conn in ((255, 4), (0, 8)):
        fg = (b != value).astype(np.uint8) if value == 255 else b
        n, lab, stats, _ = cv2.connectedComponentsWithStats(fg, connectivity=conn)
        small = stats[:, cv2.CC_STAT_AREA] < speck
        small[0] = False
        if small.any():
            b[small[lab]] = value
        regions += n - 1 - int(small.sum())
    return b if regions <= MAX_REGIONS else None


def find_finder_nests(binary_dark: np.ndarray, min_area_px: float = MIN_OUTLINE_AREA_PX) -> list:
    """All contour nests shaped like a finder marker in a binary (255 = dark) image."""
    binary_dark = despeckle(binary_dark, min_area_px)
    if binary_dark is None:
        return []
    contours, hier = cv2.findContours(binary_dark, cv2.RETR_TREE, cv2.CHAIN_APPROX_SIMPLE)
    if hier is None or len(contours) < 3:
        return []
    hier = hier[0]
    areas = np.array([cv2.contourArea(c) for c in contours])
    nests = []
    for i in range(len(contours)):
        a_i = areas[i]
        if a_i < min_area_px or hier[i, 2] == -1:
            continue
        j = _dominant_child(hier, areas, i)
        if j < 0:
            continue
        k = _dominant_child(hier, areas, j)
        if k < 0 or any(areas[c] > 0.04 * a_i for c in _children(hier, k)):
            continue
        a_j, a_k = areas[j], areas[k]
        if not (HOLE_RATIO[0] <= a_j / a_i <= HOLE_RATIO[1] and CENTRE_RATIO[0] <= a_k / a_i <= CENTRE_RATIO[1]
                and a_j > 0 and CENTRE_IN_HOLE[0] <= a_k / a_j <= CENTRE_IN_HOLE[1]):
            continue
        if not (_squarish(contours[i], a_i) and _squarish(contours[k], max(a_k, 1.0))):
            continue
        m_i, m_k = cv2.moments(contours[i]), cv2.moments(contours[k])
        if m_i["m00"] <= 0 or m_k["m00"] <= 0:
            continue
        c_i = np.array([m_i["m10"] / m_i["m00"], m_i["m01"] / m_i["m00"]])
        c_k = np.array([m_k["m10"] / m_k["m00"], m_k["m01"] / m_k["m00"]])
        if np.linalg.norm(c_i - c_k) > 0.15 * math.sqrt(a_i):
            continue
        nests.append(FinderNest(contours[i], contours[j], contours[k], c_i, float(a_i)))
    return nests


@dataclass
class MarkerTriple:
    """Three nests named Top, Right, Bottom; ``spacing_ratio`` = marker side / Top-Right distance."""

    top: FinderNest
    right: FinderNest
    bottom: FinderNest
    score: float

    @property
    def by_name(self) -> dict:
        return {"Top": self.top, "Right": self.right, "Bottom": self.bottom}

    @property
    def spacing_ratio(self) -> float:
        side = np.mean([math.sqrt(n.area_px) for n in (self.top, self.right, self.bottom)])
        d = 0.5 * (np.linalg.norm(self.right.center_px - self.top.center_px)
                   + np.linalg.norm(self.bottom.center_px - self.top.center_px))
        return float(side / max(d, 1e-9))


def name_triple(a: FinderNest, b: FinderNest, c: FinderNest):
    """Name three nests by the paper's distance rule; returns ``(MarkerTriple, error)``.

    Top is the nest off the longest side (the right-angle corner).  Right and Bottom follow from
    the turn direction: in image coordinates (y down) a pad seen from above, not mirrored, has
    ``cross(Right - Top, Bottom - Top) > 0``.  The error measures how far the triple is from a
    right isosceles triangle (0 for a perfect one seen head-on).
    """
    nests = (a, b, c)
    pairs = [(0, 1), (0, 2), (1, 2)]
    d = [np.linalg.norm(nests[p].center_px - nests[q].center_px) for p, q in pairs]
    longest = int(np.argmax(d))
    top_idx = ({0, 1, 2} - set(pairs[longest])).pop()
    others = [i for i in range(3) if i != top_idx]
    top = nests[top_idx]
    r, b_ = nests[others[0]], nests[others[1]]
    v1, v2 = r.center_px - top.center_px, b_.center_px - top.center_px
    if v1[0] * v2[1] - v1[1] * v2[0] < 0:
        r, b_ = b_, r
        v1, v2 = v2, v1
    l1, l2, l3 = np.linalg.norm(v1), np.linalg.norm(v2), d[longest]
    if min(l1, l2) <= 0:
        return None, math.inf
    err = abs(l1 - l2) / max(l1, l2) + abs(l3 - math.hypot(l1, l2)) / l3
    sizes = [n.area_px for n in nests]
    err += 0.5 * abs(math.log(max(sizes) / min(sizes)))
    return MarkerTriple(top, r, b_, err), err


def find_marker_triples(nests: list, max_error: float = 0.35, max_candidates: int = 12, rectify=None) -> list:
    """Disjoint triples of nests that form a named marker set, best first.

    ``rectify``: maps ``(N, 2)`` pixels to a view in which the pad plane is seen head-on (from the
    lens model and the IMU's gravity): the right-isosceles test is then as strict for a camera 30
    degrees off nadir behind a wide lens as for a nadir pinhole.  The triples hold the nests as found."""
    cands = sorted(nests, key=lambda n: -n.area_px)[:max_candidates]
    test = cands
    if rectify is not None and cands:
        c = np.array([n.center_px for n in cands])
        m = rectify(np.concatenate([c, c + [1.0, 0.0], c + [0.0, 1.0]]))
        k = len(cands)
        if np.isfinite(m).all():
            jac = np.abs((m[k:2 * k, 0] - m[:k, 0]) * (m[2 * k:, 1] - m[:k, 1])
                         - (m[k:2 * k, 1] - m[:k, 1]) * (m[2 * k:, 0] - m[:k, 0]))
            test = [dataclasses.replace(n, center_px=m[i], area_px=n.area_px * float(jac[i]))
                    for i, n in enumerate(cands)]
    back = {id(t): n for t, n in zip(test, cands)}
    scored = []
    for a, b, c in itertools.combinations(range(len(cands)), 3):
        t, err = name_triple(test[a], test[b], test[c])
        if t is not None and err <= max_error:
            t = MarkerTriple(back[id(t.top)], back[id(t.right)], back[id(t.bottom)], err)
            scored.append((err, (a, b, c), t))
    scored.sort(key=lambda s: s[0])
    used, out = set(), []
    for _, idx, t in scored:
        if used.intersection(idx):
            continue
        used.update(idx)
        out.append(t)
    return out
