"""Sub-pixel image features shared by the localizer's phases and by the tests.

:func:`refine_quad` places the corners of a dark-on-light (or light-on-dark) quadrilateral to
a small fraction of a pixel: along each side it finds where the intensity crosses halfway
between the two sides' plateaus (unbiased for any symmetric blur: defocus, texture filtering,
antialiasing), fits a straight line to those edge points (after undistorting them, so that
straight 3D edges stay straight under lens distortion), and intersects neighbouring lines.
"""
from __future__ import annotations

import warnings

import cv2
import numpy as np

from .geometry import Camera


def _distort_px(camera: Camera, px_und: np.ndarray) -> np.ndarray:
    xy = np.column_stack([(px_und[:, 0] - camera.cx) / camera.fx, (px_und[:, 1] - camera.cy) / camera.fy])
    xy = camera.distort_normalized(xy)
    return np.column_stack([xy[:, 0] * camera.fx + camera.cx, xy[:, 1] * camera.fy + camera.cy])


def _inside(px: np.ndarray, shape, margin=0.0) -> np.ndarray:
    """``px[..., 0:2]`` within the image of ``shape`` (pixel centres at integers), interpolation
    included, and ``margin`` px (broadcast against ``px[..., 0]``) clear of its edges."""
    x, y = px[..., 0], px[..., 1]
    return (x >= margin) & (y >= margin) & (x <= shape[1] - 1 - margin) & (y <= shape[0] - 1 - margin)


def sample_at(img: np.ndarray, pts) -> np.ndarray:
    """``img`` read bilinearly at points ``pts`` ``(..., 2)`` (x, y pixels), float64: shaped as the
    points' leading axes (a grid of them at most two deep), with the image's channels after a colour
    one's; a point outside reads the nearest edge's value (callers mark those unseen).  Points far out
    of view (a cut pad's side or cells through a wide lens) are held within float32's range: cast as
    they were, they overflowed with a warning."""
    p = np.asarray(pts, np.float64)
    lead = p.shape[:-1]
    at = np.clip(p.reshape((1, -1, 2) if len(lead) < 2 else (-1, lead[-1], 2)), -1e6, 1e6).astype(np.float32)
    v = cv2.remap(img, at[..., 0], at[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return v.astype(np.float64).reshape(lead + v.shape[2:])


def ncc(a: np.ndarray, b: np.ndarray) -> float:
    """The normalized cross-correlation of two equally long samples (0 where either is flat)."""
    a, b = a - a.mean(), b - b.mean()
    return float(a @ b / max(float(np.linalg.norm(a) * np.linalg.norm(b)), 1e-9))


def _cross_profiles(g: np.ndarray, quad: np.ndarray, offsets, m: int, trim: float, camera: Camera | None) -> list:
    """For each side of ``quad``: ``(profiles (m, R), seen (m,))``, the image sampled across the side
    at ``offsets[i]`` px along its inward normal, at ``m`` places along its middle, and which of
    those profiles lie wholly in the image and read no NaN (masked out)."""
    pts, nrm = _side_points_batch(quad, np.roll(quad, -1, axis=0), m, trim, camera)
    inward = np.sign(np.sum((quad.mean(axis=0) - pts.mean(axis=1)) * nrm.mean(axis=1), axis=1))
    out = []
    for i in range(4):
        r = np.asarray(offsets[i], np.float64)
        P = pts[i][:, None, :] + (inward[i] * r)[None, :, None] * nrm[i][:, None, :]
        prof = sample_at(g, P)
        out.append((prof, _inside(P, g.shape).all(axis=1) & np.isfinite(prof).all(axis=1)))
    return out


def refine_quad(gray: np.ndarray, quad_px, half_width: float = 3.0, camera: Camera | None = None,
                inside_brighter: bool = False):
    """Refine 4 corners (in order around the quad) of a quadrilateral seen in ``gray``.

    Returns ``(corners (4, 2) float64, rms line residual px)`` or ``(None, inf)`` when a side
    has too few edge points.  With ``camera``, lines are fitted in undistorted pixels and the
    intersections mapped back, so corners stay exact under lens distortion.  ``inside_brighter``:
    the quad is known to be brighter inside than beyond (else each profile's own polarity).  (One quad of :func:`refine_quads`.)
    """
    out, rms = refine_quads(gray, np.asarray(quad_px, np.float64).reshape(1, 4, 2), half_width, camera,
                            inside_brighter=inside_brighter)
    if not np.isfinite(out[0]).all():
        return None, float("inf")
    return out[0], float(rms[0])


def _side_points_batch(starts: np.ndarray, ends: np.ndarray, m: int, trim, camera: Camera | None):
    """Sample points ``(S, m, 2)`` and unit normals ``(S, m, 2)`` along S segments (images of
    straight 3D edges: through the lens when ``camera`` distorts), over ``[trim, 1 - trim]`` of
    each, or with ``trim = (lo, hi)`` (arrays (S,)) over ``[lo, hi]`` of segment i."""
    if np.ndim(trim) == 0:
        s = np.linspace(trim, 1 - trim, m)[None, :, None]
    else:
        lo, hi = (np.asarray(v, np.float64)[:, None, None] for v in trim)
        s = lo + (hi - lo) * np.linspace(0.0, 1.0, m)[None, :, None]
    if camera is None or not camera.has_distortion:
        d = ends - starts
        d = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
        pts = starts[:, None, :] + s * (ends - starts)[:, None, :]
        nrm = np.broadcast_to(np.stack([-d[:, 1], d[:, 0]], axis=1)[:, None, :], pts.shape)
        return pts, np.ascontiguousarray(nrm)
    S = len(starts)
    und = camera.undistort_pixels(np.concatenate([starts, ends]))
    ua, ub = und[:S], und[S:]
    p = ua[:, None, :] + s * (ub - ua)[:, None, :]
    eps = 0.5 * (ub - ua) / np.maximum(np.linalg.norm(ub - ua, axis=1, keepdims=True), 1e-9)
    flat = np.concatenate([p.reshape(-1, 2), (p + eps[:, None, :]).reshape(-1, 2), (p - eps[:, None, :]).reshape(-1, 2)])
    dist = _distort_px(camera, flat).reshape(3, S, m, 2)
    d = dist[1] - dist[2]
    d /= np.maximum(np.linalg.norm(d, axis=2, keepdims=True), 1e-12)
    return dist[0], np.stack([-d[..., 1], d[..., 0]], axis=2)


# a side the image's edge cuts is read over its stretch in view when its trimmed middle shows fewer
# than this many profiles; it is then read from this far past a corner in view (not a fifth of the
# side: a corner is rounded by blur over a few pixels, and profiles this far out clear the other side)
CUT_SIDE_MIN_PROFILES = 8
CUT_SIDE_CORNER_PX = 10.0


def _cut_short(pts: np.ndarray, hw: np.ndarray, shape) -> np.ndarray:
    """(S,) whether a side's sample points ``pts`` (S, m, 2) show fewer than
    :data:`CUT_SIDE_MIN_PROFILES` whole profiles (``hw`` px either way) in the image."""
    return _inside(pts, shape, (hw + 1.0)[:, None]).sum(axis=1) < min(CUT_SIDE_MIN_PROFILES, pts.shape[1])


def _spans_in_view(starts, ends, trim: float, hw, camera: Camera | None, shape):
    """``(lo, hi)`` (S,): the stretch of each side whose profiles lie in the image, ``trim`` of the
    side clear of a corner in view (:data:`CUT_SIDE_CORNER_PX` when that leaves too little), the
    profile's half width clear of the image's edge; ``lo >= hi`` where too little is in view."""
    pts, _ = _side_points_batch(starts, ends, SPAN_SAMPLES, 0.0, camera)
    seen = _inside(pts, shape, (np.asarray(hw, np.float64) + 1.0)[:, None])
    return _spans(seen, np.linalg.norm(pts[:, -1] - pts[:, 0], axis=1), trim)


SPAN_SAMPLES = 129  # places along a side at which :func:`_spans` is told what is in view


def _spans(seen: np.ndarray, length: np.ndarray, trim: float):
    """``(lo, hi)`` (S,) of :func:`_spans_in_view` from ``seen`` (S, n): which of n places evenly
    from each side's start to its end (both included) show a whole profile, and the sides'
    lengths (px)."""
    n = seen.shape[1]
    t = np.linspace(0.0, 1.0, n)
    lo, hi = np.ones(len(seen)), np.zeros(len(seen))
    for i in range(len(seen)):
        idx = np.flatnonzero(seen[i])
        if len(idx) < 2 or length[i] < 1.0:
            continue
        a, b = t[idx[0]], t[idx[-1]]
        corner = min(trim, CUT_SIDE_CORNER_PX / length[i])
        # a corner in view: clear it by the trim, or by a few pixels where the trim leaves too little
        lo[i] = (trim if (b - trim) * length[i] >= 2 * CUT_SIDE_MIN_PROFILES else corner) if idx[0] == 0 else a
        hi[i] = (1 - trim if (1 - trim - a) * length[i] >= 2 * CUT_SIDE_MIN_PROFILES else 1 - corner) \
            if idx[-1] == n - 1 else b
        if (hi[i] - lo[i]) * length[i] < CUT_SIDE_MIN_PROFILES:
            lo[i], hi[i] = 1.0, 0.0
    return lo, hi


def refine_quads(gray: np.ndarray, quads_px, half_widths, camera: Camera | None = None, m: int | None = None,
                 trim: float = 0.2, step: float = 0.25, inside_brighter: bool = False):
    """Vectorised :func:`refine_quad` for many quadrilaterals at once (one remap, no Python loop
    over sides): ``(corners (Q, 4, 2) with NaN rows where a quad failed, rms (Q,))``.

    Each profile across a side finds the half-level crossing between its two ends, rising the way
    they differ.  A band only a few pixels wide (a far pad's border, 4 px with a 1 px solid band)
    lies wholly inside a profile where the start is a pixel or two off: both ends then read
    beyond the band, and half of a side's crossings were its inner edge (a 7 degree tilt, a corner
    3 px out).  With ``inside_brighter`` the polarity is known: the levels are the outside end's
    and the profile's peak, and the crossing is the first from outside."""
    g = gray if gray.dtype == np.float32 else gray.astype(np.float32)
    q = np.asarray(quads_px, np.float64).reshape(-1, 4, 2)
    Q = len(q)
    if Q == 0:
        return np.zeros((0, 4, 2)), np.zeros(0)
    hw = np.broadcast_to(np.asarray(half_widths, np.float64), (Q,)).repeat(4)  # per side
    starts = q.reshape(-1, 2)
    ends = np.roll(q, -1, axis=1).reshape(-1, 2)
    S = len(starts)
    if m is None:  # about one profile per pixel of the longest side's used part, 8 to 40
        longest = float(np.nanmax(np.linalg.norm(ends - starts, axis=1))) if S else 0.0
        m = int(np.clip(longest * (1 - 2 * trim), 8, 40)) if np.isfinite(longest) else 8
    pts, nrm = _side_points_batch(starts, ends, m, trim, camera)
    short = _cut_short(pts, hw, g.shape)
    if short.any():  # sides the image's edge leaves little of between the trims: their stretch in view
        lo, hi = _spans_in_view(starts[short], ends[short], trim, hw[short], camera, g.shape)
        keep = lo < hi
        if keep.any():
            idx = np.flatnonzero(short)[keep]
            pts[idx], nrm[idx] = _side_points_batch(starts[idx], ends[idx], m, (lo[keep], hi[keep]), camera)
    nr = int(round(2 * float(hw.max()) / step)) + 1
    u = np.linspace(-1.0, 1.0, nr)
    r = u[None, :] * hw[:, None]                                    # (S, R) offsets per side
    P = pts[:, :, None, :] + r[:, None, :, None] * nrm[:, :, None, :]  # (S, m, R, 2)
    prof = sample_at(g, P.reshape(S * m, nr, 2))
    k = max(1, nr // 6)
    lo = prof[:, :k].mean(axis=1)
    hi = prof[:, -k:].mean(axis=1)
    contrast = hi - lo
    # a profile that leaves the image reads the replicated edge row: no edge of the quad's there (a
    # pad cut by the image's edge has sides that run out of it)
    seen = _inside(P, g.shape).reshape(S * m, nr).all(axis=1) & np.isfinite(prof).all(axis=1)  # (NaN: masked out)
    contrast = np.where(seen, contrast, 0.0)
    if not inside_brighter:
        sign = np.sign(contrast)
    else:
        # +normal points inward where the quad's signed area is positive; ``sign``: the way the
        # profile rises from outside in.  The levels are the outside end's and the profile's
        # extreme (the band's, wherever it lies in the window), and the crossing is the first
        # from outside: a band seen whole has two, and the inner one is not this edge
        x, y = q[..., 0], q[..., 1]
        sign = np.sign(np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1)).repeat(4 * m)
        lo = np.where(sign > 0, lo, hi)
        hi = np.where(np.isfinite(prof), prof, -np.inf).max(axis=1)  # (masked-out profiles: not seen)
        with np.errstate(invalid="ignore"):
            contrast = np.where(seen, hi - lo, 0.0)  # >= 0
    med = np.median(np.abs(contrast).reshape(S, m), axis=1).repeat(m)
    strong = seen & (np.abs(contrast) >= np.maximum(4.0, 0.25 * med))
    v = (prof - 0.5 * (lo + hi)[:, None]) * sign[:, None]
    cross = (v[:, :-1] < 0) & (v[:, 1:] >= 0) & strong[:, None]
    if not inside_brighter:  # the crossing nearest the start
        dist = np.where(cross, np.abs(u[:-1])[None, :], np.inf)
    else:  # the first from outside
        dist = np.where(cross, (u[:-1] * sign[:, None]) + 2.0, np.inf)
    j = np.argmin(dist, axis=1)
    rows = np.arange(len(j))
    valid = np.isfinite(dist[rows, j])
    a, b = v[rows, j], v[rows, j + 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(valid, a / (a - b), 0.0)
    rr = r.repeat(m, axis=0)
    off = rr[rows, j] + frac * (rr[rows, 1] - rr[rows, 0])
    edge = pts.reshape(-1, 2) + off[:, None] * nrm.reshape(-1, 2)
    if camera is not None and camera.has_distortion:
        edge = camera.undistort_pixels(edge)
    edge = edge.reshape(S, m, 2)
    w = valid.reshape(S, m).astype(np.float64)

    def fit(w):
        n = w.sum(axis=1)
        c = (edge * w[..., None]).sum(axis=1) / np.maximum(n, 1)[:, None]
        d = edge - c[:, None, :]
        sxx = (w * d[..., 0] ** 2).sum(1)
        syy = (w * d[..., 1] ** 2).sum(1)
        sxy = (w * d[..., 0] * d[..., 1]).sum(1)
        ang = 0.5 * np.arctan2(2 * sxy, sxx - syy)  # direction of the principal axis
        dirv = np.stack([np.cos(ang), np.sin(ang)], axis=1)
        resid = np.abs(d[..., 0] * -dirv[:, None, 1] + d[..., 1] * dirv[:, None, 0])
        return c, dirv, resid, n

    c, dirv, resid, n = fit(w)
    rm = np.where(w > 0, resid, np.nan)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # sides without edge points: NaN, handled below
        thr = np.maximum(3 * np.nanmedian(rm, axis=1) + 1e-3, 0.3)
    w2 = w * (resid < thr[:, None])
    use2 = w2.sum(axis=1) >= 4
    w = np.where(use2[:, None], w2, w)
    c, dirv, resid, n = fit(w)
    rms_side = np.sqrt((w * resid**2).sum(1) / np.maximum(n, 1))
    ok_side = n >= 4
    c = c.reshape(Q, 4, 2)
    dirv = dirv.reshape(Q, 4, 2)
    # corner i = intersection of side i-1 and side i
    p1, d1 = np.roll(c, 1, axis=1), np.roll(dirv, 1, axis=1)
    p2, d2 = c, dirv
    det = d1[..., 0] * (-d2[..., 1]) - d1[..., 1] * (-d2[..., 0])
    rhs = p2 - p1
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (rhs[..., 0] * (-d2[..., 1]) - rhs[..., 1] * (-d2[..., 0])) / det
        out = p1 + t1[..., None] * d1  # parallel sides give inf/NaN: marked failed below
    good = ok_side.reshape(Q, 4).all(axis=1) & np.all(np.abs(det) > 1e-9, axis=1) & np.isfinite(out).all(axis=(1, 2))
    if camera is not None and camera.has_distortion:
        flat = out.reshape(-1, 2)
        fin = np.isfinite(flat).all(axis=1)
        flat[fin] = _distort_px(camera, flat[fin])
        out = flat.reshape(Q, 4, 2)
    out[~good] = np.nan
    rms = np.sqrt(np.mean(rms_side.reshape(Q, 4) ** 2, axis=1))
    rms[~good] = np.inf
    return out, rms


_STEP_X = np.linspace(-6.0, 6.0, 2401)
_STEP_Y = 0.5 * (1.0 + np.tanh(0.7978845608 * (_STEP_X + 0.044715 * _STEP_X**3)))  # the normal CDF within 3e-4


def _blurred_step(x: np.ndarray) -> np.ndarray:
    """A unit step seen through a Gaussian of sigma 1 (argument already divided by sigma), from a table."""
    return np.interp(x, _STEP_X, _STEP_Y)


COARSE_E = np.arange(-1.6, 1.6001, 0.2)           # edge positions tried first (px)
FINE_E = np.arange(-0.24, 0.2401, 0.03)           # then around the best
SIGMAS = np.array([0.45, 0.7, 1.0, 1.5])          # blur (px) beside the pixel's own width


def banded_edge_offsets(gray: np.ndarray, quad_px: np.ndarray, bands_px: np.ndarray, camera: Camera | None = None,
                        trim: float = 0.25, reach_px: float = 2.5, step: float = 0.2, rising: bool = True) -> np.ndarray:
    """(4,) how far (px, along each side's inward normal) the outer edge of a banded border lies
    from the sides of ``quad_px``, or NaN where it cannot be told.

    A half-level crossing is biased when a band a pixel or two wide lies just inside the edge (the
    level it crosses is set by what lies beyond the band): on hvloc's border, a solid band a quarter
    of its width, then a checker of half its brightness, then the white field, the outline came out
    ~0.2 px outside its edge at 30 px, ~1 % of the height.  Here each side's mean cross-profile is
    fitted with the border's real profile: steps at ``e`` and ``e + bands_px[i, k]`` (the inner
    edges of the bands, in px at that side), each blurred by one sigma, with free levels (linear
    least squares) over a grid of ``(e, sigma)``, then a parabola through the best ``e``.  ``rising``:
    the first step must rise from outside in (a border brighter than the ground, as on the colour
    channel); without, either way (grey frames: the border's grey may be darker or lighter than the
    ground's)."""
    g = gray if gray.dtype == np.float32 else gray.astype(np.float32)
    q = np.asarray(quad_px, np.float64).reshape(4, 2)
    starts, ends = q, np.roll(q, -1, axis=0)
    m = int(np.clip(np.linalg.norm(ends - starts, axis=1).max() * (1 - 2 * trim), 6, 40))
    bands = np.asarray(bands_px, np.float64).reshape(4, -1)
    rs = [np.arange(-reach_px, bands[i].max() + reach_px + 1e-9, step) for i in range(4)]
    out = np.full(4, np.nan)
    for i, (prof, seen) in enumerate(_cross_profiles(g, q, rs, m, trim, camera)):
        r = rs[i]
        if seen.sum() < 3:
            continue
        y = prof[seen].mean(axis=0)
        edges = np.concatenate([[0.0], bands[i]])

        def sse_of(es, sigmas):
            """(S, E) squared residual of the best levels for each blur and edge position."""
            x = r[None, :, None] - es[:, None, None] - edges[None, None, :]
            out = np.empty((len(sigmas), len(es)))
            for a, s in enumerate(sigmas):
                s_eff = np.sqrt(s * s + 1.0 / 12.0)  # and the pixel's own width
                A = np.concatenate([np.ones((len(es), len(r), 1)), _blurred_step(x / s_eff)], axis=2)
                AtA = np.einsum("erk,erl->ekl", A, A) + 1e-9 * np.eye(A.shape[2])
                coef = np.linalg.solve(AtA, np.einsum("erk,r->ek", A, y)[..., None])[..., 0]
                res = np.einsum("erk,ek->er", A, coef) - y
                # the border must rise from the ground: a fall there is some other edge
                out[a] = np.where(coef[:, 1] > 0, np.sum(res**2, axis=1), np.inf) if rising else np.sum(res**2, axis=1)
            return out

        coarse = sse_of(COARSE_E, SIGMAS)  # coarse in the edge, every blur; then fine at the best blur
        a, b = np.unravel_index(np.argmin(coarse), coarse.shape)
        if not np.isfinite(coarse[a, b]):
            continue
        es = COARSE_E[b] + FINE_E
        fine = sse_of(es, SIGMAS[a:a + 1])[0]
        b = int(np.argmin(fine))
        if not np.isfinite(fine[b]) or b in (0, len(es) - 1) or abs(es[b]) >= 1.5:
            continue
        y0, y1, y2 = fine[b - 1], fine[b], fine[b + 1]
        den = y0 - 2 * y1 + y2
        out[i] = es[b] + (0.5 * (y0 - y2) / den * (FINE_E[1] - FINE_E[0]) if den > 0 and np.isfinite(den) else 0.0)
    return out


_SRGB_TO_LINEAR = (np.where(np.arange(256) <= 10, np.arange(256) / 255.0 / 12.92,
                            ((np.arange(256) / 255.0 + 0.055) / 1.055) ** 2.4) * 255.0).astype(np.float32)


def srgb_to_linear(rgb: np.ndarray) -> np.ndarray:
    """8-bit sRGB to linear light, float32 on the same 0..255 scale.  Blur (motion, defocus) mixes
    light, so a blurred edge is symmetric about its true position in linear values only: in sRGB the
    dark side of a ramp is lifted and a wide ramp's centre moves by a pixel or more."""
    a = np.asarray(rgb, np.uint8)
    if a.ndim == 2 or (a.ndim == 3 and a.shape[2] <= 4):
        return cv2.LUT(a, _SRGB_TO_LINEAR)  # (the same values, eight times as fast as numpy's indexing)
    return _SRGB_TO_LINEAR[a]


def linear_to_srgb(lin: np.ndarray) -> np.ndarray:
    """Linear light on the 0..255 scale (:func:`srgb_to_linear`'s) back to 8-bit sRGB."""
    v = np.clip(np.asarray(lin, np.float64) / 255.0, 0.0, 1.0)
    return (255.0 * np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(v, 1 / 2.4) - 0.055) + 0.5).astype(np.uint8)


def _stretch_samples(length: np.ndarray, t0: np.ndarray, t1: np.ndarray, segments: int) -> int:
    """How many cross-profiles each of ``segments`` equal stretches of the sides' spans ``t0``..``t1``
    (fractions of sides ``length`` px long) is read over: about one per px of the longest, 4 to 20."""
    return int(np.clip(np.max(length * np.clip(t1 - t0, 0.0, None)) / segments, 4, 20))


BUMP_SLACK_PX = 4.0  # how far beyond the border's place (px) the peak of its blurred profile is looked for


def band_centroid_offsets(chan: np.ndarray, quad_px: np.ndarray, bands_px: np.ndarray, levels: np.ndarray,
                          camera: Camera | None = None, reach_px=16.0, trim: float = 0.25,
                          step: float = 0.5, segments: int = 2, in_view: bool = False, widen: int = 0) -> tuple:
    """``(offsets (4, segments), blur (4, segments), at (4, segments))``: where (px, along each
    side's inward normal from the sides of ``quad_px``) the outer edge of a banded border lies, read
    from the centroid of the border's cross-profile over each of ``segments`` equal stretches of the
    side's middle (centred at fractions ``at`` of the side), and how wide a box blur along that
    normal the profile's spread shows; NaN where a stretch cannot be told.  ``in_view``: the
    stretches share the part of each side's middle whose profiles lie in the image
    (:func:`_spans_in_view`'s rule), not the whole middle, of which a side cut by the image's
    edge may show only one stretch or none.

    For motion blur wider than an edge fit's window (a 12 px smear of a 6 px border) there is no
    edge left to fit, but blur by any kernel symmetric about the frame time (the exposure is centred
    on it) moves no mass: the profile's centroid is the sharp border's, whose place behind the edge
    the design fixes (bands ending at ``bands_px[i]`` with ``levels`` relative to the first).
    ``chan`` must be linear in light (:func:`srgb_to_linear`); its ground and field levels are read
    just outside the bump around the profile's peak and taken away.  ``reach_px``: how far beyond
    the border the profiles reach, one for all sides or (4,) one per side; a bump that runs out of
    that is read again reaching twice as far, up to ``widen`` times (``chan`` must hold that much)."""
    g = chan if chan.dtype == np.float32 else chan.astype(np.float32)
    q = np.asarray(quad_px, np.float64).reshape(4, 2)
    length = np.linalg.norm(np.roll(q, -1, axis=0) - q, axis=1)
    bands = np.asarray(bands_px, np.float64).reshape(4, -1)
    lv = np.asarray(levels, np.float64)
    offsets, blur = np.full((4, segments), np.nan), np.full((4, segments), np.nan)
    reach = np.broadcast_to(np.asarray(reach_px, np.float64), (4,))
    rs = [np.arange(-reach[i], bands[i].max() + reach[i] + 1e-9, step) for i in range(4)]
    t0, t1 = np.full(4, trim), np.full(4, 1.0 - trim)  # the stretch of each side read
    if in_view:
        t0, t1 = _spans(np.stack([seen for _, seen in _cross_profiles(g, q, rs, SPAN_SAMPLES, 0.0, camera)]),
                        length, trim)
    per = _stretch_samples(length, t0, t1, segments)
    at = t0[:, None] + (t1 - t0)[:, None] * (np.arange(segments) + 0.5) / segments
    todo = np.repeat((t0 < t1)[:, None], segments, axis=1)  # (sides with too little in view: never read)
    for _ in range(widen + 1):
        runs_on = np.zeros_like(todo)
        for i, (prof, seen) in enumerate(_cross_profiles(g, q, rs, per * segments, (t0, t1) if in_view else trim,
                                                         camera)):
            if not todo[i].any():
                continue
            r = rs[i]
            edges = np.concatenate([[0.0], bands[i]])
            mass = lv * np.diff(edges)  # the sharp profile: level lv[k] between edges k and k + 1
            c0 = float(np.sum(mass * (edges[1:] + edges[:-1]) / 2) / mass.sum())
            var0 = float(np.sum(lv * np.diff(edges**3) / 3) / mass.sum() - c0**2)
            for k in np.flatnonzero(todo[i]):
                part = prof[k * per:(k + 1) * per][seen[k * per:(k + 1) * per]]
                if len(part) < 2:
                    continue
                y = part.mean(axis=0)
                # the border's bump: the one over the border's place (within a few px: the sides' error),
                # not the brightest anywhere in the window (a strip of the border's colour 16 px beside
                # a side, under a 2 px lens blur, was brighter: that side read 18 px out, the centroid
                # placed nothing, and the edge fit left the pad 11 % of its half side large, "ok")
                p = int(np.argmax(np.where(np.abs(r - 0.5 * edges[-1]) <= 0.5 * edges[-1] + BUMP_SLACK_PX, y, -np.inf)))
                low = y < 0.15 * y[p]
                before, after = np.nonzero(low[:p])[0], np.nonzero(low[p:])[0]
                if y[p] <= 0:
                    continue  # no bump
                if not len(before) or not len(after):
                    runs_on[i, k] = True  # a bump that runs out of the window
                    continue
                a, b = before[-1], p + after[0]          # the first low samples either side of the bump
                n = max(2, int(round(2.0 / step)))
                base_out = float(np.median(y[max(0, a - n):a + 1]))
                base_in = float(np.median(y[b:b + n + 1]))
                lo, hi = max(0, a - n), min(len(y), b + n + 1)
                rr = r[lo:hi]
                base = base_out + (base_in - base_out) * np.clip((rr - r[a]) / max(r[b] - r[a], 1e-9), 0.0, 1.0)
                v = np.clip(y[lo:hi] - base, 0.0, None)
                if v.sum() <= 0:
                    continue
                c = float(np.sum(v * rr) / v.sum())
                offsets[i, k] = c - c0
                blur[i, k] = float(np.sqrt(max(12.0 * (np.sum(v * (rr - c) ** 2) / v.sum() - var0), 0.0)))
        todo = runs_on
        if not todo.any():
            break
        reach = 2.0 * reach  # (every side's profiles again: those read are kept)
        rs = [np.arange(-reach[i], bands[i].max() + reach[i] + 1e-9, step) for i in range(4)]
    return offsets, blur, at


def _box_gauss_step(x: np.ndarray, box, sigma) -> np.ndarray:
    """A unit step seen through a box ``box`` px wide (motion) convolved with a Gaussian of
    ``sigma`` px (a lens, the pixel): the Gaussian step averaged over the box,
    ``sigma / box * (psi(u + box / 2 sigma) - psi(u - box / 2 sigma))`` with ``psi(u) = u Phi(u) + phi(u)``.
    ``box`` and ``sigma`` broadcast against ``x``; a box under a twentieth of sigma is taken as that."""
    box = np.maximum(box, 0.05 * sigma)

    def psi(u):
        return u * _blurred_step(u) + 0.3989422804 * np.exp(-0.5 * u * u)

    return sigma / box * (psi((x + 0.5 * box) / sigma) - psi((x - 0.5 * box) / sigma))


PROFILE_SIGMAS = np.array([0.5, 1.2, 2.2, 3.6])  # px: the Gaussian part of a border's blur, tried first
INNER_LIGHT = (0.2, 0.6)  # the checker's light over the solid band's that a fit may find (below)
BAND_LEVEL_SHARE = 0.6  # the least share of the stretches' median band level a fitted stretch shows


def _fit_banded_profile(r: np.ndarray, y: np.ndarray, edges: np.ndarray, e_reach: float, box_max: float,
                        inner=INNER_LIGHT) -> tuple:
    """``(edge, width, band)`` of one profile ``y`` on ``r``: :func:`_fit_banded_profiles`."""
    e, w, b = _fit_banded_profiles(np.asarray(r, np.float64)[None], np.asarray(y, np.float64)[None],
                                   np.ones((1, len(r))), np.asarray(edges, np.float64)[None], e_reach, box_max, inner)
    return float(e[0]), float(w[0]), float(b[0])


def _fit_banded_profiles(r: np.ndarray, y: np.ndarray, used: np.ndarray, edges: np.ndarray, e_reach: float,
                         box_max: float, inner=INNER_LIGHT) -> tuple:
    """``(edge, width, band)``, each (K,): for each of K profiles ``y`` (K, R) on lattices ``r`` (K, R)
    of one step (1 px or so; samples where ``used`` (K, R) is 0 are left out), the outer edge (px
    along ``r``) of the banded border whose blurred profile best explains it, NaN where no rising
    border does, the width (px) of the box whose spread equals its kernel's (``sqrt(box**2 + 12
    sigma**2)``) and the solid band's level there.  The model: a ground level, the solid band
    (``edges[k, 0]`` to ``edges[k, 1]``, shifted by the edge), the checker (to ``edges[k, 2]``) and
    the field beyond, each a free level, all seen through one kernel, a box (motion, at most
    ``box_max``) convolved with a Gaussian (a lens), whose widths are searched with the edge (within
    ``e_reach``) on a grid, coarse then fine, and a parabola through the best edge.  The profiles
    are fitted together, each on its own grid (one profile at a time, the calls cost more than the
    arithmetic).

    The checker's light, relative to the solid band's, is held within ``inner``: a camera sums it
    in light (half of the band's, for hvloc's checker of the border's colour and a dark one), a
    renderer filtering its texture in display values sums less (a quarter); left free, a border
    smeared over more than its width trades that level for its place."""
    r, Y, W, edges = (np.asarray(a, np.float64) for a in (r, y, used, edges))
    K = len(Y)
    lo, hi = inner
    # the 3-level models (checker's light fixed at a bound) from the 4-level one: A3 = A4 @ M
    M = {c: np.array([[1, 0, 0], [0, 1, 0], [0, c, 0], [0, 0, 1]], np.float64) for c in (lo, hi)}
    y2 = np.sum(W * Y * Y, axis=1)[:, None]

    def levels_fit(A):
        """(K, P) squared residuals of each row's P models' best levels and the solid band's level
        in each (``A``: (K, P, R, 4) basis)."""
        At = (A * W[:, None, :, None]).swapaxes(-1, -2)  # (K, P, 4, R)
        AtA, AtY = At @ A, (At @ Y[:, None, :, None])[..., 0]
        coef = np.linalg.solve(AtA + 1e-9 * np.eye(4), AtY[..., None])[..., 0]  # (K, P, 4)
        err = y2 - np.sum(coef * AtY, axis=-1)
        amp = coef[..., 1]
        ratio = coef[..., 2] / np.where(amp > 0, amp, np.inf)
        for c, out in ((lo, ratio < lo), (hi, ratio > hi)):
            if not out.any():
                continue
            m = M[c]
            A3, B3 = m.T @ AtA @ m, AtY @ m
            c3 = np.linalg.solve(A3 + 1e-9 * np.eye(3), B3[..., None])[..., 0]
            err = np.where(out, y2 - np.sum(c3 * B3, axis=-1), err)
            amp = np.where(out, c3[..., 1], amp)
        return np.where(amp > 0, err, np.inf), amp

    def basis(st):
        """(..., R, 4): ground, solid band, checker, field from the three blurred steps ``st`` (3, ..., R)."""
        return np.stack([np.ones_like(st[0]), st[0] - st[1], st[1] - st[2], st[2]], axis=-1)

    def steps(x, fb, fs):
        """(3, K, P, R): the three band edges' steps at ``x`` (K, P, R) from the edge, widths (K, P)."""
        return _box_gauss_step(x[None] - edges.T[:, :, None, None], fb[None, ..., None], fs[None, ..., None])

    # coarse: the edge in steps of the profile's own, so that every model's steps are read off one
    # table per blur; then around the best, finely, the blur's two widths a little either side
    d = float(r[0, 1] - r[0, 0])
    n_e = int(np.ceil(e_reach / d))
    es = np.arange(-n_e, n_e + 1) * d
    boxes = np.linspace(0.0, max(box_max, 1.0), 7)
    sig = np.sqrt(PROFILE_SIGMAS**2 + 1.0 / 12.0)
    bb, ss = (a.ravel() for a in np.meshgrid(boxes, sig, indexing="ij"))
    R = r.shape[1]
    u = r[:, :1] - es[-1] + d * np.arange(R + len(es) - 1)[None, :]  # (K, U): every r - e on the lattice
    table = steps(np.broadcast_to(u[:, None, :], (K, len(bb), u.shape[1])), np.broadcast_to(bb, (K, len(bb))),
                  np.broadcast_to(ss, (K, len(ss))))  # (3, K, BS, U)
    idx = np.arange(R)[None, :] + (len(es) - 1 - np.arange(len(es)))[:, None]  # (E, R): r_j - e_p
    err, _ = levels_fit(basis(table[..., idx]).reshape(K, -1, R, 4))  # (K, BS * E)
    b_of, s_of, e_of = np.repeat(bb, len(es)), np.repeat(ss, len(es)), np.tile(es, len(bb))
    db = boxes[1] - boxes[0]

    def fine(fb, fs, fe):
        """(K, P) squared residuals and band levels at widths and edges (K, P) (on the same samples:
        the edge's place comes from the model, not the sampling)."""
        return levels_fit(basis(steps(r[:, None, :] - fe[..., None], fb, fs)))

    p = np.argmin(err, axis=1)
    none = ~np.isfinite(err[np.arange(K), p])
    # around the best, the edge and both widths together (the box trades for the edge: searched
    # one at a time, a stretch's edge stopped 0.5 px off), four times, each time finer (as good as
    # twice on 5x5x7, for half the models); then a parabola through the edge's three best at the
    # best widths
    b0, s0, e0 = b_of[p], s_of[p], e_of[p]
    grid = [a.ravel() for a in np.meshgrid(np.linspace(-0.6, 0.6, 3), np.linspace(-0.4, 0.4, 3),
                                           np.linspace(-0.6, 0.6, 5), indexing="ij")]
    for span in (1.0, 0.5, 0.25, 0.125):
        fb = np.clip(b0[:, None] + span * db * grid[0], 0.0, None)
        fs = s0[:, None] * np.exp(span * grid[1])
        fe = e0[:, None] + span * d * grid[2]
        w = np.argmin(fine(fb, fs, fe)[0], axis=1)
        b0, s0, e0 = (a[np.arange(K), w] for a in (fb, fs, fe))
    row, amp = fine(np.repeat(b0[:, None], 3, axis=1), np.repeat(s0[:, None], 3, axis=1), e0[:, None] + [-0.1, 0.0, 0.1])
    width = np.hypot(b0, np.sqrt(12.0) * s0)
    middle = np.isfinite(row).all(axis=1) & (row[:, 1] <= np.minimum(row[:, 0], row[:, 2]))
    with np.errstate(invalid="ignore", divide="ignore"):  # (a stretch whose models are all infinite: no parabola)
        den = row[:, 0] - 2 * row[:, 1] + row[:, 2]
        shift = np.where(middle, np.where(den > 0, 0.5 * (row[:, 0] - row[:, 2]) / np.where(den > 0, den, 1.0), 0.0) * 0.1,
                         0.1 * (np.argmin(np.where(np.isfinite(row), row, np.inf), axis=1) - 1))
    e = np.where(none | ~np.isfinite(row).any(axis=1), np.nan, e0 + shift)
    # (the band's level where the parabola's middle lies, a tenth of a px from its vertex at most)
    return e, np.where(none, np.nan, width), np.where(np.isfinite(e), amp[:, 1], np.nan)


def banded_profile_offsets(chan: np.ndarray, quad_px: np.ndarray, bands_px: np.ndarray, around: np.ndarray,
                           within_px: float, blur_px: float, camera: Camera | None = None, reach_px: float = 16.0,
                           trim: float = 0.25, step: float = 1.0, max_width_px=np.inf) -> np.ndarray:
    """(4, S) where (px, along each side's inward normal from the sides of ``quad_px``) the outer
    edge of the banded border lies over each of S equal stretches of each side's middle (``trim``
    of the side left at either end), as a fit of the stretch's mean cross-profile by the border's
    own blurred profile (:func:`_fit_banded_profile`) finds it within ``within_px`` of ``around``
    (4, S), where :func:`band_centroid_offsets` read it on the same stretches; NaN where there is no
    such reading or no fit, where the kernel fitted is wider than ``max_width_px`` (one for all
    sides or (4,) one per side), or where the solid band's level is under :data:`BAND_LEVEL_SHARE`
    of the stretches' median: something hides part of that stretch (a box over a corner, softened
    by 1 px, left two stretches 0.3-0.5 of the others' light, their fit agreed with their
    centroid, and a corner lay 2.9 px off; under blur alone the stretches' levels lie within 0.8-1.25
    of their median).  ``chan`` must be linear in light; ``blur_px``: the smear read there.

    A centroid is the sharp border's only when all of the blurred border's light is summed and
    nothing else's, which a Gaussian's long tails (cut where they fall under the ground's texture)
    and the field's own level beside it do not allow: under a 2 px lens blur the centroid placed
    the outline 1-2 % of its half side out (``benchmarks/blur_bias.py``).  The fit needs the
    border's bands resolved: under a smear wider than the border the checker's light trades for the
    border's place (:data:`INNER_LIGHT`), and the centroid, which needs no shape, is better.  What
    the kernel is wide is the fit's own reading, in the channel fitted: JPEG smears a colour channel
    further than luma (a 56 px pad under 4.5 px of motion, 5 px in luma, fitted a 9.9 px kernel in the
    border's channel through JPEG 75, and the fit put its edge 1.1 px in, trading the solid band's
    light for its place).  Past the border's width its place is not told by its shape."""
    g = chan if chan.dtype == np.float32 else chan.astype(np.float32)
    q = np.asarray(quad_px, np.float64).reshape(4, 2)
    around = np.asarray(around, np.float64)
    segments = around.shape[1]
    length = np.linalg.norm(np.roll(q, -1, axis=0) - q, axis=1)
    bands = np.asarray(bands_px, np.float64).reshape(4, -1)
    offsets = np.full((4, segments), np.nan)
    levels = np.full((4, segments), np.nan)
    reach = max(reach_px, 1.5 * blur_px + 4.0)  # beyond the border, and into the field past it
    rs = [np.arange(-reach, bands[i].max() + min(reach, bands[i].max() * 1.2) + 1e-9, step) for i in range(4)]
    widest = np.broadcast_to(np.asarray(max_width_px, np.float64), (4,))
    per = _stretch_samples(length, np.full(4, trim), np.full(4, 1.0 - trim), segments)
    n = max(len(x) for x in rs)  # (every stretch's profile on one lattice length, the rest unused)
    at, rr, yy, used, ee = [], [], [], [], []
    for i, (prof, seen) in enumerate(_cross_profiles(g, q, rs, per * segments, trim, camera)):
        for k in range(segments):
            part = prof[k * per:(k + 1) * per][seen[k * per:(k + 1) * per]]
            if len(part) < 2 or not np.isfinite(around[i, k]):
                continue
            m = len(rs[i])
            at.append((i, k))
            rr.append(rs[i][0] - around[i, k] + step * np.arange(n))
            yy.append(np.pad(part.mean(axis=0), (0, n - m)))
            used.append(np.arange(n) < m)
            ee.append(np.concatenate([[0.0], bands[i]]))
    if at:
        e, width, level = _fit_banded_profiles(np.array(rr), np.array(yy), np.array(used), np.array(ee), within_px,
                                               1.6 * blur_px + 2.0)
        for (i, k), ek, wk, lk in zip(at, e, width, level):
            levels[i, k] = lk
            if wk <= widest[i]:
                offsets[i, k] = around[i, k] + ek
    # a stretch part hidden (a box over a corner reaching into it) shows less of the band's light
    # than the others, and its fit is no measure of the border's place
    dim = levels < BAND_LEVEL_SHARE * np.nanmedian(levels) if np.isfinite(levels).any() else np.zeros_like(levels, bool)
    offsets[dim] = np.nan
    return offsets


def step_blur(gray: np.ndarray, quad_px: np.ndarray, at_px: np.ndarray, camera: Camera | None = None,
              reach_px: float = 12.0, trim: float = 0.3, step: float = 0.5, widen: int = 0) -> np.ndarray:
    """(4,) the width (px) of the box blur that the steepest rising edge within ``reach_px`` of
    ``at_px[i]`` (px along side i's inward normal from ``quad_px``) shows across that side, NaN
    where none is found, inf where it runs on past the widest window read (below): sqrt(12) times
    the spread of the profile's derivative, the blur kernel seen edge-on.  ``gray`` should be linear in light.  Motion blur smears luma as much as colour;
    JPEG's half-resolution chroma leaves luma sharp, so a luma edge tells the two apart.

    A rise that runs on past either end of the window (a smear wider than it: 30 px across a 20
    px border merges the border's two edges into one ramp) is read again in a window twice as wide,
    up to ``widen`` times, from the same steepest place: read as nothing, a 30-45 px smear across
    one pair of sides left the other pair's 1.6 px as the pad's smear, and its edges were fitted as
    sharp ones, 7-20 % of a side out."""
    g = gray if gray.dtype == np.float32 else gray.astype(np.float32)
    q = np.asarray(quad_px, np.float64).reshape(4, 2)
    m = int(np.clip(np.linalg.norm(np.roll(q, -1, axis=0) - q, axis=1).max() * (1 - 2 * trim), 6, 40))
    out = np.full(4, np.nan)
    todo = np.ones(4, bool)
    for k in range(widen + 1):
        reach = reach_px * 2 ** k
        rs = [np.arange(at_px[i] - reach, at_px[i] + reach + 1e-9, step) for i in range(4)]
        runs_on = np.zeros(4, bool)
        for i, (prof, seen) in enumerate(_cross_profiles(g, q, rs, m, trim, camera)):
            if not todo[i] or seen.sum() < 2:
                continue
            r = rs[i]
            y = prof[seen].mean(axis=0)
            d = np.clip(np.diff(y), 0.0, None)
            x = (r[1:] + r[:-1]) / 2
            first = np.abs(x - at_px[i]) <= reach_px  # the steepest place is the first window's
            p = int(np.argmax(np.where(first, d, -1.0)))
            low = d < 0.15 * d[p]
            before, after = np.nonzero(low[:p])[0], np.nonzero(low[p:])[0]
            if d[p] <= 0:
                continue
            if not len(before) or not len(after):
                runs_on[i] = True
                continue
            v, xx = d[before[-1]:p + after[0] + 1], x[before[-1]:p + after[0] + 1]
            c = float(np.sum(v * xx) / v.sum())
            out[i] = float(np.sqrt(12.0 * np.sum(v * (xx - c) ** 2) / v.sum()))
        todo = runs_on
        if not todo.any():
            break
    out[todo] = np.inf
    return out


def rise_offsets(gray: np.ndarray, quad_px: np.ndarray, camera: Camera | None = None, lo: float = -2.0,
                 hi: float = 5.0, span: float = 3.0, step: float = 0.25, trim: float = 0.25,
                 apart_px: float | None = None) -> np.ndarray:
    """(4,) where (px along each side's inward normal, within ``lo``..``hi``) the mean profile across
    the middle of each side of ``quad_px`` rises over ``span`` px going inward by at least 0.6 of its
    largest rise there, nearest the side: the edge of a bright inside, found before a narrow fit (0
    for a side out of view).  Rises are of log brightness: a hard shadow's edge (a quarter of the
    light) rises less than white paper over a dark checker, in the shadow or out of it.

    ``apart_px``: the width of a border around the bright inside, whose own outer edge rises too.
    Where the rise taken is still climbing at ``lo`` (it peaks further out, its flank all that is
    in reach) and another rise peaks in reach a border's width in from where that one peaks
    (within a pixel, and at least 0.3 of the largest), that inner one is the inside's edge and
    is taken, at its peak.  (fisheye_glare_deck at 14 m: a swollen colour outline predicted the
    white field 1.9-2.8 px outside its edge, in a border washed bright by glare; the pad's outer
    edge, 4.2 px further out, was taken by its flank, and the field's side fitted on it, the pose
    7 % low and refused.  Where no such inner rise is there, the flank is taken as before: an
    outline whose colour lies a few px inside the pad puts the field's own edge beyond ``lo``.)"""
    q = np.asarray(quad_px, np.float64).reshape(4, 2)
    g = gray if gray.dtype == np.float32 else gray.astype(np.float32)
    m = int(np.clip(np.linalg.norm(np.roll(q, -1, axis=0) - q, axis=1).max() * (1 - 2 * trim), 6, 40))
    k = max(1, int(round(span / 2 / step)))
    r = np.arange(lo - k * step, hi + k * step + 1e-9, step)
    beyond = None  # each side's rise read outward of ``lo`` (only where some side needs it: once)
    out = np.zeros(4)
    for i, (prof, seen) in enumerate(_cross_profiles(g, q, [r] * 4, m, trim, camera)):
        rise, at, level = _rises(prof, seen, r, k)
        if rise is None or not rise.max() > 0:
            continue
        strong = rise >= 0.6 * rise.max()  # of the strong rises the nearest: a shadow's edge further in is not it
        j = np.flatnonzero(strong)[np.argmin(np.abs(at[strong]))]
        out[i] = at[j]
        if apart_px and strong[:j + 1].all() and rise[0] >= rise[1]:
            if beyond is None:
                r_out = np.arange(lo - apart_px - 2.0 - k * step, lo + k * step + 1e-9, step)
                beyond = [_rises(p, s, r_out, k) for p, s in _cross_profiles(g, q, [r_out] * 4, m, trim, camera)]
            inner = _inner_edge(rise, at, level, j, k, *beyond[i][:2], apart_px)
            if inner is not None:
                out[i] = inner
    return out


def _rises(prof: np.ndarray, seen: np.ndarray, r: np.ndarray, k: int) -> tuple:
    """``(rise, at, level)``: the mean of the ``seen`` profiles, in log brightness, rising over ``2 k``
    samples of ``r``, at the middle of each, and its level there; ``(None,) * 3`` where fewer than
    3 are seen."""
    if seen.sum() < 3:
        return None, None, None
    y = np.log(prof[seen].mean(axis=0) + 1.0)
    return y[2 * k:] - y[:-2 * k], r[k:-k], y[k:-k]


def _inner_edge(rise, at, level, j: int, k: int, out_rise, out_at, apart_px: float) -> float | None:
    """For :func:`rise_offsets`: the peak of a rise in reach (``rise`` at ``at``, the log brightness
    ``level`` there) ``apart_px`` (within a pixel) in from where the side's outermost rise peaks, read
    beyond ``lo`` (``out_rise`` at ``out_at``), and leading into an inside brighter than all the
    profile reaches between the flank taken (index ``j``) and it (``k``: the samples a rise spans
    either side of its middle); ``None`` when there is none.

    (Without the last: in unseen61's first frame, a 70 px pad under 6.6 px of smear, the rise
    peaking just beyond ``lo`` was the white field's own edge, the profile white 2 px in; a rise
    out of a black shape in the field, a border's width further in and no brighter, was taken
    for the field's edge, and the outline refused as swollen.)"""
    if out_rise is None:
        return None
    p_out = out_at[np.argmax(out_rise)]
    peak = (rise >= np.r_[np.inf, rise[:-1]]) & (rise >= np.r_[rise[1:], np.inf])
    peak &= (rise >= 0.3 * max(rise.max(), out_rise.max())) & (np.abs(at - p_out - apart_px) <= 1.0)
    for i in np.flatnonzero(peak)[np.argsort(np.abs(at[peak] - p_out - apart_px), kind="stable")]:
        inside = level[min(i + k, len(level) - 1)]
        if level[j:max(i - k, j) + 1].max() < inside:
            return float(at[i])
    return None
