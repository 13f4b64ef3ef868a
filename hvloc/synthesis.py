"""The pad drawn where it should be and smeared as it should be: a pose under motion blur too
heavy for any feature.

A gust near the ground smears 40-80 px in a 30 ms exposure: Harris corners, Lucas-Kanade, ORB
and the markers' contours all fail, and the flow tracker's chain breaks.  Yet what the frame
should show is known: the pad's printed texture (``pad.png``), the pose a moment ago, the
camera's velocity (from its last poses), its turn rate (the gyro) and the exposure.  So the
texture is drawn at the predicted pose, once for each of a few instants of the exposure
(centred on the frame's time), and the drawings averaged in linear light: the frame as it would
look had the prediction been right.  The drawing is then aligned to the frame (OpenCV's ECC, an
affine warp, coarse to fine), and the pad points the warp carries into the frame are the pose's
correspondences.

Both images are read relative to their local white (a shadow across the pad, the drone's own,
is no part of the drawing), and compared only where the whole smear lies on the pad's field (the
black-on-white print) or on the border within :data:`FIELD_NEAR_PX` of it.  Not on the rest of a
wide border: read relative to its local white it is dark in the frame (the white there is the
ground's beside it, or the field's) but light in the drawing (nothing is drawn beyond the pad, so
the white there is the border's own).  Compared over it, a 1.5 m pad with a 0.15 m border over snow
at 1.5-2.3 m was posed 10-24 mm off, from the true pose as from the prediction (unseen49); now
1-5 mm.  A drawing that
aligns with a correlation under :data:`MIN_CC`, a warp that turns or scales far, or a frame the
smeared pad fills too little of gives nothing.  Nor does a pad whose scale the frame cannot hold:
one predicted under :data:`MIN_PAD_PX`, a frame much softer than the drawing (blurred to match, up
to :data:`MAX_BLUR_SHARE` of the side), or an alignment that, restarted a little larger or smaller,
does not come back (:func:`_scale_unsettled`).  Deterministic: ECC's iterations are bounded by a
count.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from pad_design.texture import texture_to_pad

from .features import srgb_to_linear
from .geometry import Camera, ideal_grid, invert, pad_plane_homography
from .phases import Detection
from .shutter import Twist

WORK_PX = 400        # the alignment runs on the predicted pad's window shrunk to this many px on its longer side (not enlarged)
MIN_WINDOW_PX = 24   # ... which must be at least this large (frame px), and hold this many squared where the smear is on the pad
# the predicted pad's side must span this many frame px: on smaller pads the drawing, sharp where the
# frame is not, is aligned by trading scale for blur (JPEG 65 views, predictions 7 % off or exact: at
# 35-40 px the alignments ended 2-7 % off in scale, one from the exact pose; at 45 px within 2 %, at
# 50-80 px within 1 %; /work/scratch/synprobe_t.py)
MIN_PAD_PX = 45.0
MAX_INSTANTS = 12    # instants of the exposure drawn (fewer when the predicted smear is short)
INSTANT_PX = 3.0     # ... one per this many px of predicted smear (window px)
MIN_FILL = 0.3       # share of the predicted pad's part in view where the whole smear lies on the pad
# the aligned drawing's correlation with the frame where it is compared (both read relative to their
# white): the default pad smeared 35-65 px at 0.45-1.2 m 0.83-0.9, another pad's texture 0.18-0.58 (with
# the whole border compared, 0.85-0.9 against 0.6-0.68: the border is every pad's)
MIN_CC = 0.75
WHITE_PX = 21        # the local white is the brightest within this many window px (then smoothed)
# the drawing is compared on the pad's field and the border within this many window px of it: there
# both images' local white is the field's (farther out the drawing's is the border's own, nothing
# being drawn beyond the pad, and the frame's the ground's beside it)
FIELD_NEAR_PX = WHITE_PX // 2
MAX_TURN_DEG = 8.0   # the warp may turn the drawing this much at most ...
MAX_SCALE = 1.15     # ... and scale it within 1 / this and this
MAX_SHIFT = 0.15     # ... and move it this share of the window's longer side ...
# ... and stretch it at most this much more along one axis than across (its singular values' ratio, less 1).  To
# first order a stretch is a tilt: seen at an angle a from its normal, a pad tilted d more is foreshortened by about
# tan(a) d more, and the pose from the carried points takes the stretch as that tilt.  The prediction's tilt comes
# from a pose at most SYNTHESIS_MAX_AGE_S old, and the warps of right ones stretched little (gusty_blur, fuzz seed 437:
# 28 drawn poses, 0.2-2.4 %, the poses 0.2-0.9 degrees off); a warp aligned under glare on a glossy pad stretched
# 9.4 % at cc 0.76 (branch exp/glare-rings, fuzz seed 445's frame 73, 32 degrees oblique: its pose 11.3 degrees off
# stating 1.3, 21.7 % of the height)
MAX_STRETCH = 0.05
SHUTTER_BANDS = 8    # a rolling shutter's frame is drawn in this many bands of rows, each at its own time
GRID = 5             # pad points per side whose images are the correspondences (those in the smear's area)
BLUR_STEPS_PX = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0)  # blurs tried on the drawing to match a softer frame ...
BLUR_GAIN = 0.002    # ... each taken over the last only for this much more correlation
BLUR_ROUNDS = 2      # ... read again after aligning with the blurred drawing (from a truer warp)
# ... and a frame softer than that by more than this share of the pad's side is refused: blurred alike,
# the drawing still aligns about 1-1.4 times that share small (50-80 px pads under 1-4 px of Gaussian
# blur, predictions 7 % off: /work/scratch/synprobe_b.py)
MAX_BLUR_SHARE = 0.03
SCALE_PROBE = 0.05   # the alignment, started again this share larger and smaller than where it ended ...
SCALE_SETTLED = 0.3  # ... must come back within this share of the probe (else the frame does not hold its scale)
ECC_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 60, 1e-5)  # bounded: deterministic
ALIGN_SIGMA_PX = 1.0  # a correspondence's noise, in window px: the warp's own error (calibrated on rendered gusts)


def _shrunk(k: float, a: np.ndarray, b: np.ndarray, mask: np.ndarray, warp: np.ndarray) -> tuple:
    """``(a, b, mask, warp)`` at ``k`` times the size (``k`` < 1; the warp's shift with them), or as they are."""
    if k >= 1:
        return a, b, mask, warp
    ak = cv2.resize(a, None, fx=k, fy=k, interpolation=cv2.INTER_AREA)
    bk = cv2.resize(b, None, fx=k, fy=k, interpolation=cv2.INTER_AREA)
    mk = cv2.resize(mask, (ak.shape[1], ak.shape[0]), interpolation=cv2.INTER_NEAREST)
    wk = warp.copy()
    wk[:, 2] *= k
    return ak, bk, mk, wk


def _matched_blur(a: np.ndarray, b: np.ndarray, mask: np.ndarray, warp: np.ndarray) -> float:
    """The Gaussian blur (sigma, window px; one of :data:`BLUR_STEPS_PX`) that, added to the drawing
    ``b`` aligned by ``warp``, makes it correlate best with the frame ``a`` over ``mask``: 0 when the
    drawing is as soft as the frame.

    ECC aligns a sharp drawing to a softer frame by shrinking it: the blur spreads the dark cells'
    edges into the white, and a smaller drawing puts more edge where the frame's is (sharp 50-80 px
    pads under a Gaussian blur of 2-3 px, predictions 7 % off either way: aligned 1-9 % small, the
    same from both sides, so no probe of the scale would notice)."""
    h, w = a.shape
    best, best_cc = 0.0, -np.inf
    for s in BLUR_STEPS_PX:
        bs = cv2.GaussianBlur(b, (0, 0), s) if s > 0 else b
        seen = cv2.warpAffine(bs, warp, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
        cc = cv2.computeECC(a, seen, mask)
        if cc > best_cc + BLUR_GAIN:
            best, best_cc = s, cc
        elif cc < best_cc:  # past the best (the correlation rises to the frame's blur, then falls)
            break
    return best


def _scale_unsettled(a: np.ndarray, b: np.ndarray, mask: np.ndarray, warp: np.ndarray) -> float | None:
    """``None`` when the frame ``a`` settles the scale of the alignment ``warp`` of the drawing ``b``
    (over ``mask``); else how far (a share of the scale) an alignment started :data:`SCALE_PROBE`
    larger or smaller ends from it.

    A far pad's interior is a few pixels per feature: ECC's affine then keeps the scale it starts
    from, which is the prediction's, and a pose made from it is as wrong as the one it was predicted
    from (unseen45: an outline 7.6 % low was carried to a drawn pose 10.9 % off, a false accept).
    So the alignment is started again from its own end scaled up and down about the window's centre:
    where the frame holds the scale both come back, where it does not they stay about where they
    were put (unseen45's 39-40 px pads: ends 2-5 % apart; its 48-58 px ones aligned within 1 % of
    the true scale from predictions 10 % off either way; /work/scratch/synscale.py)."""
    h, w = a.shape
    c = np.array([w / 2.0, h / 2.0])
    worst = 0.0
    for z in (1 + SCALE_PROBE, 1 / (1 + SCALE_PROBE)):
        start = warp.astype(np.float64).copy()
        start[:, :2] = warp[:, :2] * z
        start[:, 2] = warp[:, 2] + (warp[:, :2] @ c) * (1 - z)  # scaled about the warp's image of the centre
        try:
            _, got = cv2.findTransformECC(a, b, start.astype(np.float32), cv2.MOTION_AFFINE,
                                          ECC_CRITERIA, mask, 5)
        except cv2.error:
            return 1.0
        ratio = math.sqrt(abs(np.linalg.det(got[:, :2].astype(np.float64)) / np.linalg.det(warp[:, :2].astype(np.float64))))
        worst = max(worst, abs(math.log(ratio)))
    return None if worst <= SCALE_SETTLED * SCALE_PROBE else math.expm1(worst)


def _white_relative(img: np.ndarray) -> np.ndarray:
    """``img`` over its local white (the brightest nearby, smoothed): shading and shadows, which the
    drawing lacks, divided out; the texture's black on white kept."""
    env = cv2.GaussianBlur(cv2.dilate(img, np.ones((WHITE_PX, WHITE_PX), np.uint8)), (0, 0), WHITE_PX / 3.0)
    return cv2.divide(img, np.maximum(env, np.float32(1e-3 * max(float(img.max()), 1e-6))))


def box_levels(image: np.ndarray, side_m: float, smallest_px: int) -> list:
    """``[(texture, texels per metre), ...]``: ``image`` (the whole pad, ``side_m`` across) and its
    halves, quarters, ... down to ``smallest_px``, each box-filtered as a pixel averages and each
    the whole pad in a whole number of texels (its own texels per metre).  Not a Gaussian pyramid:
    ``cv2.pyrDown``'s samples sit on every other texel, half a texel off the box's centre at each
    level, and a pad drawn from its levels moved by up to 0.75 px (49 px across, 12 m;
    ``PadSynthesis.draw`` against the finest level drawn 4 x 4 per pixel and averaged)."""
    levels = [(image, image.shape[1] / side_m)]
    while min(levels[-1][0].shape[:2]) > smallest_px:
        h, w = levels[-1][0].shape[:2]
        nw, nh = max(1, round(w / 2)), max(1, round(h / 2))
        levels.append((cv2.resize(levels[-1][0], (nw, nh), interpolation=cv2.INTER_AREA), nw / side_m))
    return levels


def level_for(levels: list, side_m: float, H: np.ndarray, scale: float = 1.0) -> tuple:
    """``(texture, texels per metre)``: the coarsest of ``levels`` (:func:`box_levels`) with at least
    as many texels across the pad as the pad spans pixels at its centre (``H``: pad (x, y) m ->
    ideal pixel, drawn ``scale`` times enlarged): texels no larger than a drawn pixel, so the
    drawing's bilinear reads lose no detail the pixel keeps."""
    ends = cv2.perspectiveTransform(np.array([[[-0.5 * side_m, 0.0], [0.5 * side_m, 0.0]]]), H)[0]
    span = float(np.linalg.norm(ends[1] - ends[0])) * scale
    k = 0
    while k + 1 < len(levels) and levels[k + 1][1] * side_m >= span:
        k += 1
    return levels[k]


class PadSynthesis:
    """The pad's texture in linear light at box-filtered scales; :meth:`locate` aligns it, drawn at
    a predicted pose and smeared, to a frame."""

    def __init__(self, pad):
        self.pad = pad
        gray = cv2.cvtColor(np.ascontiguousarray(pad.texture_rgb), cv2.COLOR_RGB2GRAY)
        self.levels = box_levels(srgb_to_linear(gray), pad.side_m, 64)

    def reach_m(self, camera: Camera, height_m: float) -> float:
        """How far off (m, across the pad's plane) a prediction from ``height_m`` above the pad may
        be for the alignment to carry the drawing back: :data:`MAX_SHIFT` of the window's longer
        side, the window being the pad or, near the ground, the frame's view of its plane."""
        view = max(camera.width / camera.fx, camera.height / camera.fy) * max(height_m, 0.0)
        return MAX_SHIFT * min(self.pad.side_m, view)

    def window(self, camera: Camera, box, scale: float, own: bool = False) -> np.ndarray:
        """``(h, w, 2)`` float32: the ideal pinhole place of each pixel of the frame's window ``box``
        (x0, y0, x1, y1) resampled at ``scale``: pixel ``j`` of the window is the frame's
        ``x0 + (j + 0.5) / scale - 0.5``.  Through a lens, read off the whole frame's grid (made
        once per camera), or with ``own`` undistorted pixel by pixel: for a small window, whose
        first call would otherwise make that grid (780 ms at 1280x960, in flight; 8,100 pixels
        take about 1 ms)."""
        x0, y0, x1, y1 = box
        w, h = max(1, int(round((x1 - x0) * scale))), max(1, int(round((y1 - y0) * scale)))
        u = (x0 + (np.arange(w) + 0.5) / scale - 0.5).astype(np.float32)
        v = (y0 + (np.arange(h) + 0.5) / scale - 0.5).astype(np.float32)
        uu, vv = np.meshgrid(u, v)
        if not camera.has_distortion:
            return np.dstack([uu, vv])
        if own:
            px = np.column_stack([uu.ravel(), vv.ravel()]).astype(np.float64)
            return camera.undistort_pixels(px).reshape(h, w, 2).astype(np.float32)
        return cv2.remap(ideal_grid(camera, dtype=np.float32), uu, vv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)

    def draw(self, camera: Camera, grid: np.ndarray, scale: float, pose_at, times, row_dt=None) -> tuple:
        """``(image, inside, field)`` on ``grid`` (:meth:`window`): the texture seen from
        ``pose_at(tau)`` (``T_P_C``) at each instant of ``times``, averaged in linear light (float32),
        where every one of them sees the pad, and where every one sees the pad's field, within its
        border (uint8 0/1 each).  ``row_dt``: each grid row's exposure time relative to the frame's (a
        rolling shutter; drawn in bands of rows, each at its middle row's time)."""
        h, w = grid.shape[:2]
        acc = np.zeros((h, w), np.float32)
        inside = np.ones((h, w), np.uint8)
        field = np.ones((h, w), np.uint8)
        border_m = self.pad.geometry.border_m
        edges = np.linspace(0, h, (SHUTTER_BANDS if row_dt is not None else 1) + 1).round().astype(int)
        bands = [(a, b, 0.0 if row_dt is None else float(row_dt[(a + b - 1) // 2])) for a, b in zip(edges, edges[1:]) if b > a]
        for tau in times:
            for a, b, dt in bands:
                H = pad_plane_homography(camera, pose_at(tau + dt))  # pad (x, y) m -> ideal pixel
                tex, ppm = level_for(self.levels, self.pad.side_m, H, scale)
                M = np.linalg.inv(H @ texture_to_pad(self.pad.side_m, ppm))  # ideal pixel -> texel
                uv = cv2.perspectiveTransform(np.ascontiguousarray(grid[a:b]).reshape(-1, 1, 2), M).reshape(b - a, w, 2)
                acc[a:b] += cv2.remap(tex, uv, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
                n = tex.shape[0]
                inside[a:b] &= (cv2.inRange(uv, (0.5, 0.5), (n - 1.5, n - 1.5)) > 0).astype(np.uint8)
                e = border_m * ppm + 0.5
                field[a:b] &= (cv2.inRange(uv, (e, e), (n - 1 - e, n - 1 - e)) > 0).astype(np.uint8)
        return acc * np.float32(1.0 / len(times)), inside, field

    def locate(self, gray: np.ndarray, camera: Camera, cam2pad: np.ndarray, vel_P=None, rate_C=None,
               exposure_s: float = 0.0, line_s: float = 0.0, ref_row: float | None = None) -> tuple:
        """``(Detection | None, reason)``: the pad's points and their pixels in ``gray`` (uint8),
        from the texture drawn at the predicted ``cam2pad`` (``T_P_C``) and smeared by the camera's
        velocity ``vel_P`` (m/s, pad frame) and turn rate ``rate_C`` (rad/s, camera frame) over
        ``exposure_s`` centred on the frame's time; a rolling shutter (``line_s`` between rows,
        ``ref_row`` the frame time's) draws each band of rows at its own time."""
        half = self.pad.side_m / 2
        quad = camera.project_from(cam2pad, np.array([[-half, half, 0], [half, half, 0], [half, -half, 0],
                                                      [-half, -half, 0]]))
        if not np.isfinite(quad).all():
            return None, "the predicted pad is not wholly in front of the camera"
        side = float(np.mean(np.linalg.norm(quad - np.roll(quad, 1, axis=0), axis=1)))
        if side < MIN_PAD_PX:
            return None, f"the predicted pad spans {side:.0f} px (< {MIN_PAD_PX}): too few to align its drawing by"
        v = np.zeros(3) if vel_P is None else np.asarray(vel_P, np.float64)
        r = np.zeros(3) if rate_C is None else np.asarray(rate_C, np.float64)
        e = max(float(exposure_s), 0.0)
        # how far the prediction's motion smears the pad's centre over the exposure (frame px)
        depth = max(float(invert(cam2pad)[2, 3]), 1e-3)
        smear = min(camera.fx, camera.fy) * e * (float(np.linalg.norm(r)) + float(np.linalg.norm(v)) / depth)
        # the window: the predicted pad and a margin (the smear, and a tenth of its size), in the frame
        lo, hi = quad.min(axis=0), quad.max(axis=0)
        m = max(16.0, smear + 0.1 * float(np.max(hi - lo)))
        box = (max(0, int(lo[0] - m)), max(0, int(lo[1] - m)),
               min(camera.width, int(math.ceil(hi[0] + m))), min(camera.height, int(math.ceil(hi[1] + m))))
        if box[2] - box[0] < MIN_WINDOW_PX or box[3] - box[1] < MIN_WINDOW_PX:
            return None, "the predicted pad is out of view"
        scale = min(1.0, WORK_PX / max(box[2] - box[0], box[3] - box[1]))
        grid = self.window(camera, box, scale)
        h, w = grid.shape[:2]
        n = int(np.clip(math.ceil(smear * scale / INSTANT_PX), 1, MAX_INSTANTS))
        taus = np.linspace(-e / 2, e / 2, n) if n > 1 else [0.0]
        motion = Twist(v, r)

        def pose_at(tau):
            return motion.moved(cam2pad, tau)

        row_dt = None
        if line_s:
            ref = (camera.height - 1) / 2.0 if ref_row is None else float(ref_row)
            row_dt = (box[1] + (np.arange(h) + 0.5) / scale - 0.5 - ref) * float(line_s)
        drawn, inside, field = self.draw(camera, grid, scale, pose_at, taus, row_dt)
        inside = cv2.erode(inside, np.ones((5, 5), np.uint8))
        compared = cv2.dilate(field, np.ones((2 * FIELD_NEAR_PX + 1,) * 2, np.uint8)) & inside
        frame_rect = np.array([[0, 0], [camera.width, 0], [camera.width, camera.height], [0, camera.height]], np.float32)
        seen = cv2.intersectConvexConvex(quad.astype(np.float32), frame_rect)[0] * scale * scale  # the pad in view, window px
        fill = float(inside.sum()) / max(seen, 1.0)
        if fill < MIN_FILL:
            return None, f"the whole smear lies on the pad over {100 * fill:.0f} % of its part in view (< {100 * MIN_FILL:.0f} %)"
        if compared.sum() < (MIN_WINDOW_PX * scale) ** 2:
            return None, f"the whole smear lies on the pad's field or the border beside it over {int(compared.sum())} " \
                         f"window px of its part in view (< {(MIN_WINDOW_PX * scale) ** 2:.0f})"
        x0, y0, x1, y1 = box
        crop = srgb_to_linear(np.ascontiguousarray(gray[y0:y1, x0:x1]))
        frame = cv2.resize(crop, (w, h), interpolation=cv2.INTER_AREA) if (w, h) != crop.shape[::-1] else crop
        a, b = _white_relative(frame), _white_relative(drawn)
        warp = np.eye(2, 3, dtype=np.float32)
        cc = -1.0
        # coarse to fine: half the work size (where it is large enough), then the work size.  The
        # coarse pass is only a start: one that does not converge, or converges somewhere the
        # drawing does not match (a 25 px pad halved is a few features), is dropped and the fine
        # pass starts from the prediction (bench_v2's x_field_rs_oblique at 13 m: 0.17 there)
        coarse = 0.5 if min(w, h) >= 4 * MIN_WINDOW_PX else 1.0
        for k in sorted({coarse, 1.0}):
            ak, bk, mk, wk = _shrunk(k, a, b, compared, warp)
            try:
                cc, wk = cv2.findTransformECC(ak, bk, wk, cv2.MOTION_AFFINE,
                                              ECC_CRITERIA, mk, 5)
            except cv2.error:
                if k < 1:
                    continue
                return None, "the smeared drawing did not align"
            if k < 1 and cc < MIN_CC:
                continue
            warp = wk.copy()
            warp[:, 2] /= k
        # the frame may be softer than the drawing (a defocused lens, a smear the prediction missed):
        # the drawing blurred as much, and aligned again from there
        blur = 0.0  # the blur added to the drawing, squared (window px)
        for _ in range(BLUR_ROUNDS):
            sigma = _matched_blur(a, b, compared, warp)
            if sigma == 0.0:
                break
            b = cv2.GaussianBlur(b, (0, 0), sigma)
            blur += sigma ** 2
            try:
                cc, warp = cv2.findTransformECC(a, b, warp, cv2.MOTION_AFFINE,
                                                ECC_CRITERIA, compared, 5)
            except cv2.error:
                return None, "the smeared drawing, blurred as the frame is, did not align"
        if math.sqrt(blur) / scale > MAX_BLUR_SHARE * side:
            return None, (f"the frame is softer than the smeared drawing by {math.sqrt(blur) / scale:.1f} px "
                          f"(> {100 * MAX_BLUR_SHARE:.0f} % of the pad's {side:.0f} px): its scale cannot be held")
        A = warp[:, :2].astype(np.float64)
        turn = math.degrees(math.atan2(A[1, 0] - A[0, 1], A[0, 0] + A[1, 1]))
        zoom = math.sqrt(abs(np.linalg.det(A)))
        shift = float(np.linalg.norm(warp[:, 2] + (A - np.eye(2)) @ np.array([w / 2.0, h / 2.0])))
        if cc < MIN_CC:
            return None, f"the smeared drawing aligns with correlation {cc:.2f} (< {MIN_CC})"
        if abs(turn) > MAX_TURN_DEG or not 1 / MAX_SCALE < zoom < MAX_SCALE or shift > MAX_SHIFT * max(w, h):
            return None, f"the smeared drawing moved too far to align ({turn:.1f} deg, x{zoom:.2f}, {shift:.0f} px)"
        sv = np.linalg.svd(A, compute_uv=False)
        stretch = float(sv[0] / max(sv[1], 1e-12) - 1.0)
        if stretch > MAX_STRETCH:
            return None, (f"the smeared drawing stretched {100 * stretch:.1f} % along one axis to align (> "
                          f"{100 * MAX_STRETCH:g} %): a tilt its prediction did not have, or a warp the frame pulled")
        # (at half size where the pad is still twice the smallest drawn there: a 50-60 px pad halved
        # is too few pixels to hold its scale, and was refused)
        off = _scale_unsettled(*_shrunk(0.5 if side * scale >= 4 * MIN_PAD_PX else 1.0, a, b, compared, warp))
        if off is not None:
            return None, (f"the smeared drawing's scale is not settled by the frame (started {100 * SCALE_PROBE:.0f} % "
                          f"off it, the alignment ends {100 * off:.1f} % off)")
        # pad points on a grid, where the smear lies on the pad: drawn at the predicted pose (window
        # px), carried into the frame by the inverse warp (frame(x) ~ drawing(warp x))
        g = (np.arange(GRID) + 0.5) / GRID - 0.5
        P = np.array([[x, y, 0.0] for y in g for x in g]) * self.pad.side_m
        px = camera.project_from(cam2pad, P)
        ok = np.isfinite(px).all(axis=1)
        q = (np.nan_to_num(px) - [x0, y0] + 0.5) * scale - 0.5
        qi = np.round(q).astype(int)
        ok &= (qi[:, 0] >= 0) & (qi[:, 0] < w) & (qi[:, 1] >= 0) & (qi[:, 1] < h)
        ok[ok] = inside[qi[ok, 1], qi[ok, 0]] > 0
        if ok.sum() < 4:
            return None, f"{int(ok.sum())} pad points where the smear lies on the pad (< 4)"
        Wi = cv2.invertAffineTransform(warp).astype(np.float64)
        x = q[ok] @ Wi[:, :2].T + Wi[:, 2]
        frame_px = (x + 0.5) / scale - 0.5 + [x0, y0]
        info = {"by": "synthesis", "cc": round(float(cc), 3), "smear_px": round(smear, 1), "instants": n,
                "stretch": round(stretch, 4),
                "blur_px": round(math.sqrt(blur) / scale, 2),
                "fill": round(fill, 2), "px_sigma_blur": ALIGN_SIGMA_PX / scale}
        return Detection(P[ok], frame_px, "texture", info), "ok"
