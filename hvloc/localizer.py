"""The hierarchical localizer: Approaching (pad outline), Adjustment (finder markers),
Touchdown (Harris + pyramidal Lucas-Kanade to a keyframe), phase switching with hysteresis and
fallback, and false-pose detection (vision vs IMU rotation jumps, reprojection and motion gates).

``process`` never raises on an image: anything it cannot use gives ``status="lost"`` with a
reason.
"""
from __future__ import annotations

import math
import time
import traceback
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from . import phases as ph
from .config import LocalizerConfig
from .geometry import (GRAVITY_MPS2, Camera, heading_turn, invert, make_transform, matrix_from_quat_xyzw, rotation_angle,
                       pad_plane_homography, rotation_z, rotvec_between, so3_exp, so3_log, transform_points)
from .pose import (PIXEL_SIGMA, PoseResult, SharedNoise, outlying_points, point_residuals, projection_sigma_px,
                   solve_planar_pose)
from .shutter import RollingShutter, Twist, VelocityFilter
from .work import ImageWork, array_key

PHASES = ("approaching", "adjustment", "touchdown")
# the phase an estimate reports: its method's, the paper's three; the texture (the pad found by its print, or
# drawn and smeared where the last pose predicts it) is every phase's last resort and reports the phase it
# was tried in: a far pad under smear posed by its drawing at 13 m said "touchdown" to the flight stack
METHOD_PHASE = {"outline": "approaching", "markers": "adjustment", "flow": "touchdown", "texture": None}
DEFAULT_T_B_C = make_transform(np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]), (0.0, 0.0, -0.05))


# which methods each phase tries, in order (the first that gives a pose wins)
METHOD_ORDER = {"approaching": ("outline", "markers", "texture"),
                "adjustment": ("markers", "outline", "flow", "texture"),
                "touchdown": ("markers", "flow", "outline", "texture")}


# a frame after one without a pose is also tried for the texture as if the camera had come down to this
# share of the last pose's height (the frame shrunk for there, the squares of the pad a view there fits
# in): unseen88 lost at 0.26 m and came back at 0.17-0.19 m, where the last height shrank it too little
STALE_LOWEST_SHARE = 0.5
TEXTURE_COLD_EVERY = 4  # with no height known, in Approaching the texture is tried on every 4th frame without a pose
HEADING_MAX_AGE_S = 30.0  # the pad's heading learnt from a pose names outlines this long (the AHRS drifts)
SYNTHESIS_MAX_AGE_S = 0.35  # the pad is drawn at a pose predicted from one at most this old (hvloc.synthesis) ...
# ... or, where the IMU's rows carry the velocity filter's position on, this old, as long as that position's
# doubt (1 sigma, its largest axis) stays within the alignment's reach (hvloc.synthesis.PadSynthesis.reach_m)
SYNTHESIS_COAST_S = 1.0
SHUTTER_VELOCITY_DOUBT = 0.5  # the share of a pose that the shutter's velocity moved, counted uncertain (its lag)
UNKNOWN_SPEED_MPS = 0.5  # per axis: the speed relative to the pad a pose is counted uncertain by while no velocity is known (shutter, smear)
SHUTTER_MIN_SPEED_MPS = 0.1  # ... and at least this speed, spread over the axes, where two poses give one
RATE_SPREAD_MIN_PX = 0.05  # a doubt in the gyro's rate that unrolls no point by this much is not solved for
# Lucas-Kanade's tracks (the flow's, the texture's refinement) in a smeared frame shift together by this
# share of each one's own smear over the exposure, counted in the pose's covariance (:meth:`_smear_spread`) ...
TRACK_SMEAR_DOUBT = 0.1
TRACK_SMEAR_MIN_PX = 4.0  # ... where some track is smeared this far
HULL_CORNER_PX = 1.0  # a hull's corner's noise (px): a cut pad's colour hull, a grey pad's blob, before its design fit places it
# the design fit's tilt is held where the frame's motion smears the pad more than this (px) over the exposure:
# the fit's blur is isotropic, and a smear along one way is taken up by the tilt.  On unseen100 (1-4 px of
# motion smear) the fitted tilt put 44-100 px pads 0.14-0.39 % of the height off in the median, held 0.08-0.24
TILT_MAX_SMEAR_PX = 1.0
# ... and not fitted at all where it smears a corner over this share of the pad's side: the isotropic blur stands
# in for a smear of up to ~a quarter of the side (views of 24-100 px pads smeared a quarter of their side, fitted
# from the labelled pose: 0.5-2.4 % of the height off at worst; half their side: up to 21 %)
DESIGN_FIT_MAX_SMEAR_SHARE = 0.3
# on a tilting deck whose tilt is not tracked, the design fit fits the pad's tilt from this size (px), where
# elsewhere it holds the IMU's below hvloc.texfit.TILT_MIN_SIDE_PX: held there, the pad's four corners fix its
# tilt too loosely and the pose is refused (fuzz seeds 114, 117, 142: 35-47 far frames each)
UNTRACKED_TILT_MIN_SIDE_PX = 24.0
# A grey outline read only faintly as the design (hvloc.phases.GREY_NEAR_ASYM_NCC) is taken where its design fit
# reads at the full bars, or faintly there where the fitted drawing, lit square by square, matches the frame this
# well.  A glossy, stained pad's sheen and dirt dilute the plain read of what a quarter turn changes (the fuzz's
# fz363, fz382, fz387: 26-120 px pads read 0.36-0.55 through the labelled outline, leading the next naming by
# 0.47-0.66, and were refused from 11 m down to 3.7 m); the drawing's own lighting takes much of the sheen up.
# 563 design fits on eleven grey scenes (scratch/greyfit.py: started from the labelled outline, from it shifted
# 15-25 % of the side, scaled 0.8 or 1.2, or with a corner a fifth of the side off): of those placed within 3 %
# of the side, 105 read faintly, their drawing correlating 0.88-0.98 (median 0.95, 73 % at this bar or more);
# misplaced 5-9 % and read faintly (9, all started from a corner a fifth off, unsquare, on a tilting deck whose
# wrong tilt the fit held), 0.92 at most.  The read is needed too: misplaced fits correlated up to 0.955, and
# read as nothing
FAINT_READ_FIT_NCC = 0.93
# ... and a tilt fitted there, below TILT_MIN_SIDE_PX, is believed only as far as the fits of the frames before
# agree: the deck swells over seconds, and successive fits of a slowly tilting pad scatter by their own error
# (times sqrt 2), whatever its cause: the RMS step over sqrt 2 is the sigma of the worst axis where one axis
# dominates (a far pad's flat one), sqrt 2 more than each axis's where both scatter alike.  A stained 39 px pad under a fisheye (fuzz seed 117) was fitted 8-9
# degrees off in single frames stating 2, its fits stepping 1.5-11 degrees from frame to frame; a clean
# 46-60 px one (seed 114) 0-2 degrees off, stepping 0.1-2.  Until FAR_TILT_STEPS such steps are seen (each
# within FAR_TILT_GAP_S of the last), the tilt is doubted as the deck's swing.
FAR_TILT_STEPS = 3
FAR_TILT_GAP_S = 0.5
FAR_TILT_KEEP = 8  # the last so many steps judged
# ORB's keypoints (a texture pose its drawing did not refine) land anywhere along a smear: a uniform spread
# over it, 1/sqrt(12) of its length (unseen84/85, at 0.2-0.28 m under 31-52 px: 3.9-5.8 mm off stating 1.9-2.4)
KEYPOINT_SMEAR_DOUBT = 0.29
KEYPOINT_SIGMA_PER_RMS = 1.0  # ... and each keypoint's own noise is its fit's residual RMS (at least PIXEL_SIGMA)
# an outline whose sides an edge fit placed is not taken where the motion predicts over this many times the
# smear read across one of them, and more than the edge fit holds to (:meth:`HierarchicalLocalizer._edge_fit_outrun`)
EDGE_FIT_OUTRUN = 2.0
TWIST_WINDOW_S = 0.45  # the shutter's velocity filter forgets after this long without a pose (the IMU's rows are kept as long)
# a flow pose refused for its reprojection RMS under a rolling shutter is solved again with the velocity its rows'
# skew asks for (:meth:`HierarchicalLocalizer._velocity_from_image`), when that velocity lies within this squared
# Mahalanobis distance of the velocity filter's prediction (3 degrees of freedom, 99 %) ...
SHUTTER_VELOCITY_SEARCH_CHI2 = 11.34
SHUTTER_VELOCITY_SEARCH_PX = 1.0  # ... each track's pixel counted this far off (1 sigma) against that prediction
VELOCITY_SEARCH_STEPS = 4  # ... Gauss-Newton steps at most
VELOCITY_FROM_IMAGE_MIN_POINTS = 12  # ... and a pad pose (markers, texture) of at least this many points too


def next_phase(phase: str, h: float | None, last_method: str, cfg: LocalizerConfig) -> str:
    """The switching policy: thresholds with hysteresis on the last accepted height ``h``.
    A plain function so that the benchmark's sweep replays exactly this policy."""
    if h is None:
        return phase
    hy = cfg.hysteresis_m
    if phase == "approaching" and h < cfg.adjust_height_m - hy:
        return "adjustment"
    if phase == "adjustment":
        if h > cfg.adjust_height_m + hy:
            return "approaching"
        if h < cfg.touchdown_height_m and last_method != "markers":
            return "touchdown"
    if phase == "touchdown" and h > cfg.touchdown_height_m + hy:
        return "adjustment"
    return phase


def policy_height(last_height: float | None, last_t: float, t: float, cfg: LocalizerConfig) -> float | None:
    """The height the switching policy may use: the last accepted one, unless it is stale (then
    ``None``: without it a localizer whose only method is gated by height could never recover)."""
    if last_height is None or t - last_t > cfg.prior_timeout_s:
        return None
    return last_height


OUTER_AGREE_PX = 0.45  # the pad's outer corners join a markers pose when the markers' own fit puts them this close (RMS)
# the least pad (px, as its white field's corners put it) that those corners alone may place (HierarchicalLocalizer._small_field_refused)
FIELD_MIN_SIDE_PX = 20.0
# the design's fit may move the outline's corners by this share of its side at most: further, the two measures of
# one pad disagree and neither is taken (far_wide JPEG 50: a 21 px pad's corners 2.6 px from its design's, kept, 11.5 %
# of the height off, "ok"; the only such pose of four wide-lens scenes', 1,585)
DESIGN_FIT_MAX_MOVE = 0.1
MARKER_SIGMA_PER_RMS = 3.0  # a three-marker pose's pixel noise: this times its image-only residual RMS
MARKER_MIN_SIGMA_PX = 0.1  # ... and at least this
MARKER_SHARED_PER_SIGMA = 1.0  # fewer markers: the shift and swell their corners share, in units of their own noise
# a texture pose's position in the pad's plane is no surer than this share of a texel: the pad is known
# as a raster (pad.png), drawn and printed to a fraction of a texel.  Landed at 0.15-0.18 m over a
# texture printed at 1000 px/m (4-5 px a texel), unseen84's texture poses were 0.2-0.3 mm off stating
# 0.1-0.2 (NEES 20-42), and the flow chained from them with it
TEXTURE_TEXEL_DOUBT = 0.25
MARKER_MIN_MODULE_PX = 2.0  # a finder marker's module must span this many pixels to be found (render/phase.py's rule)


def method_allowed(method: str, h: float | None, cfg: LocalizerConfig, markers_seen_below_m: float = 0.0) -> bool:
    """Markers are not tried far above the adjustment height, nor above ``markers_seen_below_m``
    (where this pad's markers still resolve in this camera: a 1.5 m pad's markers at 1080p do at
    16 m, far above the 8 m the default pad and camera switch at)."""
    top = max(cfg.adjust_height_m + cfg.hysteresis_m, markers_seen_below_m)
    return not (method == "markers" and h is not None and h > top)


def motion_gate(cam2pad: np.ndarray, t: float, last_cam2pad: np.ndarray | None, last_t: float,
                cfg: LocalizerConfig) -> str:
    """Reprojection-independent physical gate: no faster motion than ``max_speed_mps``."""
    if cam2pad[2, 3] <= 0:
        return "camera below the pad plane"
    if last_cam2pad is None:
        return ""
    dt = max(t - last_t, 1e-3)
    jump = float(np.linalg.norm(cam2pad[:3, 3] - last_cam2pad[:3, 3]))
    allowed = cfg.max_speed_mps * dt + 0.05 + 0.05 * float(last_cam2pad[2, 3])
    return f"moved {jump:.2f} m in {dt:.3f} s (> {allowed:.2f} m possible)" if jump > allowed else ""


@dataclass
class Estimate:
    t: float
    phase: str
    status: str                  # ok | rejected | lost
    cam2pad: np.ndarray | None   # T_P_C
    n_corr: int = 0
    rms_px: float = float("nan")
    cov: np.ndarray | None = None
    ms: float = 0.0
    reason: str = ""
    method: str = ""
    extras: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def height(self) -> float:
        return float(self.cam2pad[2, 3]) if self.cam2pad is not None else float("nan")


def check_image(image) -> tuple:
    """``(rgb uint8 (H, W, 3) or None, gray uint8 (H, W) or None, reason)``: what the phases can use."""
    if not isinstance(image, np.ndarray):
        return None, None, f"image is a {type(image).__name__}, not a numpy array"
    if image.ndim not in (2, 3) or image.size == 0:
        return None, None, f"image has shape {image.shape}"
    if image.ndim == 3 and image.shape[2] not in (1, 3, 4):
        return None, None, f"image has {image.shape[2]} channels (1, 3 or 4 supported)"
    if min(image.shape[:2]) < 16:
        return None, None, f"image is too small ({image.shape[1]}x{image.shape[0]})"
    img = image
    if img.dtype != np.uint8:
        if not np.issubdtype(img.dtype, np.number) or np.issubdtype(img.dtype, np.complexfloating):
            return None, None, f"image dtype {img.dtype} is not numeric"
        f = np.nan_to_num(img.astype(np.float64), nan=0.0, posinf=0.0, neginf=0.0)
        hi = float(f.max()) if f.size else 0.0
        scale = 255.0 if np.issubdtype(img.dtype, np.floating) and hi <= 1.0 else (255.0 / 65535.0 if hi > 255 else 1.0)
        img = np.clip(f * scale, 0, 255).astype(np.uint8)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    if img.ndim == 2:
        return None, np.ascontiguousarray(img), ""
    if img.shape[2] == 4:
        img = img[..., :3]
    rgb = np.ascontiguousarray(img)
    return rgb, cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY), ""


def frame_time(t) -> tuple:
    """``(t as a float, "")``, or ``(nan, why)`` when ``t`` is not a finite number of seconds."""
    if isinstance(t, (str, bytes, bool, np.bool_)):
        return float("nan"), f"timestamp {t!r} is a {type(t).__name__}, not a number of seconds"
    try:
        f = float(t)
    except (TypeError, ValueError, OverflowError):
        return float("nan"), f"timestamp {t!r} is not a number of seconds"
    if not math.isfinite(f):
        return float("nan"), f"timestamp {f} is not finite"
    return f, ""


def guarded_process(process, image, t, imu, phase: str) -> "Estimate":
    """Run ``process(image, t_float, imu)`` so that it never raises: a bad timestamp or an internal
    error gives ``status="lost"`` with the reason; the time spent is in ``ms``.  Shared by every
    localizer behind the ``process(image, t, imu) -> Estimate`` protocol."""
    t0 = time.perf_counter()
    tf, why = frame_time(t)
    if why:
        est = Estimate(tf, phase, "lost", None, reason=why)
    else:
        try:
            est = process(image, tf, imu)
            if not isinstance(est, Estimate):  # a localizer from elsewhere that broke the protocol
                raise TypeError(f"process returned {type(est).__name__}, not an Estimate")
        except Exception as err:  # never raise on an image: report it
            est = Estimate(tf, phase, "lost", None, reason=f"internal error: {type(err).__name__}: {err}",
                           extras={"traceback": traceback.format_exc(limit=3)})
    est.ms = (time.perf_counter() - t0) * 1000.0
    return est


def imu_rotation(imu) -> np.ndarray | None:
    """``R_W_B`` from an IMU sample: a 3x3 matrix, a quaternion (qx, qy, qz, qw), or an imu.csv row;
    ``None`` for anything that is not a finite, proper rotation (NaN, a zero quaternion, a wrong
    shape): the localizer then runs on vision alone for that frame."""
    return imu_check(imu)[0]


IMU_ROW = 11  # an imu.csv row: t, gyro xyz, accel xyz, AHRS quaternion (xyzw)


def imu_check(imu) -> tuple:
    """``(R_W_B or None, why)``: what :func:`imu_rotation` gives, with the reason when it is unusable.
    A block of rows (the IMU's samples since the last frame, oldest first) gives its last row's."""
    if imu is None:
        return None, ""
    try:
        a = np.asarray(imu, np.float64)
    except (TypeError, ValueError):
        return None, f"imu sample of type {type(imu).__name__} is not numeric"
    if a.ndim == 2 and a.shape[1] == IMU_ROW:
        if len(a) == 0:
            return None, "imu block has no rows"
        a = a[-1]
    if a.shape == (IMU_ROW,):
        a = a[7:11]
    if a.shape not in ((3, 3), (4,)):
        return None, (f"imu sample has shape {a.shape} (a 3x3 rotation, an (x, y, z, w) quaternion, an imu.csv "
                      "row or a block of them)")
    if not np.isfinite(a).all():
        return None, "imu attitude is not finite"
    if a.shape == (4,):
        if not 0.5 < np.linalg.norm(a) < 2.0:
            return None, f"imu quaternion has norm {np.linalg.norm(a):.3g} (not a rotation)"
        return matrix_from_quat_xyzw(a), ""
    if np.abs(a @ a.T - np.eye(3)).max() > 1e-3 or np.linalg.det(a) < 0:
        return None, "imu attitude matrix is not a rotation"
    return a, ""


GYRO_TURN_MAX_GAP_S = 0.05  # rows further apart than this: the turn between them is not known


def gyro_turn(imu, since_t: float | None, R: np.ndarray | None) -> tuple:
    """``(R_B0_B1 or None, time)``: the body's turn ``R`` (from B0, the body when the turn began)
    carried on over a block's gyro rows after IMU time ``since_t``, each row's rate held since the
    row before; and the last row's time, which the next block's rows follow.  ``None`` (the turn
    unknown until it begins again) where there is none to carry on, ``since_t`` is not known, or the
    block has no usable rows, rows not in time order or rows too far apart
    (:data:`GYRO_TURN_MAX_GAP_S`): a block of rows only (a bare attitude or one row says no turn)."""
    rows = _gyro_rows(imu, 0.0)  # (its usable rows: a corrupt one leaves a gap, checked below)
    if rows is None or len(rows[0]) < 2 or np.any(np.diff(rows[1]) <= 0.0):
        return None, None
    g, tt, _ = rows
    last = float(np.asarray(imu, np.float64)[-1, 0])
    t = last + tt
    if R is None or since_t is None or not since_t <= last:
        return None, last
    new = t > since_t
    dt = np.diff(np.r_[since_t, t[new]])
    if np.any(dt > GYRO_TURN_MAX_GAP_S):
        return None, last
    for w, d in zip(g[new], dt):
        R = R @ so3_exp(w * d)
    return R, last


def imu_rate(imu, span_s: float = 0.0) -> np.ndarray | None:
    """The body's angular rate (rad/s, FLU) of an imu.csv row (its gyro), or ``None`` for a bare
    attitude or a row whose gyro is not finite or past any gyro's range (:data:`GYRO_MAX_RAD_S`).
    Of a block of rows: the mean of its usable rows within ``span_s`` before its last one (the
    frame's readout; ``0``: the last row alone).  One sample carries the airframe's
    vibration (0.02-0.2 rad/s on a multirotor, as much as the turn the rolling shutter corrects for);
    the mean over the rows the frame was read in is the turn the image shows."""
    return _readout(_gyro_rows(imu, span_s))[0]


def _gyro_rows(imu, span_s: float):
    """``(gyro, time before the last row, within span_s)`` of a block's usable rows (a gyro sample
    finite and within :data:`GYRO_MAX_RAD_S`, a finite time), or ``None`` for no block of rows."""
    try:
        a = np.asarray(imu, np.float64)
    except (TypeError, ValueError):
        return None
    if a.ndim == 1:
        a = a[None]
    if a.ndim != 2 or a.shape[1] != IMU_ROW:
        return None
    g, tt = a[:, 1:4], a[:, 0] - a[-1, 0]
    good = np.isfinite(g).all(axis=1) & np.isfinite(tt)
    good[good] = np.linalg.norm(g[good], axis=1) <= GYRO_MAX_RAD_S
    return g[good], tt[good], tt[good] >= -span_s - 1e-9


RATE_DOUBT_MIN_ROWS = 4  # a block of fewer rows says nothing of its own scatter


def imu_rate_doubt(imu, span_s: float = 0.0) -> np.ndarray | None:
    """The standard deviation of :func:`imu_rate`'s mean (rad/s per body axis), from the block's own
    scatter: each axis's rows about a line through them (the drone's own turn taken out), over the
    square root of the rows the mean is taken over.  ``None`` where the block has fewer than
    :data:`RATE_DOUBT_MIN_ROWS` usable rows (one row says nothing of its noise).

    A multirotor's gyro carries 0.02-0.2 rad/s of its rotors' vibration in every sample, aliased
    where nothing filters it before sampling; the mean over a 30 ms readout keeps 0.03-0.1 rad/s of
    it, which turns the rolling shutter's unrolling by up to 3 px across a 1280-px frame.  Counted as
    white noise, which a tone is not: on the airframe suite's vibrating tiers the mean's error was
    0.6 of this in rms per axis (never beyond 3 of it), conservative."""
    return _readout(_gyro_rows(imu, span_s))[1]


def _readout(rows) -> tuple:
    """``(mean, its doubt, scatter)`` of :func:`_gyro_rows`' rows within the readout: their mean
    rate, the rows' :func:`_gyro_scatter` over the square root of how many are averaged, and that
    scatter (``None`` for what the rows cannot say)."""
    if rows is None or not rows[2].any():
        return None, None, None
    g, _, within = rows
    scatter = _gyro_scatter(rows)
    return g[within].mean(axis=0), None if scatter is None else scatter / math.sqrt(int(within.sum())), scatter


def _gyro_scatter(rows) -> np.ndarray | None:
    """Per axis, the scatter of :func:`_gyro_rows`' rows about a line through them (the drone's
    own turn taken out), or ``None`` for fewer than :data:`RATE_DOUBT_MIN_ROWS` rows."""
    if rows is None or len(rows[0]) < RATE_DOUBT_MIN_ROWS or np.ptp(rows[1]) <= 0.0:
        return None
    g, tt, _ = rows
    coef = np.polyfit(tt, g, 1)
    res = g - (np.outer(tt, coef[0]) + coef[1])
    return np.sqrt((res ** 2).sum(axis=0) / (len(g) - 2))


RATE_WINDOW_S = 0.1  # s: the last rows of a block whose ones before the readout join the readout's mean rate


def imu_turn(imu, span_s: float = 0.0) -> tuple:
    """``(rate, doubt)``: :func:`imu_rate`'s mean over the readout joined with the mean of the rows
    before it within the block's last :data:`RATE_WINDOW_S`, each weighed by its variance (per body
    axis), and the doubt of the two together; ``(imu_rate, imu_rate_doubt)`` where either says
    nothing (a single row, no rows before the readout).  The block is read once.  The rows before
    the readout lag the turn: where the two means differ beyond their noise, the difference squared
    counts as the earlier rows' doubt, so a sharp turn keeps the readout's own mean.

    The mean over a 30 ms readout keeps 0.03-0.1 rad/s of a multirotor's vibration (stop 42:
    0.064 rms on the airframe suite's vibrating tier), and a small pad at 5-9 m moved 50-100 mm with
    it.  Over 13 rolling-shutter descents (the airframe suite's four datasets, bench_v2's two,
    unseen40) Adjustment RMSE 19.1 -> 15.1 mm (a_slow_vibrating 36.2 -> 24.8, a_action_vibrating
    15.4 -> 13.0, unseen40 8.7 -> 6.9), touchdown 2.3 -> 2.2 mm; on unseen43 15.0 -> 14.3 mm.
    Shrinking the mean toward zero by its doubt instead helped the slow camera (21.7 mm) and hurt
    the manoeuvring ones (a_action_vibrating 17.5, unseen43 16.4): their turns are real."""
    rows = _gyro_rows(imu, span_s)
    rate, doubt, scatter = _readout(rows)
    if doubt is None:
        return rate, None
    g, tt, within = rows
    before = ~within & (tt >= -RATE_WINDOW_S - 1e-9)
    if span_s <= 0.0 or not before.any():
        return rate, doubt
    earlier, d_earlier2 = g[before].mean(axis=0), scatter ** 2 / int(before.sum())
    lag2 = np.maximum(0.0, (earlier - rate) ** 2 - doubt ** 2 - d_earlier2)
    w_now, w_before = 1.0 / np.maximum(doubt ** 2, 1e-30), 1.0 / np.maximum(d_earlier2 + lag2, 1e-30)
    return (w_now * rate + w_before * earlier) / (w_now + w_before), 1.0 / np.sqrt(w_now + w_before)


def imu_for(localizer, imu):
    """What ``localizer.process`` is given of the IMU: a block of rows as is where the localizer
    says it takes blocks (``IMU_BLOCK = True``, as hvloc's own do), else the block's last row, as
    the protocol gave before blocks (one row, a quaternion or a rotation), so that a localizer
    written for a single row keeps working."""
    if imu is None or getattr(localizer, "IMU_BLOCK", False):
        return imu
    return imu_last_row(imu)


def imu_last_row(imu):
    """A block's last row; anything else as it is."""
    try:
        a = np.asarray(imu)
    except (TypeError, ValueError):
        return imu
    if a.ndim == 2 and a.shape[1] == IMU_ROW and len(a):
        return a[-1]
    return imu


ACCEL_MAX_MPS2 = 200.0  # an accelerometer's 16 g (157 m/s^2): past it, a corrupt sample
IMU_DENSE_S = 0.02  # rows further apart than this (under 50 Hz) are not integrated


def imu_accel(imu, t: float, R_corr=None, since_t: float | None = None) -> list:
    """``[(time, a_W, dt), ...]``: each usable row of an IMU block (every value finite, the
    accelerometer within its range) as the body's acceleration in the world (m/s^2: its
    accelerometer's specific force turned by its own attitude, gravity taken out), its time on the
    camera's clock (the block's last row is taken to be at ``t``) and the time since the row before
    it.  ``R_corr(R_W_B)``: the attitude with its learnt error taken out.  ``since_t``: the IMU time
    of the row before the block's first (the last block's last), from which the first row is
    integrated; without it the first row only starts the clock.

    That first row is a frame's share of the motion: one of four rows at 50 Hz from a 200 Hz IMU.
    Dropped, the rows integrated too little velocity (a twentieth at 10 Hz: gusty_blur's 0.8 s
    without a pose near the ground, 0.41 of the rows' 0.43 m/s), and at 50 Hz they covered too
    little of the time for the velocity filter to take them (three quarters, under its four
    fifths): it never used the IMU, and coasted (unseen81, 50 Hz: its velocity 3-4 times further
    off than with the rows)."""
    try:
        a = np.asarray(imu, np.float64)
    except (TypeError, ValueError):
        return []
    if a.ndim != 2 or a.shape[1] != IMU_ROW or len(a) < 1 or not np.isfinite(a[-1, 0]):
        return []
    before = np.full((1, IMU_ROW), np.nan)
    if since_t is not None and math.isfinite(since_t) and since_t < a[0, 0]:
        before[0, 0] = since_t
    out = []
    for prev, row in zip(np.vstack([before, a[:-1]]), a):
        dt = row[0] - prev[0]
        f = row[4:7]
        if not (np.isfinite(row).all() and 0.0 < dt and np.linalg.norm(f) <= ACCEL_MAX_MPS2):
            continue
        R, _ = imu_check(row)
        if R is None:
            continue
        if R_corr is not None:
            R = R_corr(R)
        out.append((t - (a[-1, 0] - row[0]), R @ f - np.array([0.0, 0.0, GRAVITY_MPS2]), dt))
    return out


GYRO_MAX_RAD_S = 40.0  # a MEMS gyro's full scale is 2000 deg/s (35 rad/s): a rate past it is a corrupt sample


def clock_event(last_t: float | None, last: "Estimate | None", t: float, prior_timeout_s: float) -> tuple:
    """``(event, note)`` keeping a localizer's state consistent with time: ``"reset"`` when ``t`` is
    older than the last frame (a new run: a new sequence on the same localizer, a replay),
    ``"drop"`` when the last accepted pose is older than ``prior_timeout_s`` (no gate, ROI or
    tracker may reason from it), else ``""``."""
    if last_t is not None and t < last_t:
        return "reset", f"time went back {last_t - t:.3g} s: state reset"
    if last is not None and t - last.t > prior_timeout_s:
        return "drop", f"last pose {t - last.t:.3g} s old: prior dropped"
    return "", ""


class AHRSTiltBias:
    """The AHRS's slow roll and pitch error, learnt from the image, and taken out of its attitude.

    An AHRS's gravity is off by a slowly drifting rotation in the body frame (accelerometer bias,
    misalignment; a few tenths of a degree over tens of seconds).  The gravity prior pulls every
    pose toward it, and a 0.3 degree tilt is 0.5 % of the height sideways: on bench_v1 nearly all
    of the Adjustment error (sim800 at 4-6 m: 23.5 mm sideways, 2 mm in height).  Each pose
    also says, from the image alone, where the pad's normal is: noisily (markers at 6-10 m about a
    degree a frame, at 4-6 m half a degree, below 3 m a few hundredths) but without that drift, and
    independently from frame to frame (autocorrelation under 0.2 at lags of 1 to 10 frames).

    A Kalman filter on the error (body frame, per axis): it drifts as a first-order Gauss-Markov
    process of standard deviation ``sigma0_deg`` (the gravity prior's, the AHRS's stated accuracy)
    and correlation time ``tau_s``; each image-only normal measures it with its fit's tilt sigma
    and ``WHITE_SHARE`` of ``sigma0_deg`` more (what the AHRS's own noise moves from row to row,
    which no average removes).  A measurement further than 3 sigma + 1 degree from the estimate is
    a bad fit, not the AHRS, and is skipped.  Heading is not touched (gravity says nothing about it).

    It was a weighted mean of the disagreements, faded over ``tau_s`` and shrunk toward zero, each
    weighed by its fit's sigma scaled by the noise that kind of pose had shown: bench_v1's
    Adjustment RMSE with it on (5 s) sim800 11.4 -> 12.9 mm, field1080 33.1 -> 26.8 mm; the
    filter (10 s): 10.8 and 25.7 mm.  The mean's weights knew neither how far the error drifts
    between frames nor how much is left to learn: replayed on sim800's logged tilts, its estimate
    at 4-6 m was 0.22 degrees off per axis, the filter's 0.18, the raw AHRS's 0.26."""

    WHITE_SHARE = 0.2  # 0.1 degrees of a 0.5 degree AHRS

    def __init__(self, tau_s: float, sigma0_deg: float = 0.5):
        self.tau_s, self.var0 = float(tau_s), math.radians(sigma0_deg) ** 2
        self.white_var = math.radians(self.WHITE_SHARE * sigma0_deg) ** 2
        self.reset()

    def reset(self) -> None:
        self.x = np.zeros(3)
        self.P = self.var0  # per axis
        self.t: float | None = None
        self.n = 0

    @property
    def estimate(self) -> np.ndarray:
        """The AHRS's error rotation (body frame, rad): AHRS attitude = true attitude @ exp(this)."""
        return self.x

    @property
    def white_deg(self) -> float:
        """The AHRS's own row-to-row noise (deg), which no average of its error removes."""
        return math.degrees(math.sqrt(self.white_var))

    @property
    def sigma_deg(self) -> float:
        """How well the estimate is known, per axis (deg)."""
        return math.degrees(math.sqrt(self.P))

    def corrected(self, R_W_B: np.ndarray | None) -> np.ndarray | None:
        if R_W_B is None or self.tau_s <= 0 or self.n == 0:
            return R_W_B
        return R_W_B @ so3_exp(-self.x)

    def update(self, R_W_B_raw: np.ndarray, R_B_C: np.ndarray, normal_img_C, fit_sigma_deg: float,
               t: float, mirror_C=None, mirror_chi2_gap: float = float("inf")) -> None:
        """One image-only pad normal (C) with its fit's tilt sigma, seen at ``t`` with the raw AHRS
        attitude; ``mirror_C``: the other planar solution's normal (at its own minimum), whose fit
        is ``mirror_chi2_gap`` worse (squared noise units).

        A far pad's fit can have two minima several degrees apart that fit alike, the AHRS's up
        choosing between them; there the chosen normal is worse than its fit's sigma says and biased
        the same way from frame to frame (bench_v1's markers_only field1080 at 6-8 m: 32 of 88 poses
        had a second minimum 6.5 degrees away in the median, 1.4 worse in chi^2; their normals were
        1.56 degrees off per axis, -0.51 on average in x, against a stated 1.73; poses with one
        minimum 1.06 against 1.46).  Taken at face value the filter learnt that bias: Adjustment
        RMSE 34 -> 54 mm there.  So: a second minimum d away that fits only ``gap`` worse says the
        cost is flatter than its curvature at the first (a bowl of the fit's sigma would put it
        d^2/sigma^2 higher), and the normal counts as that uncertain (d^2/gap, gap at least 1); and
        the two are weighed as a Gaussian sum, each by its fit and by how well it agrees with the
        estimate, the estimate's variance counting how far apart they are."""
        if (self.tau_s <= 0 or normal_img_C is None or not math.isfinite(t) or not math.isfinite(fit_sigma_deg)
                or fit_sigma_deg <= 0):
            return
        u = R_W_B_raw.T @ np.array([0.0, 0.0, 1.0])  # the AHRS's up, body frame

        def error(normal_C):
            # AHRS = true @ exp(e): its up is exp(-e) applied to the true one, so up - true = u x e and
            # e across u is (up - true) x u
            n = R_B_C @ np.asarray(normal_C, np.float64)
            return np.cross(u - n / np.linalg.norm(n), u)

        if self.t is not None and t > self.t:  # the drift since the last measurement
            a = math.exp(-(t - self.t) / self.tau_s)
            self.x *= a
            self.P = a * a * self.P + (1.0 - a * a) * self.var0
        self.t = t if self.t is None else max(self.t, t)
        R = math.radians(fit_sigma_deg) ** 2
        cands = [(error(normal_img_C), 0.0)]
        if mirror_C is not None and math.isfinite(mirror_chi2_gap):
            cands.append((error(mirror_C), -0.5 * max(mirror_chi2_gap, 0.0)))
            # flatter than the fit's curvature says: as uncertain as d^2 / gap
            apart = float(np.sum((cands[1][0] - cands[0][0]) ** 2))
            R = max(R, apart / max(mirror_chi2_gap, 1.0))
        S = self.P + R + self.white_var
        gate = 3.0 * math.sqrt(S) + math.radians(1.0)
        nus, logw = [], []
        for e, lw in cands:  # a normal further than the gate from the estimate is a bad fit, not the AHRS
            nu = e - self.x
            d2 = float(nu @ nu)
            if math.sqrt(d2 / 2.0) <= gate:
                nus.append(nu)
                logw.append(lw - d2 / (2.0 * S))
        if not nus:
            return
        w = np.exp(np.array(logw) - max(logw))
        w /= w.sum()
        gain = self.P / S
        means = [self.x + gain * nu for nu in nus]
        x = sum(wi * m for wi, m in zip(w, means))
        self.P = self.P * (1.0 - gain) + sum(wi * float((m - x) @ (m - x)) for wi, m in zip(w, means)) / 2.0
        self.x = x
        self.n += 1


def constant_rate_prediction(x: np.ndarray, P: np.ndarray, q: float, dt: float) -> tuple:
    """A value and its rate ``x`` (first axis; any further axes share ``P``), with covariance ``P``,
    carried ``dt`` on under white acceleration of spectral density ``q``: ``(x, P)`` then."""
    F = np.array([[1.0, dt], [0.0, 1.0]])
    Q = q * np.array([[dt ** 3 / 3.0, dt * dt / 2.0], [dt * dt / 2.0, dt]])
    return F @ x, F @ P @ F.T + Q


class DeckTilt:
    """A tilting deck's tilt in the world, tracked from the image, for the gravity prior.

    On a deck that rolls and pitches (``pad_tilt_deg`` of the config) the IMU's up is the pad's
    normal only to within the deck's tilt, and a far pad's pose tilted by d is off sideways by the
    height times d.  The tilt moves smoothly (a swell of seconds): the image measures it well from
    many points (markers, texture: their own normal, the AHRS's attitude turning it into the world),
    and between such poses a Kalman filter per world axis (tilt and its rate; white acceleration of
    what a swell of ``pad_tilt_deg`` at :data:`PERIOD_MIN_S` has) predicts it.  Its prediction is the
    up the poses are drawn to, as sure as the filter says; with nothing recent, the IMU's up as sure
    as the deck's RMS tilt.  A measurement further than 3 sigma + 1 degree from the prediction is a
    bad fit (a mirror pose), not the deck, and is skipped."""

    PERIOD_MIN_S = 4.0  # the shortest swell it follows at full amplitude

    def __init__(self, amplitude_deg: float, ahrs_sigma_deg: float):
        self.ahrs = math.radians(ahrs_sigma_deg)
        self.widen(amplitude_deg)
        self.reset()

    @classmethod
    def fastest_rate(cls, amplitude):
        """How fast (per second, in ``amplitude``'s unit) a deck tilting ``amplitude`` may turn: its
        swell at :data:`PERIOD_MIN_S` through level."""
        return amplitude * 2.0 * math.pi / cls.PERIOD_MIN_S

    def widen(self, amplitude_deg: float) -> None:
        """How far the deck may tilt (degrees), what it is tracked and bounded with; its track kept."""
        self.A = math.radians(amplitude_deg)
        w = 2.0 * math.pi / self.PERIOD_MIN_S
        self.q = (self.A * w * w) ** 2  # the white acceleration's spectral density (rad^2 / s^3)
        self.rate0 = self.fastest_rate(self.A)

    def reset(self) -> None:
        self.x = np.zeros((2, 2))  # [tilt, rate] x [world x, world y] (rotation vector, rad)
        self.P = np.zeros((2, 2))  # shared by both axes
        self.t: float | None = None
        self.by_design = False

    def _predicted(self, t: float):
        return constant_rate_prediction(self.x, self.P, self.q, max(t - self.t, 0.0))

    def _known(self, P) -> bool:
        return math.sqrt(P[0, 0]) < self.A / math.sqrt(2.0)

    def prior(self, t: float) -> tuple:
        """``(tilt (3,) rad, sigma deg, tolerance deg, tracked)`` at ``t``: the rotation vector
        (world) that takes the world's up to the pad's normal, how sure it is (with the AHRS's
        error), how far from it the pad may lie (3 sigma, at most the deck's amplitude), and whether
        the image has told it (else the IMU's up, as sure as the deck's RMS tilt)."""
        if self.t is not None:
            x, P = self._predicted(t)
            if self._known(P):
                tilt = x[0]
                n = float(np.linalg.norm(tilt))
                if n > self.A:
                    tilt = tilt * (self.A / n)
                s = math.hypot(self.ahrs, math.sqrt(P[0, 0]))
                return np.array([tilt[0], tilt[1], 0.0]), math.degrees(s), math.degrees(min(self.A, 3.0 * s)), True
        return np.zeros(3), math.degrees(math.hypot(self.ahrs, self.A / math.sqrt(2.0))), math.degrees(self.A), False

    def update(self, t: float, normal_W, sigma_deg: float, by_design: bool = False) -> None:
        """One image-only pad normal in the world with its fit's tilt sigma (deg), seen at ``t``;
        ``by_design``: fitted by the pad's design (an outline's design fit), which :attr:`by_design` keeps
        while only such fits have told the track since it was started."""
        if normal_W is None or not math.isfinite(t) or not math.isfinite(sigma_deg) or sigma_deg <= 0:
            return
        z = rotvec_between([0.0, 0.0, 1.0], normal_W)[:2]  # (about a horizontal axis: its z is 0)
        R = math.radians(sigma_deg) ** 2 + self.ahrs ** 2
        if self.t is None or not self._known(self._predicted(t)[1]):
            self.x = np.array([z, [0.0, 0.0]])
            self.P = np.diag([R, self.rate0 ** 2])
            self.t, self.by_design = t, by_design
            return
        x, P = self._predicted(t)
        S = P[0, 0] + R
        if np.abs(z - x[0]).max() > 3.0 * math.sqrt(S) + math.radians(1.0):
            return
        self.by_design = self.by_design and by_design
        K = P[:, 0] / S
        self.x = x + np.outer(K, z - x[0])
        self.P = P - np.outer(K, K) * S
        self.t = max(self.t, t)


def _mirror_refusal(pose: PoseResult, deck_tilt_deg: float = 0.0) -> str:
    """Why a pose whose flip nothing decided (:func:`hvloc.pose.solve_planar_pose`: no IMU, no
    previous pose, the mount's level up undecided; or the IMU's up, where the pad may tilt
    ``deck_tilt_deg`` from it and both lie within that) is refused, or ``""``.  (fz307, a grey camera
    over a 6 degree deck with the IMU on, was told "no IMU" here: its user would look for the wrong fault.)"""
    if pose.flip_choice != "ambiguous":
        return ""
    apart = float(np.linalg.norm(pose.other_cam2pad[:3, 3] - pose.cam2pad[:3, 3]))
    why = (f"and the IMU's up does not tell them apart: both lie within the {deck_tilt_deg:g} deg a deck may tilt"
           if deck_tilt_deg > 0
           else "and no IMU, previous pose or level flight tells them apart")
    return (f"the pose and its mirror, {apart:.2f} m apart, fit alike (reprojection RMS {pose.rms_px:.2f} and "
            f"{pose.other_rms_px:.2f} px), {why}")


def up_in_camera(R_W_B, T_B_C) -> np.ndarray | None:
    """The world's up direction in the camera frame, from the IMU attitude (None without one)."""
    return None if R_W_B is None else (R_W_B @ T_B_C[:3, :3]).T @ np.array([0.0, 0.0, 1.0])


def _fitted_up(cam2pad: np.ndarray, info: dict) -> dict:
    """A detection's ``fitted_up_C`` and ``fitted_up_sigma_deg`` where the design fit (``info``,
    :func:`hvloc.texfit.fit_pose_to_design`) fitted the pad's tilt: the pad's normal in the camera as
    ``cam2pad`` (the fit) has it, and the fit's doubt of it, for the pose's gravity prior in place of
    the IMU's (:meth:`HierarchicalLocalizer._posed`).  Its corners alone, solved with the IMU's up,
    kept half of what the fit found (unseen104: heights +0.38 % held, +0.19 % so, -0.06 % with the
    fitted up): a 100 px pad's four corners say little about a few tenths of a degree of tilt.  Its
    doubt: on unseen104's 55-130 px pads 0.02-0.17 degrees, the tilt 0.005-0.18 off (0.6 of it in
    the median, 1.3 at most); doubted as the IMU's up, the poses were 0.19 of their stated sigma
    off.  ``{}`` otherwise."""
    if "tilt_deg" not in info:
        return {}
    return {"fitted_up_C": cam2pad[:3, :3].T @ np.array([0.0, 0.0, 1.0]), "fitted_up_sigma_deg": info["tilt_sigma_deg"]}


def _image_only_up(fitted_up_C, fitted_sigma_deg: float, prior_up_C, prior_sigma_deg: float) -> dict:
    """``{"design_normal_C", "design_tilt_sigma_deg"}``: the pad's normal as a design fit's image alone
    fixed it, its fitted normal ``fitted_up_C`` (doubt ``fitted_sigma_deg``) with the prior it was weighed
    against (``prior_up_C``, ``prior_sigma_deg``) taken out again, as Gaussians in the tilt's tangent plane:
    what a deck's track may take as a measurement of its own, not its prediction fed back.  ``{}`` where the
    fit told nearly nothing beyond its prior (doubt within 5 % of it)."""
    sm, sp = math.radians(fitted_sigma_deg), math.radians(prior_sigma_deg)
    if not (math.isfinite(sm) and math.isfinite(sp) and 0.0 < sm < 0.95 * sp):
        return {}
    gain = sp * sp / (sp * sp - sm * sm)  # the image's normal lies this much further from the prior than the fit's
    n0 = np.asarray(prior_up_C, np.float64) / np.linalg.norm(prior_up_C)
    normal = so3_exp(gain * rotvec_between(n0, fitted_up_C)) @ n0
    return {"design_normal_C": normal, "design_tilt_sigma_deg": math.degrees(sm * sp / math.sqrt(sp * sp - sm * sm))}


def outline_rms_share(est: "Estimate") -> float:
    """An outline pose's reprojection RMS over the pad's side (px), with hidden corners' larger
    noise (``px_sigma_scale``) allowed for; 0 for any other pose.  Four corners fix the pose's six
    degrees of freedom with two to spare, so a corner a tenth of the side off (a shadow or JPEG
    smear swelling one corner) leaves a residual of only a few percent of the side, and the
    height is off by about as much as the corner."""
    return _rms_share(est.rms_px, est.extras) if est.method == "outline" else 0.0


def _rms_share(rms_px: float, info: dict) -> float:
    """:func:`outline_rms_share` of a reprojection RMS, with an outline's ``side_px`` and
    ``px_sigma_scale`` from ``info`` (its detection's, or its estimate's extras)."""
    side = info.get("side_px")
    if not side or not np.isfinite(rms_px):
        return 0.0
    scale = np.asarray(info.get("px_sigma_scale", [1.0]), np.float64)
    return float(rms_px / side / math.sqrt(float(np.mean(scale**2))))


FORESEEN_CHI2 = 11.34  # 3 degrees of freedom, 99 %
# a pad posed by its design fitted from the predicted pose: each outer corner as noisy as this times the
# blur the fit found (px).  Over 41 datasets the 66 frames it gained (20-45 px pads, and outlines found
# again after them) were 1.8 % of the height off in the median, NEES median 0.9, none beyond 3 sigma
DESIGN_SIGMA_PER_BLUR = 1.0


def foreseen(pose, predicted) -> bool:
    """Whether ``pose`` (a :class:`hvloc.pose.PoseResult`) lies where ``predicted`` (the velocity
    filter's ``(p, P, v)`` for its frame: :meth:`hvloc.shutter.VelocityFilter.position`) foresaw it:
    the positions within the chi-square bound of both doubts as stated (:data:`FORESEEN_CHI2`; a
    pose whose corners are off beyond their noise is then held the stricter); ``False`` with no
    prediction or covariance."""
    if predicted is None or pose.cov is None:
        return False
    d = pose.cam2pad[:3, 3] - predicted[0]
    try:
        return float(d @ np.linalg.solve(predicted[1] + pose.cov[:3, :3], d)) <= FORESEEN_CHI2
    except np.linalg.LinAlgError:
        return False


def corner_sigma_px(info: dict) -> np.ndarray:
    """The pixel noise of a detection's correspondences as its ``info`` states it: the found corner's
    floor (:data:`PIXEL_SIGMA`), with the noise of a corner placed under motion smear
    (``px_sigma_blur``), and for a corner out of view or hidden, where the lines of its sides'
    stretches in view meet, as many times more as the stretches' error grows out there
    (``px_sigma_scale``, per correspondence): whatever moved the lines, the smear too.  (unseen51's
    cut pad under 9.7 px of smear: a hidden corner 7 px out where its sides' corners in view were
    3.8 px, 2.7 times less sure by its stretches, was stated 1.3 px with the smear's noise unscaled.)
    A white field placed by a loose fit carries its lines' scatter (``px_sigma_field``).  Corners of
    a design fit that held the found corners' tilt carry how far those were from the design
    (``px_sigma_held``: :meth:`HierarchicalLocalizer._design_fitted`)."""
    base = math.hypot(PIXEL_SIGMA, info.get("px_sigma_blur") or 0.0, info.get("px_sigma_field") or 0.0,
                      info.get("px_sigma_held") or 0.0)
    return base * np.asarray(info.get("px_sigma_scale", 1.0))


MAX_SIDEWAYS_SIGMA = 0.1 / 3.0  # share of the height: a pose gravity does not hold stating more is refused


def loose_tilt_refusal(est: "Estimate", cfg: LocalizerConfig, imu: bool) -> str:
    """Why a pose whose tilt the IMU's gravity does not fix is refused, or ``""``: on a tilting
    deck (``pad_tilt_deg``), where the IMU's up is no longer the pad's normal, and without the IMU's
    attitude (``imu`` false), where only the image and the level-flight prior fix it.  A tilt error
    of d moves the camera's position in the pad's frame sideways by about the height times d.  A
    pose whose own covariance says its sideways position is known no better than
    :data:`MAX_SIDEWAYS_SIGMA` of the height (a far pad's four corners, which hardly fix its tilt)
    may be off by a tenth of the height within its 3 sigma: refused, not stated.  (At 2 sigma, 5 %,
    the decks suite and a scene made after it, unseen73, kept 143 of 145 outline poses and 3 of
    them were off by 9-11 % of the height, 2.3-3 of their sigmas: a far outline's covariance on a
    tilted pad understates.  Without the IMU, the decks suite and unseen73-75 had 73 false accepts
    in 1753 frames, far outline poses 10-24 % of the height off, stating 7-18 %: none with this
    refusal.  The conditions suite without the IMU: 298 -> 16 false accepts in 7,198 frames,
    availability 88.3 -> 67.4 %.)"""
    if (imu and cfg.pad_tilt_deg <= 0) or est.cov is None or est.cam2pad is None:
        return ""
    h = max(abs(float(est.cam2pad[2, 3])), 1e-6)
    # (not the pad's stated relief, which every pose from the pad carries whatever fixes its tilt: at
    # touchdown on a deck a 19 mm relief alone, 9.7 mm per axis, was 3.5 % of a 0.28 m height.  The
    # tilt its wrinkles may give the patch seen counts: it is a tilt the image does not fix.  Left
    # out, fuzz seed 365's two markers on a 19 mm relief at 2.2 m, their patch's tilt 59 mm
    # sideways, passed at 3.1 % and were 8.9 % of the height and 5 degrees off, a false accept;
    # counted, 64 random deck scenes with a relief lost 2 of 8,724 poses and that one)
    relief = (cfg.pad_relief_m / 2.0) ** 2
    side = math.sqrt(max(float(est.cov[0, 0]) - relief, float(est.cov[1, 1]) - relief, 0.0))
    if side > MAX_SIDEWAYS_SIGMA * h:
        why = (f"on a deck that may tilt {cfg.pad_tilt_deg:g} deg" if imu else "without the IMU's gravity")
        return (f"{why} the image fixes the pad's tilt too loosely: "
                f"sideways sigma {100 * side / h:.1f} % of the height (> {100 * MAX_SIDEWAYS_SIGMA:.1f} %)")
    return ""


SURE_TILT_DEG = 1.0  # a pose whose image alone fixes the pad's tilt to this (one sigma) sees how the pad lies
# A deck's tilt counts as tracked (its design fitted as on an untracked deck's otherwise) where its track's prediction
# is this sure: a tilt as uncertain moves a far pose sideways by MAX_SIDEWAYS_SIGMA of the height, what
# loose_tilt_refusal refuses.  A track made from one pose does not know the swell's rate, and its prediction
# spreads to 3.7-4.1 degrees within a quarter of a second: fzu165's grey outline at 73 px, on such a track and
# so no longer fitted by its design (up to hvloc.texfit.MAX_SIDE_PX under a rolling shutter), was posed from its
# four corners 2.6 degrees off in tilt, 5.6 % of the height
DECK_TRACKED_SIGMA_DEG = math.degrees(math.atan(MAX_SIDEWAYS_SIGMA))
DECK_SEEN_POSES = 3  # so many such poses within DECK_SEEN_WINDOW_S contradicting the IMU's up: the pad tilts (a deck)
DECK_SEEN_WINDOW_S = 5.0
DECK_AMPLITUDE_SHARE = 1.5  # a deck seen tilting d is taken to tilt up to this times d
# ... seen (and a deck's amplitude widened) by poses whose points spread (RMS about their centre, per axis) over
# at least this share of the pad's side: a wrinkle tilts a small patch degrees from the pad's plane, a deck the
# whole pad.  A variant of
# fuzz seed 143's scene (a 17 mm relief, not stated) took its one 8.5 cm nested marker, spread 0.03 m of a
# 0.85 m pad, tilted 3.5-4 degrees, for a deck: 23 poses followed that patch, 10-11 % of the height off, "ok".
# The three finder markers spread 0.3 of the side; two adjacent ones 0.2-0.25
DECK_SEEN_MIN_SPREAD = 0.15


def image_tilt_from_many(est: "Estimate") -> bool:
    """Whether ``est``'s image-only pad normal comes from many points: markers or texture, 12 or
    more, not a smeared drawing's affine warp (:mod:`hvloc.synthesis`).  Not the outline's four
    corners, whose tilt moves 0.5 degrees for a 0.03 px bias of its corners far away, and 10 degrees
    or more "confidently" for a corner a few pixels off (a shadow across it)."""
    return est.method in ("markers", "texture") and est.n_corr >= 12 and est.extras.get("by") != "synthesis"


def sure_tilt(est: "Estimate") -> bool:
    """Whether ``est``'s image alone fixed the pad's tilt from many points (:func:`image_tilt_from_many`)
    to :data:`SURE_TILT_DEG`."""
    return image_tilt_from_many(est) and float(est.extras.get("tilt_sigma_deg", math.inf)) < SURE_TILT_DEG


def image_tilt_contradicts(est: "Estimate", cfg: LocalizerConfig, allowed_deg: float) -> bool:
    """Whether the pad's tilt as ``est``'s image alone fixes it (before the gravity prior pulls it
    toward the IMU's up) contradicts the IMU by far more than both can err: five times their sigmas
    together (the image's fit, the IMU's up as the config knows it), from 12 points or more, and
    further than the tilt gate's ``allowed_deg``; twice that unless the image fixed the tilt to
    :data:`SURE_TILT_DEG`: a far markers fit can have a second minimum degrees away, and its sigma
    understates.  (Not five sigmas alone: told an AHRS of 0.05 degrees, the image's own bias of a
    few tenths near the ground would be five of them.)"""
    alone, sigma = est.extras.get("tilt_err_deg", math.nan), est.extras.get("tilt_sigma_deg", math.nan)
    if est.n_corr < 12 or not alone > 5.0 * math.hypot(sigma, cfg.up_sigma_deg()):
        return False
    return alone > (1.0 if sure_tilt(est) else 2.0) * allowed_deg


PAD_YAW_DEG, PAD_YAW_PERIOD_S = 20.0, 8.0  # the deck's yaw swell the pad's heading filter follows (PadHeading)
PAD_HEADING_SIGMA_DEG = 1.0  # a pose's heading noise, as that filter weighs it where its covariance does not say
PAD_YAW_HORIZON_S = 1.0  # ... and how long on it carries the pad's turn
PAD_YAW_RATE_DEG_S = PAD_YAW_DEG * 2.0 * math.pi / PAD_YAW_PERIOD_S  # that swell's fastest turn (15.7 degrees a second)
# how far the pad may have turned unseen over a gap without poses, beyond what its heading filter
# carries (FalsePoseGates.unseen_turn_deg): at most this, well short of a quarter turn, which is what
# a misnamed outline is off by and the jump must still refuse
PAD_UNSEEN_TURN_MAX_DEG = 20.0
PAD_YAW_MIN_RATE_DEG_S = 1.0  # a slower turn is no turn (PadHeading.turning)
PAD_HEADING_MIN_SIGMA_DEG = 0.05  # a pose's heading is taken no surer than this
# the offsets' own heading noise (PadHeading.unexplained_var) is read from the last this many accepted
# poses, from every three of them within this span (over a longer one a turn's curvature would count)
PAD_HEADING_SCATTER_WINDOW, PAD_HEADING_SCATTER_SPAN_S = 21, 0.6
# ... and until they show it, taken to be a hobby AHRS's: its heading jitters a few tenths of a degree
# from row to row (the generator's default 0.3, its random scenes' up to 0.6); this counts as so many
# of the triples the scatter is read from (PadHeading.unexplained_var)
PAD_HEADING_JITTER_PRIOR_DEG, PAD_HEADING_JITTER_PRIOR_N = 0.5, 3
CHI2_1_MEDIAN = 0.4549364  # the median of a chi-square of one degree of freedom


def heading_var(est: "Estimate") -> float | None:
    """How well ``est`` fixes the pad's heading (rad^2): its covariance's rotation about the pad's
    normal (the covariance turns about the camera's axes); ``None`` without one."""
    if est.cov is None or est.cam2pad is None:
        return None
    n_C = est.cam2pad[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    return float(n_C @ est.cov[3:, 3:] @ n_C)


def pad_normal_W(normal_C, R_W_B, T_B_C: np.ndarray) -> np.ndarray | None:
    """The pad's normal in the world (unit) from ``normal_C``, its normal in the camera, turned by the
    attitude ``R_W_B`` through the mount ``T_B_C``; ``None`` without either."""
    if R_W_B is None or normal_C is None:
        return None
    n = R_W_B @ T_B_C[:3, :3] @ np.asarray(normal_C, np.float64)
    return n / np.linalg.norm(n)


def tilt_sigma_deg(est: "Estimate") -> float | None:
    """How well ``est`` fixes the pad's tilt (degrees, one sigma along its worst axis): its
    covariance's rotation about the two camera axes across the pad's normal; ``None`` without one."""
    if est.cov is None or est.cam2pad is None:
        return None
    n_C = est.cam2pad[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    across = np.eye(3) - np.outer(n_C, n_C)
    worst = float(np.linalg.eigvalsh(across @ est.cov[3:, 3:] @ across).max())
    return math.degrees(math.sqrt(worst)) if math.isfinite(worst) and worst >= 0.0 else None


# On a tilting deck the pad's tilt in the world moves, but no faster than a swell of its whole amplitude at
# DeckTilt.PERIOD_MIN_S swings it: a pose whose pad normal (in the world, through the AHRS) stepped from the last
# accepted pose's by more than that swing over the time between them, and TILT_STEP_SIGMAS of the two poses'
# tilt doubts (and the AHRS's) together, is refused.  On a level pad the vision-IMU rotation jump
# (imu_jump_deg) holds the whole rotation; on a deck it held only the heading.  Branch exp/glare-rings's
# fz445 frame 73: a texture pose from a smeared drawing's affine warp (24 points over 0.21 m of the pad at 2 m)
# tilted 11.3 degrees off stating 1.3, 0.12 s after an outline pose 1.1 off, on a deck told 7 degrees: its
# tilt 10.7 degrees from the IMU's up passed the tilt gate (3 + 7), 21.7 % of the height off.  Offline over
# the 2,471 deck poses of 36 random scenes (the true attitude, without the AHRS's term) such a step refused 2,
# both beyond their 3 sigma, no other; run live on them and on the conditions suite, it changed no frame
TILT_STEP_SIGMAS = 3.0


def tilt_step_refusal(est: "Estimate", n_W: np.ndarray, last: tuple | None, cfg: LocalizerConfig) -> str:
    """Why ``est`` (pad normal ``n_W`` in the world) must be refused for its tilt's step from the last
    accepted pose's ``last`` (``(t, n_W, tilt sigma deg)``) on a deck that may tilt ``cfg.pad_tilt_deg``,
    or ``""``: not on a level pad, without either pose's covariance."""
    sigma = tilt_sigma_deg(est)
    if cfg.pad_tilt_deg <= 0 or last is None or sigma is None or last[2] is None:
        return ""
    t0, n0, s0 = last
    a = cfg.pad_tilt_deg
    swing = min(2.0 * a, DeckTilt.fastest_rate(a) * max(est.t - t0, 0.0))
    step = math.degrees(math.acos(float(np.clip(n_W @ n0, -1.0, 1.0))))
    allowed = swing + TILT_STEP_SIGMAS * math.sqrt(sigma ** 2 + s0 ** 2 + cfg.ahrs_tilt_sigma_deg ** 2)
    if step <= allowed:
        return ""
    return (f"the pad's tilt stepped {step:.1f} deg in {est.t - t0:.2f} s from the last pose's (> {allowed:.1f}: "
            f"a deck tilting {a:g} deg swings {swing:.1f} in that time; the poses' tilts +-{sigma:.1f}, +-{s0:.1f})")


# A cold start's naming by the pad's whole design (hvloc.phases.name_by_design).  One frame's naming
# was taken wherever it correlated 0.6 and led the next by 0.04; on unseen47 a quad swollen to 25 px
# around an 18 px pad was named a quarter turn wrong so (0.64, leading by 0.067), and only the
# square's gate kept its pose out.  Over the 41 datasets of scratch/s58 the namings whose best was
# wrong correlated 0.64-0.85 leading by 0.006-0.031, or 0.64 leading by 0.067; the right namings taken
# alone 0.76-0.97 leading by 0.06-0.14.  A naming short of sure is taken where the namings of other
# frames within DESIGN_VOTE_WINDOW_S give the pad the same heading in the world (the AHRS carries the
# camera's turn between frames), the leads of those that agree less those of like-sized outlines
# that disagree adding up to the single frame's bar (DesignVotes)
DESIGN_SURE_NCC = 0.75  # a naming taken alone correlates at least this ...
DESIGN_SURE_LEAD = 0.06  # ... and leads the next naming by this
DESIGN_VOTE_LEAD = 0.01  # a naming leading by less is no vote
DESIGN_VOTE_WINDOW_S = 2.0  # votes this old at most are weighed together
DESIGN_VOTE_AGREE_DEG = 20.0  # votes whose pad headings lie this close agree (a quarter turn apart: they disagree)
DESIGN_VOTE_SIDE_SHARE = 0.2  # votes weighed together are of outlines this alike in size (another quad is another object)
# named by the design fitted from each naming (HierarchicalLocalizer._named_by_fit): the next one's RMS this many times the best's
FIT_NAMING_RATIO = 1.3
# ... or by such namings over frames (DesignVotes, each vote's lead the log of its ratio, the bar the single frame's):
# a naming leading by a smaller ratio than this is no vote.  Fitted from the labelled pose's gravity on the found
# outlines of 16-33 px of the dusk deck and unseen105 (scratch/s66/nf_small.txt): the 3 of 50 whose best fit was
# the wrong naming led by 1.008-1.025; the right ones by 1.011-2.24, all but one by 1.044 or more
FIT_VOTE_RATIO = 1.04


class DesignVotes:
    """A cold start's namings by the pad's design, frame by frame, each as the heading of the pad in
    the world it gives (:data:`DESIGN_SURE_NCC` ... :data:`DESIGN_VOTE_SIDE_SHARE`).  ``name``: what
    names the pad (``"pad design"``: the correlation's namings, leads in correlation; the fits' leads
    are the log of their RMS ratio, :data:`FIT_NAMING_RATIO`); ``sure_best``, ``sure_lead``: a naming
    taken alone; ``vote_lead``: a vote at least; ``enough``: the agreeing votes' leads, less the others',
    that name the pad."""

    def __init__(self, name: str = "pad design", sure_best: float = DESIGN_SURE_NCC,
                 sure_lead: float = DESIGN_SURE_LEAD, vote_lead: float = DESIGN_VOTE_LEAD,
                 enough: float = ph.DESIGN_MIN_LEAD):
        self.name, self.sure_best, self.sure_lead, self.vote_lead, self.enough = name, sure_best, sure_lead, vote_lead, enough
        self.votes: list = []  # (t, heading rad, side px, lead)

    def cast(self, t: float, heading: float | None, side_px: float, best: float, lead: float) -> str | None:
        """This frame's naming, its correlation ``best`` leading the next naming's by ``lead``, giving
        the pad's world heading ``heading`` (``None`` without an attitude): the ``name`` (``"pad
        design"``) where it is taken alone, ``"pad design over frames"`` where an earlier vote of a
        like-sized outline agrees with it and the leads of those that agree, this one's included, less
        those that disagree add up to ``enough``, else ``None``; it is kept as a vote either way."""
        if not (best >= ph.DESIGN_MIN_NCC and lead >= self.vote_lead):
            return None
        sure = best >= self.sure_best and lead >= self.sure_lead
        if not (math.isfinite(t) and math.isfinite(side_px) and side_px > 0 and heading is not None
                and math.isfinite(heading)):  # no vote to weigh (no attitude, or no time to weigh it at)
            return self.name if sure else None
        if sure:
            taken = self.name
        else:
            self.votes = [v for v in self.votes if 0.0 <= t - v[0] <= DESIGN_VOTE_WINDOW_S]
            like = [v for v in self.votes if abs(v[2] / side_px - 1.0) <= DESIGN_VOTE_SIDE_SHARE]
            turn = [abs(math.atan2(math.sin(v[1] - heading), math.cos(v[1] - heading))) for v in like]
            agree = [v[3] for v, d in zip(like, turn) if d <= math.radians(DESIGN_VOTE_AGREE_DEG)]
            against = [v[3] for v, d in zip(like, turn) if d > math.radians(DESIGN_VOTE_AGREE_DEG)]
            taken = (f"{self.name} over frames" if agree and lead + sum(agree) - sum(against) >= self.enough
                     else None)
        self.votes.append((t, heading, side_px, lead))
        return taken


class FalsePoseGates:
    """hvloc's false-pose detection, for any localizer's poses: reprojection RMS, physically
    possible motion since the last accepted pose, the pad's tilt against the IMU's gravity, and
    the vision-IMU rotation offset that must not jump.  Stateful (the running offset)."""

    def __init__(self, config: LocalizerConfig, T_B_C: np.ndarray):
        self.config, self.T_B_C = config, np.asarray(T_B_C, np.float64)
        self.reset()

    def reset(self) -> None:
        self.R_W_P: np.ndarray | None = None  # running vision-IMU rotation offset (the pad's orientation in the world) ...
        self.heading = PadHeading()  # ... whose heading turns as the accepted poses show
        self.imu_rejects = 0
        # how far the pad may lie from the up the gates are given (a tilting deck: its tracked tilt's
        # tolerance, set per frame by the localizer; else the deck's whole amplitude)
        self.tilt_allowance_deg = self.config.pad_tilt_deg
        self.last_tilt = None  # (t, the pad's normal in the world, its tilt sigma deg) of the last pose passed

    def check(self, est: "Estimate", R_W_B, last: "Estimate | None", R_W_B_raw=None) -> str:
        """Why ``est`` (an ``ok`` pose) must be rejected, or ``""``; ``last``: the last accepted one.
        ``R_W_B_raw``: the AHRS's own attitude where ``R_W_B`` has a deck's predicted tilt taken out
        (the tilt's step from ``last`` is measured in the world: :func:`tilt_step_refusal`)."""
        n_W = None if est.cam2pad is None else \
            pad_normal_W(est.cam2pad[2, :3], R_W_B if R_W_B_raw is None else R_W_B_raw, self.T_B_C)
        why = self._check(est, R_W_B, last, n_W)
        if not why and est.cam2pad is not None:
            self.last_tilt = None if n_W is None else (est.t, n_W, tilt_sigma_deg(est))
        return why

    def _check(self, est: "Estimate", R_W_B, last: "Estimate | None", n_W) -> str:
        """:meth:`check`'s verdict, the gates' state moved on only where it passes; ``n_W``: the pad's
        normal in the world through the AHRS's own attitude."""
        cfg = self.config
        if not cfg.false_pose_detection:
            return ""
        if not np.isfinite(est.rms_px):  # a fit that did not converge (a quad folded to a line), not a large RMS
            return f"reprojection RMS not finite ({est.rms_px}): the fit failed"
        if est.rms_px > cfg.max_reprojection_px:
            return f"reprojection RMS {est.rms_px:.2f} px > {cfg.max_reprojection_px}"
        share = outline_rms_share(est)
        if share > cfg.max_outline_rms_share:
            return (f"the outline's corners are no square's: reprojection RMS {100 * share:.1f} % of its side "
                    f"(> {100 * cfg.max_outline_rms_share:g} %)")
        why = motion_gate(est.cam2pad, est.t, last.cam2pad if last else None, last.t if last else 0.0, cfg)
        if why:
            return why
        if R_W_B is None:
            return loose_tilt_refusal(est, cfg, False)
        up_C = up_in_camera(R_W_B, self.T_B_C)
        tilt = math.degrees(math.acos(float(np.clip((est.cam2pad[:3, :3].T @ np.array([0.0, 0.0, 1.0])) @ up_C,
                                                    -1.0, 1.0))))
        allowed = cfg.max_tilt_error_deg + self.tilt_allowance_deg  # (a tilting deck's pad is not level)
        if tilt > allowed:
            return f"tilt disagrees with the IMU's gravity by {tilt:.1f} deg (> {allowed:g})"
        why = loose_tilt_refusal(est, cfg, True)
        if why:
            return why
        # the gravity prior pulls a refined pose toward the IMU: where many points fix the tilt (the
        # markers), also ask what the image alone said (image_tilt_contradicts)
        if image_tilt_contradicts(est, cfg, allowed):
            return (f"tilt from the image alone disagrees with the IMU's gravity by {est.extras['tilt_err_deg']:.1f} "
                    f"deg (+-{est.extras['tilt_sigma_deg']:.1f} deg)")
        if last is not None and self.last_tilt is not None and self.last_tilt[0] == last.t:
            why = tilt_step_refusal(est, n_W, self.last_tilt, cfg)
            if why:
                return why
        R_W_P = R_W_B @ self.T_B_C[:3, :3] @ invert(est.cam2pad)[:3, :3]
        if self.R_W_P is None:
            self.R_W_P = R_W_P
        else:
            ref = self.pad_orientation(est.t)
            # the turn the pad may have made unseen since the last pose is granted (toward this pose's)
            unseen = math.radians(self.unseen_turn_deg(est.t))
            if unseen > 0:
                ref = rotation_z(float(np.clip(heading_turn(ref, R_W_P), -unseen, unseen))) @ ref
            jump = math.degrees(rotation_angle(ref, R_W_P) if cfg.pad_tilt_deg <= 0 else abs(heading_turn(ref, R_W_P)))
            if jump > cfg.imu_jump_deg:
                self.imu_rejects += 1
                if self.imu_rejects >= 8:  # the reference itself was wrong: start again
                    self.R_W_P, self.imu_rejects = R_W_P, 0
                    self.heading.reset()
                    self.heading.update(est.t, R_W_P, heading_var(est))
                beyond = f" beyond the {math.degrees(unseen):.0f} deg it may have turned unseen" if unseen > 0 else ""
                return f"vision-IMU rotation jumped {jump:.1f} deg (> {cfg.imu_jump_deg}){beyond}"
            # slow drift (the AHRS's): move the reference a little toward the new offset; its heading
            # is the one the pad's turn has reached (PadHeading).  On a tilting deck the reference is
            # the last accepted pose's (a naming a quarter turn off still jumps)
            d = so3_log(ref.T @ R_W_P)
            self.R_W_P = ref @ so3_exp((1.0 if cfg.pad_tilt_deg > 0 else cfg.imu_drift_rate) * d)
        self.heading.update(est.t, R_W_P, heading_var(est))
        self.imu_rejects = 0
        return ""

    def unseen_turn_deg(self, t: float) -> float:
        """How far (degrees) the pad may have turned at ``t`` beyond the heading its filter predicts:
        nothing within :data:`PAD_YAW_HORIZON_S` of the last accepted pose (the filter carries the
        turn that far), then the swell's fastest turn (:data:`PAD_YAW_RATE_DEG_S`) over the rest of
        the gap, at most :data:`PAD_UNSEEN_TURN_MAX_DEG`.  A deck yawing 5 degrees turned 6-8
        degrees in the 2-3 s before the pad was seen again (fz340, fzu17), and its right poses were
        refused as jumps until the reference started again eight frames later."""
        if self.heading.x is None or not math.isfinite(t):
            return 0.0
        gap = max(t - self.heading.t - PAD_YAW_HORIZON_S, 0.0)
        return min(PAD_YAW_RATE_DEG_S * gap, PAD_UNSEEN_TURN_MAX_DEG)

    def pad_orientation(self, t: float) -> np.ndarray | None:
        """The pad's orientation in the world (the vision-IMU offset) expected at ``t``: the running
        reference's tilt, and the heading its turn is predicted to have reached (:class:`PadHeading`)."""
        if self.R_W_P is None:
            return None
        psi = self.heading.predicted(t) if math.isfinite(t) else None
        if psi is None:
            return self.R_W_P
        return rotation_z(psi - math.atan2(self.R_W_P[1, 0], self.R_W_P[0, 0])) @ self.R_W_P


class PadHeading:
    """The pad's heading in the world (the vision-IMU offset's, so the AHRS's heading drift with it)
    and its turn rate: a Kalman filter on the accepted poses' headings with the white turn
    acceleration of a deck yawing :data:`PAD_YAW_DEG` in :data:`PAD_YAW_PERIOD_S`.  A ship turning or
    its deck yawing in a swell turns the pad under the camera; the reference of a level pad, drawn
    a twentieth of the way toward each pose, lagged a deck yawing 20 degrees in 9 s past the jump's
    bar (unseen78: 91 of 383 frames refused, all right), and a rate fitted to the last two seconds'
    poses lagged it too (the rate grows 10 degrees a second each second).  Of a still pad it follows
    the poses' own heading noise, a few tenths of a degree: a quarter-turn misnaming still jumps.
    Each offset counts with its pose's heading variance and the scatter the recent offsets show
    beyond what their poses state (:meth:`unexplained_var`: the AHRS's own heading noise)."""

    def __init__(self):
        w = 2.0 * math.pi / PAD_YAW_PERIOD_S
        self.q = (math.radians(PAD_YAW_DEG) * w * w) ** 2  # white turn acceleration (rad^2 / s^3)
        self.r = math.radians(PAD_HEADING_SIGMA_DEG) ** 2
        self.reset()

    def reset(self) -> None:
        self.x: np.ndarray | None = None  # heading (unwrapped), rate
        self.P = np.zeros((2, 2))
        self.t = 0.0
        self.recent: list = []  # the last accepted offsets: (t, heading unwrapped, its stated variance)
        self.triples_seen = 0  # how many offsets since the reset came with two before them (the prior's fade)

    def unexplained_var(self) -> float:
        """The heading noise (rad^2) the recent offsets show beyond what their poses state: the
        AHRS's own (a magnetometer's heading jitters from row to row; the generator's default AHRS
        by 0.3 degrees) and any a pose understates.  Each offset is compared with the line through
        its two neighbours, which a steady turn lies on (a turn's curvature over
        :data:`PAD_HEADING_SCATTER_SPAN_S` is a few hundredths of a degree), robustly (the median).
        Weighed at the poses' 0.05 degrees alone, a still pad's offsets jittering 0.3 degrees read
        as a turn of 10 degrees a second: carried through a second without a pose, gusty_blur's
        reference was 10.5 degrees off and refused eight right texture poses at 0.17-0.25 m.
        Read from a flight's first few offsets the median is as likely nil as not: until they are
        many, it is drawn toward a hobby AHRS's jitter (:data:`PAD_HEADING_JITTER_PRIOR_DEG`, worth
        :data:`PAD_HEADING_JITTER_PRIOR_N` triples against those seen since the filter started: after
        a few seconds of poses it is the offsets' own).  Without that, fz549's first eight offsets
        (its AHRS's heading jittering 0.46 degrees) read as a turn of 11 degrees a second, and seven
        right poses after them were refused as jumps."""
        h = self.recent
        e2, stated = [], []
        for (t0, p0, r0), (t1, p1, r1), (t2, p2, r2) in zip(h, h[1:], h[2:]):
            span = t2 - t0
            if not (t0 < t1 < t2 and span <= PAD_HEADING_SCATTER_SPAN_S):
                continue
            a, b = (t2 - t1) / span, (t1 - t0) / span
            g = 1.0 + a * a + b * b  # the residual's variance in units of one offset's
            e2.append((p1 - a * p0 - b * p2) ** 2 / g)
            stated.append((r1 + a * a * r0 + b * b * r2) / g)
        read = max(float(np.median(e2)) / CHI2_1_MEDIAN - float(np.median(stated)), 0.0) if e2 else 0.0
        n, n0 = self.triples_seen, PAD_HEADING_JITTER_PRIOR_N  # (the window's triples are among those seen)
        return (n * read + n0 * math.radians(PAD_HEADING_JITTER_PRIOR_DEG) ** 2) / (n + n0)

    def turning(self) -> bool:
        """Whether the poses show the pad turning: a rate past three of its sigmas and
        :data:`PAD_YAW_MIN_RATE_DEG_S`; only then is the heading carried on at it (a rate drawn from
        far outlines' noisy headings and carried on put the reference 8-16 degrees off on
        soft_gusty_deck at 15 m), and the IMU's accelerations turned by this heading, not the
        gates' slow reference (a still pad's heading followed at its poses' noise drifted a flow
        chain at 0.15 m 13 -> 19 mm on tiny_aruco_nested)."""
        return bool(self.x is not None and abs(self.x[1]) > max(3.0 * math.sqrt(self.P[1, 1]),
                                                                 math.radians(PAD_YAW_MIN_RATE_DEG_S)))

    def predicted(self, t: float) -> float | None:
        """The heading (rad) at ``t``, or ``None`` before the first pose.  The turn is carried at most
        :data:`PAD_YAW_HORIZON_S` on: after a gap, a rate a few degrees a second off must not name the
        outline a quarter turn wrong (:meth:`HierarchicalLocalizer._heading_hint`)."""
        if self.x is None:
            return None
        rate = self.x[1] if self.turning() else 0.0
        return float(self.x[0] + rate * min(max(t - self.t, 0.0), PAD_YAW_HORIZON_S))

    def update(self, t: float, R_W_P: np.ndarray, var: float | None = None) -> None:
        """One accepted pose's offset at ``t``, its heading known to ``var`` (rad^2; by default
        :data:`PAD_HEADING_SIGMA_DEG` squared)."""
        psi = math.atan2(R_W_P[1, 0], R_W_P[0, 0])
        r = self.r if var is None or not math.isfinite(var) else max(float(var), math.radians(PAD_HEADING_MIN_SIGMA_DEG) ** 2)
        if math.isfinite(t):
            if self.recent and t <= self.recent[-1][0]:  # an odd timestamp: not compared with the others
                self.recent.clear()
            last = self.recent[-1][1] if self.recent else psi
            self.recent = self.recent[-(PAD_HEADING_SCATTER_WINDOW - 1):] + [(t, last + math.remainder(psi - last, 2.0 * math.pi), r)]
            self.triples_seen += len(self.recent) >= 3
        r += self.unexplained_var()
        if self.x is None or not math.isfinite(t):
            self.x, self.t = np.array([psi, 0.0]), t if math.isfinite(t) else self.t
            self.P = np.diag([r, math.radians(PAD_YAW_RATE_DEG_S) ** 2])
            return
        x, P = constant_rate_prediction(self.x, self.P, self.q, max(t - self.t, 0.0))
        nu = math.remainder(psi - x[0], 2.0 * math.pi)
        S = P[0, 0] + r
        K = P[:, 0] / S
        self.x, self.P, self.t = x + K * nu, P - np.outer(K, K) * S, max(self.t, t)


class HierarchicalLocalizer:
    """``HierarchicalLocalizer(pad, camera, config).process(image, t, imu=None) -> Estimate``.

    ``imu``: the IMU's rows since the last frame, ``(N, 11)`` in imu.csv's columns and oldest first,
    the last at or before ``t`` (its attitude is the frame's); or one such row, an ``(x, y, z, w)``
    quaternion or a 3x3 ``R_W_B``.  Of a block, the gyro's rate is the mean over the rows the frame
    was read in (:func:`imu_rate`)."""

    IMU_BLOCK = True

    def __init__(self, pad, camera: Camera, config: LocalizerConfig | None = None, T_B_C: np.ndarray | None = None,
                 work: ImageWork | None = None, line_s: float = 0.0, ref_row: float | None = None,
                 exposure_s: float = 0.0, response: tuple | None = None):
        """``line_s``, ``ref_row``: the camera's rolling shutter (:mod:`hvloc.shutter`): the time
        between its rows, and the row whose time a frame's stamp is (by default the middle one).
        ``exposure_s``: how long a frame is exposed (0: not known), which says how far motion
        smears it (:mod:`hvloc.synthesis`).  ``response``: the camera's photometric calibration
        where known, ``(gamma, sharpen, sharpen_sigma_px)`` (``camera.json``'s ``response``): a far
        pad's design is drawn as the camera writes it (:func:`hvloc.texfit.fit_pose_to_design`)."""
        self.geometry = pad.geometry if hasattr(pad, "geometry") else pad
        self.pad = pad if getattr(pad, "texture_rgb", None) is not None else None  # a bare geometry has no texture
        self._texture = None  # its ORB features (hvloc.texture), made when first needed
        self._design_cache = None  # its printed design in grey (phases.PadDesign), made when first needed
        if self.geometry.border is None or self.geometry.cue is None:
            raise ValueError(f"the hierarchical localizer needs hvloc's pad (its coloured border and yaw cue); "
                             f"this pad is {self.geometry.variant!r}")
        self.camera = camera
        self.config = config or LocalizerConfig()
        self.T_B_C = DEFAULT_T_B_C if T_B_C is None else np.asarray(T_B_C, np.float64)
        if not math.isfinite(line_s) or abs(line_s) * camera.height > 1.0:
            raise ValueError(f"line_s: {line_s!r} s between rows is no camera's rolling shutter")
        if ref_row is not None and not math.isfinite(ref_row):
            raise ValueError(f"ref_row: {ref_row!r} is no row")
        self.shutter = RollingShutter(float(line_s), (camera.height - 1) / 2.0 if ref_row is None else float(ref_row))
        if not (math.isfinite(exposure_s) and 0.0 <= exposure_s <= 1.0):
            raise ValueError(f"exposure_s: {exposure_s!r} s is no frame's exposure")
        self.exposure_s = float(exposure_s)
        if response is not None:
            from .texfit import parse_response

            response = parse_response(response)
        self.response = response
        # the IMU's rows a frame's gyro rate is the mean of (imu_rate): those its rows were read in
        self.rate_span_s = abs(self.shutter.line_s) * (camera.height - 1)
        self._synthesis = None  # the pad drawn and smeared (hvloc.synthesis), made when first needed
        # the image work; localizers of one pad and camera that see the same frames may share one
        # (hvloc.work): their estimates are exactly what each would make alone
        self.work = work if work is not None else ImageWork()
        self.outer_P = self.geometry.outer_corners
        modules = [m.module_m for m in self.geometry.markers_in("corner")]
        # the height at which the corner markers' modules, seen straight on, span MARKER_MIN_MODULE_PX
        self.markers_seen_below_m = (min(camera.fx, camera.fy) * min(modules) / MARKER_MIN_MODULE_PX
                                     if modules else 0.0)
        self.reset()

    def reset(self) -> None:
        if getattr(self, "told_config", None) is not None:  # a deck it saw (_pad_tilt_seen) is forgotten with the track
            self.config, self.told_config = self.told_config, None
        self.told_config: LocalizerConfig | None = None  # the config as given, once the pad was seen to tilt
        self.tilted: list = []  # the recent sure poses whose image contradicted a level pad: (t, normal W, sigma, tilt)
        self.deck_note = ""  # this frame's word that the pad was seen to tilt
        self.deck_seen: list = []  # ... and the poses that showed it, taken for a deck from the next frame
        self.phase = "approaching"
        self.last: Estimate | None = None       # last accepted estimate
        self.last_t: float | None = None         # time of the last frame processed (any status)
        self.velocity: np.ndarray | None = None  # camera velocity in P (m/s), from the last two accepted poses
        self.frame_dt: float | None = None       # the usual time between frames (a running estimate)
        self.gap = False                         # this frame follows a gap (dropped or missing frames)
        self.attitude: np.ndarray | None = None  # the AHRS's attitude R_W_B this frame (its own, as read)
        self.frame_t: float | None = None        # ... and this frame's time
        self.far_tilts: list = []                # (t, normal W) of far pads' tilts fitted on an untracked deck (_far_tilt_doubt)
        self.last_attitude: np.ndarray | None = None  # ... at the last accepted pose (_predicted)
        self.turn_B: np.ndarray | None = None    # the gyro's turn of the body since the last accepted pose (gyro_turn)
        self.gyro_t: float | None = None         # the IMU time of the last gyro row taken into it
        self.gates = FalsePoseGates(self.config, self.T_B_C)
        self.heading_t: float | None = None      # when the gates' vision-IMU offset (the pad's heading) was last confirmed
        self.design_votes = DesignVotes()        # a cold start's namings by the pad's design ...
        self.fit_votes = DesignVotes("pad design fitted", sure_best=ph.DESIGN_MIN_NCC,  # ... fitted from each naming
                                     sure_lead=math.log(FIT_NAMING_RATIO), vote_lead=math.log(FIT_VOTE_RATIO),
                                     enough=math.log(FIT_NAMING_RATIO))
        self.unposed = 0                         # frames since the last accepted pose (this one included)
        self.ahrs = AHRSTiltBias(self.config.ahrs_bias_time_s, self.config.ahrs_tilt_sigma_deg)
        cfg = self.config
        self.deck = DeckTilt(cfg.pad_tilt_deg, cfg.ahrs_tilt_sigma_deg) if cfg.pad_tilt_deg > 0 else None
        # the gravity prior this frame: how sure the up given to the poses is (deg), and how far from
        # it the pad may lie (a tilting deck's; 0: level)
        self.up_sigma_deg, self.up_tolerance_deg = cfg.up_sigma_deg(), cfg.pad_tilt_deg
        self.deck_tracked = False  # whether a tilting deck's tilt is known from the image this frame
        self.deck_known = False  # ... or known at all, however loosely (its prior drawn from the track)
        self.texture_tried_kf: int | None = None  # the chained keyframe the texture was last drawn over (_texture_over_flow)
        self.flow = ph.FlowTracker(self.camera, self.config.flow_reanchor_scale, self.config.flow_min_tracks, self.work,
                                   self.outer_P)
        self.flow.unroll = self._unrolled if self.shutter.active else None
        self.flow.gravity_sigma_deg = self.config.up_sigma_deg()
        self.flow.ground = self.config.anchor_once  # (the pad's own corners only: FlowTracker.ground)
        self.twist: Twist | None = None          # the camera's motion at this frame (hvloc.shutter)
        # the shutter's velocity, from the poses and the IMU's rows (and the position they carry on: _synthesized)
        self.vfilter = VelocityFilter(TWIST_WINDOW_S, coast_s=SYNTHESIS_COAST_S)
        self.rate_B: np.ndarray | None = None    # the gyro's body rate at this frame, when the IMU gives one
        self.rate_doubt: np.ndarray | None = None  # ... and its standard deviation per body axis (imu_rate_doubt)
        self.accels: list = []                   # the IMU's rows of the last SYNTHESIS_COAST_S (imu_accel)
        self.policy_h: float | None = None       # the height the switching policy uses this frame (policy_height)

    # ------------------------------------------------------------------ public
    def process(self, image, t: float, imu=None) -> Estimate:
        return guarded_process(self._process, image, t, imu, self.phase)

    # ------------------------------------------------------------------ internals
    def _clock(self, t: float) -> str:
        event, note = clock_event(self.last_t, self.last, t, self.config.prior_timeout_s)
        if event == "reset":
            self.reset()
        elif event == "drop":
            self._forget_motion()
        dt = t - self.last_t if self.last_t is not None else None
        self.gap = bool(dt is not None and self.frame_dt is not None and dt > 1.5 * self.frame_dt)
        if dt is not None and dt > 0:
            self.frame_dt = dt if self.frame_dt is None else 0.9 * self.frame_dt + 0.1 * min(dt, 2 * self.frame_dt)
        self.last_t = t
        return note

    def _predicted(self, t: float):
        """The pose expected at ``t``, from which the flow guesses where its features are: the last
        accepted one turned as the gyro turned since (the pad itself does not turn; where no gyro
        rows came, as the AHRS's attitude did) and placed where the velocity filter predicts it
        (the poses' positions carried by the IMU's accelerations, :class:`hvloc.shutter.VelocityFilter`;
        before it has two poses, and only after a gap, moved at the last two poses' velocity);
        ``None`` where nothing is known of the motion.

        Every frame, not only after a gap: at 10 Hz a gusty drone over a drifting deck moves the
        pad 70-100 px between two 1080p frames near the ground, past what Lucas-Kanade's pyramid
        follows on the border's checker, whose cells repeat every 35-75 px there.  The tracks
        slipped a cell together and agreed on a pose a cell off (unseen61, a camera pitched 25
        degrees: 28 poses 65-88 mm off accepted at 0.7-0.15 m, NEES 87-156).  The gyro's turn, not
        the AHRS's: the generator's AHRS errs by a third of its error afresh each sample, 0.15-1
        degree between two frames (3-30 px), where the gyro's rows integrate to within 0.01-0.02
        degree.  The filter's position, not the last velocity: two poses' difference carries their
        noise (outline poses 17 mm off at 1.4 m put such a guess half a cell off, and the chain
        stayed 12-24 mm off), and a gust turns it within a frame; the filter weighs the poses by
        their covariance and carries the IMU's accelerations between them."""
        if self.last is None:
            return None
        T, guessed = self.last.cam2pad.copy(), False
        pred = self.vfilter.position(t)
        if pred is not None:
            T[:3, 3] = pred[0]
            guessed = True
        elif self.gap and self.velocity is not None:
            T[:3, 3] += self.velocity * (t - self.last.t)
            guessed = True
        turn = self.turn_B
        if turn is None and self.attitude is not None and self.last_attitude is not None:
            turn = self.last_attitude.T @ self.attitude
        if turn is not None:
            R_B_C = self.T_B_C[:3, :3]
            T[:3, :3] = T[:3, :3] @ R_B_C.T @ turn @ R_B_C
            guessed = True
        return T if guessed and T[2, 3] > 0.05 else None

    def _process(self, image, t: float, imu) -> Estimate:
        clock = self._clock(t)
        if not self.config.imu_rows:
            imu = imu_last_row(imu)
        R_W_B, imu_why = imu_check(imu)
        imu_t = self.gyro_t  # the IMU time of the last block's last row
        self.turn_B, self.gyro_t = gyro_turn(imu, self.gyro_t, self.turn_B)
        self.rate_B, self.rate_doubt = imu_turn(imu, self.rate_span_s) if R_W_B is not None else (None, None)
        # the accelerations since the velocity filter's last pose, up to its coast (_update_twist)
        since = -math.inf if self.vfilter.t is None else self.vfilter.t
        self.accels = ([r for r in self.accels if since < r[0] < t and t - r[0] < self.vfilter.coast_s]
                       + (imu_accel(imu, t, self.ahrs.corrected, imu_t) if R_W_B is not None else []))
        self.deck_tracked, self.deck_known, self.deck_note = False, False, ""
        if self.deck_seen:
            self._take_for_deck()
        R_use = self.ahrs.corrected(R_W_B)
        if self.deck is not None and R_W_B is not None and math.isfinite(t):
            # the attitude relative to the deck's tracked tilt: its up is the pad's normal as predicted
            tilt, self.up_sigma_deg, self.up_tolerance_deg, self.deck_known = self.deck.prior(float(t))
            # (tracked, for the design fit, only as far as a pose may stand on it: a track spread past
            # DECK_TRACKED_SIGMA_DEG, a swell's rate not yet learnt, fixes the tilt no better than an untracked
            # deck's whole swing does; a grey outline's four corners are posed on any track, as before: fz444's
            # 203 px pad, past what the design is fitted to, on a 3.7 degree track, 0.9 % of the height off)
            self.deck_tracked = self.deck_known and self.up_sigma_deg <= DECK_TRACKED_SIGMA_DEG
            R_use = so3_exp(-tilt) @ R_use
            self.gates.tilt_allowance_deg = self.up_tolerance_deg
            self.flow.gravity_sigma_deg = self.up_sigma_deg
        est = self._estimate(image, t, R_use, R_W_B)
        # said in the reason too, whatever the frame's status (DESIGN.md for the clock), after a
        # failure's own reasons: estimates.csv does not carry the extras
        for key, note in (("clock", clock), ("imu", imu_why and imu_why + ": vision alone"), ("deck", self.deck_note)):
            if note:
                est.extras[key] = note
                est.reason = f"{est.reason}; {note}" if est.reason else note
        return est

    def _estimate(self, image, t: float, R_W_B, R_W_B_raw=None) -> Estimate:
        """``R_W_B``: the attitude the phases and gates use (the AHRS's, its learnt tilt error taken
        out); ``R_W_B_raw``: the AHRS's own, which that error is learnt against."""
        self.attitude = R_W_B_raw if R_W_B_raw is not None else R_W_B
        self.frame_t = t
        rgb, gray, why = self.work(lambda: ("image",), check_image, image, copy_result=False)
        if gray is None:
            return Estimate(t, self.phase, "lost", None, reason=why)
        if gray.shape != (self.camera.height, self.camera.width):
            return Estimate(t, self.phase, "lost", None,
                            reason=f"image is {gray.shape[1]}x{gray.shape[0]}, camera is {self.camera.width}x{self.camera.height}")
        up_C = up_in_camera(R_W_B, self.T_B_C)
        self._update_twist(t, R_W_B is not None)
        cfg = self.config
        h = policy_height(self.last.height if self.last else None, self.last.t if self.last else 0.0, t, cfg)
        self.policy_h = h
        self._update_phase(h)
        self.unposed += 1
        order = METHOD_ORDER[self.phase]
        if self.flow.kf is not None and self.flow.kf.drawn and "texture" in order:
            # tracks from a smeared keyframe: only where the pad's drawing no longer places the frame
            order = tuple(m for m in order if m != "flow") + ("flow",)
        if cfg.anchor_once and self.flow.kf is not None:  # flow-only ablation: anchored once, then flow alone
            order = ("flow",)
        enabled = {"outline": cfg.use_outline and rgb is not None, "markers": cfg.use_markers, "flow": cfg.use_flow,
                   "texture": cfg.use_texture and cfg.use_flow and self.pad is not None}
        reasons = []
        rejected = None
        # the methods in the phase's order: the first whose pose passes the gates wins; a pose the
        # gates reject does not stop the next method (a pad cut by the image edge must not keep
        # the flow tracker from its turn)
        # last of all, two markers named by the recent pose (:func:`phases._pair_by_prior`), or on a
        # cold start by the pad's design around them (:func:`phases._pair_by_design`): only where
        # nothing else posed the frame (the flow tracker and a cut outline, where they hold, are the
        # better pose near the ground)
        twist = self.twist  # the frame's (a flow pose may solve its own velocity: not kept if it is rejected)
        pairs = "markers" in order and (self.last is not None or self.pad is not None)
        tries = [(m, False) for m in order] + ([("markers", True)] if pairs else [])
        markers_why = ""
        for method, by_prior in tries:
            if not enabled[method]:
                continue
            if by_prior and self.last is None and markers_why and (ph.nests_found(markers_why) or 0) < 2:
                # a cold start whose markers' try (the whole image) found under two nests, or a layout:
                # no pair to name, and their search is not made again
                continue
            if not method_allowed(method, h, cfg, self.markers_seen_below_m):
                continue
            if method == "flow" and not self.flow.ready:
                reasons.append("flow: no keyframe")
                continue
            if method == "texture" and not self._texture_allowed(h):
                continue
            res, why = self._try(method, rgb, gray, up_C, t, R_W_B, by_prior)
            if method == "markers" and not by_prior:
                markers_why = why
            if res is None:
                if by_prior:
                    why = why.replace(ph.NO_LAYOUT, "none named by the recent pose either" if self.last is not None
                                      else "none named by the pad's design either")
                reasons.append(f"{method}: {why}")
                continue
            tried_twist = self.twist
            for method, res in self._candidates(method, res, gray, up_C):
                self.twist = tried_twist
                pose, n, extras = res
                est = Estimate(t, METHOD_PHASE[method] or self.phase, "ok", pose.cam2pad, n, pose.rms_px, pose.cov, method=method,
                               extras=extras)
                verdict = self._gate(est, R_W_B)
                self._pad_tilt_seen(est, R_W_B if R_W_B_raw is None else R_W_B_raw)
                if verdict:
                    est.status, est.reason = "rejected", verdict
                    self.twist = twist
                    reasons.append(f"{method}: rejected, {verdict}")
                    rejected = rejected or est
                    continue
                return self._accepted(method, est, gray, reasons, R_W_B, R_W_B_raw)
        self.flow.skip()
        if rejected is not None:
            rejected.reason = "; ".join(reasons)
            return rejected
        return Estimate(t, self.phase, "lost", None, reason="; ".join(reasons) or "no method enabled")

    def _accepted(self, method: str, est: Estimate, gray, reasons: list, R_W_B, R_W_B_raw) -> Estimate:
        """``est``, a pose of ``method`` the gates passed, taken: the last pose, the velocity filter,
        the AHRS's tilt error and the deck's tilt told, the flow tracker kept ready."""
        t = est.t
        if reasons:
            est.extras["before"] = "; ".join(reasons)
        if self.last is not None and 0 < est.t - self.last.t < 0.5:
            self.velocity = (est.cam2pad[:3, 3] - self.last.cam2pad[:3, 3]) / (est.t - self.last.t)
        else:  # poses that far apart tell no velocity, and one from before them is another moment's
            self.velocity = None
        self.last = est
        self.last_attitude, self.turn_B = self.attitude, np.eye(3)
        # the velocity filter (the rolling shutter's correction reads it, and the flow's guess: _predicted)
        cov = est.extras.get("still_cov")
        if cov is None:  # a pose with no covariance: counted 1 % of its height off
            cov = est.cov if est.cov is not None else (0.01 * max(est.cam2pad[2, 3], 0.1)) ** 2 * np.eye(3)
        self.vfilter.update(t, est.extras.get("still_p", est.cam2pad[:3, 3]), cov,
                            est.extras.get("still_shared", (None, None)), est.extras.get("still_dv"))
        self.unposed = 0
        if R_W_B is not None:
            self.heading_t = t
            # the image's own view of the normal, from many points (field1080's outline tilts were
            # 0.6 degrees off on average: they taught the AHRS a wrong error)
            R_img = R_W_B if R_W_B_raw is None else R_W_B_raw  # (the AHRS's own: what the image's normal is turned by)
            if image_tilt_from_many(est):
                self.ahrs.update(R_img, self.T_B_C[:3, :3],
                                 est.extras.get("normal_img_C"), est.extras.get("tilt_sigma_deg", float("nan")), t,
                                 est.extras.get("mirror_normal_img_C"),
                                 est.extras.get("mirror_chi2_gap", float("inf")))
                normal_W = pad_normal_W(est.extras.get("normal_img_C"), R_img, self.T_B_C)
                # (the AHRS's error is not learnt on a deck; the deck's tilt is, but not from markers that stood on
                # a track only design fits made: a far markers fit can lie degrees off its stated sigma
                # (image_tilt_contradicts), and on a track of their own they were taken first where they stood
                # alone.  fz253's 13-15 px markers, taken on its design-made track at 4.5-6.5 m, drew it 5 degrees
                # off in one frame, their fit 0.96 degrees sure, and were posed up to 11 % of the height off)
                if self.deck is not None and normal_W is not None and not (
                        est.method == "markers" and self.deck_known and self.deck.by_design):
                    self.deck.update(t, normal_W, est.extras.get("tilt_sigma_deg", float("nan")))
            elif self.deck is not None and "design_normal_C" in est.extras:
                # an outline whose tilt its design fit fixed surely: the whole pad's drawing measured it, as
                # a texture pose's points do (its four corners alone never count: image_tilt_from_many).
                # Left out, a grey camera's deck (fzu165) was posed from 3 m to 2 m by such outlines, 0.1-0.4 %
                # of the height off, while its tilt stayed untracked: the markers that came next, 36
                # corners 0.4 % off, were refused as loose
                normal_W = pad_normal_W(est.extras["design_normal_C"], R_img, self.T_B_C)
                if normal_W is not None:
                    self.deck.update(t, normal_W, est.extras["design_tilt_sigma_deg"], by_design=True)
        self._after_accept(method, est, gray)
        return est

    def _candidates(self, method: str, res: tuple, gray, up_C) -> list:
        """``[(method, (pose, n, extras)), ...]``: what the gates are asked in turn for a method's pose
        ``res``: a flow pose's the pad's texture placed where it puts it first, where that anchors a
        chained keyframe (:meth:`_texture_over_flow`); else the pose alone."""
        if method == "flow":
            over = self._texture_over_flow(res[0], gray, up_C)
            if over is not None:
                return [("texture", over), (method, res)]
        return [(method, res)]

    def _texture_over_flow(self, pose: PoseResult, gray, up_C):
        """``(pose, n, extras) | None``: the pad's texture drawn where the flow's ``pose`` puts it and
        tracked into the frame (:meth:`hvloc.texture.PadTexture.placed_at`, no ORB), once for each
        chained keyframe (one the tracker renewed from its own pose, not anchored to the pad), where
        that pose lies where the flow's says within both doubts (:func:`foreseen`) and is surer than
        the keyframe: the keyframe after it is then the texture's, anchored.

        A chain's error grows at each renewal, the tracked pose's tilt above all where nothing holds
        it: on a tilting deck the IMU's up says little.  On the smoke deck (10 degrees, 320x320) a
        chain of 12 renewals from 0.77 m drifted 0.7-1.2 degrees, 5-9 mm sideways at 0.3-0.45 m,
        where the texture's poses were within 0.15 degrees; on level ground the chain held to 1-2
        mm and the texture to a few tenths."""
        cfg, kf = self.config, self.flow.kf
        if (kf is None or kf.anchored or kf.serial == self.texture_tried_kf or cfg.anchor_once or not cfg.use_texture
                or self.pad is None or pose.cov is None or not self._texture_allowed(self.policy_h, orb=True)):
            return None
        self.texture_tried_kf = kf.serial
        from .texture import RANSAC_PX

        T, motion = pose.cam2pad, self._drawn_motion()
        plan = self._smear_plan(T, motion) or (T, None, 0.0, 2.0 * RANSAC_PX)  # (sharp: no smear to draw)
        det, _ = self.work(lambda: ("texture_at", id(self._texture), array_key(T), plan[3], plan[1] is not None and (
                                        array_key(motion.v_P), array_key(motion.w_C), self.exposure_s)),
                           self._texture.placed_at, gray, self.camera, *plan)
        posed, _ = self._posed(det, "", self._prior(), up_C, False)
        if posed is None or posed[0].cov is None:
            return None
        if not foreseen(posed[0], (T[:3, 3], pose.cov[:3, :3])) or not _surer(kf, posed[0].cov):
            return None
        posed[2]["over_flow"] = True
        return posed

    def _pad_tilt_seen(self, est: Estimate, R_W_B) -> None:
        """A pad taken for level that the image shows tilting is taken for a deck from the next frame.

        By default the pad lies level (``pad_tilt_deg`` 0): the gravity prior draws every pose to the
        IMU's up, and on a deck that rolls 5 degrees the poses are off by the roll, saying ``ok``
        (the decks suite: 312 false accepts in 723 frames; unseen76: 45).  Markers and texture near
        the pad fix its tilt from the image alone to a degree and better (:func:`sure_tilt`), and
        there a level pad's tilt never contradicted the IMU (:func:`image_tilt_contradicts`; such a
        pose is refused).  After :data:`DECK_SEEN_POSES` such poses within
        :data:`DECK_SEEN_WINDOW_S` (not in a row: a rolling deck passes level) the localizer does what
        ``pad_tilt_deg`` would have had it do: the deck's tilt tracked from these poses on
        (:class:`DeckTilt`, bounded by 1.5 times the most the image has shown, widened as it shows
        more), far poses whose tilt the image cannot fix refused, the AHRS's error no longer learnt
        (the deck's tilt is not it), and the poses, velocity and keyframe made on a level pad
        forgotten.  Said in the frame's reason (``deck``).  Before that the far poses are as wrong
        as ever: only the user, stating ``pad_tilt_deg``, can tell a far pad's tilt.

        A deck told too small a ``pad_tilt_deg`` is widened the same way where a sure pose's tilt
        lies three of its sigmas past it (unseen79, a deck tilting to 6.7 degrees told 2: touchdown
        31 % posed, the tracked tilt held to 2 degrees and the tracks' poses refused)."""
        # (not from a patch of the pad: a wrinkle tilts it as far as a deck does, DECK_SEEN_MIN_SPREAD)
        sees_pad = est.extras.get("spread_m", 0.0) >= DECK_SEEN_MIN_SPREAD * self.geometry.side_m
        n_W = pad_normal_W(est.extras.get("normal_img_C"), R_W_B, self.T_B_C) if sure_tilt(est) and sees_pad else None
        if n_W is None:
            return
        tilt = math.degrees(math.acos(float(np.clip(n_W[2], -1.0, 1.0))))
        sigma = float(est.extras["tilt_sigma_deg"])
        if self.told_config is not None:  # a deck it saw: as far as the image shows it tilting
            if DECK_AMPLITUDE_SHARE * tilt > self.config.pad_tilt_deg:
                self._deck_amplitude(DECK_AMPLITUDE_SHARE * tilt)
            return
        if self.deck is not None:  # a deck it was told of: widened where the image surely shows it tilting further
            if tilt - 3.0 * sigma > self.config.pad_tilt_deg:
                told = self.config.pad_tilt_deg
                self.told_config = self.config
                self._deck_amplitude(DECK_AMPLITUDE_SHARE * tilt)
                self.deck_note = (f"the pad lay {tilt:.1f} deg (+-{sigma:.1f}) from the IMU's up, further than the "
                                  f"pad_tilt_deg of {told:g} it was told: taken to tilt up to {self.config.pad_tilt_deg:.1f} deg")
            return
        if self.deck_seen:
            return
        if not image_tilt_contradicts(est, self.config, self.config.max_tilt_error_deg + self.gates.tilt_allowance_deg):
            return
        self.tilted = [r for r in self.tilted if 0.0 <= est.t - r[0] <= DECK_SEEN_WINDOW_S] + [(est.t, n_W, sigma, tilt)]
        if len(self.tilted) < DECK_SEEN_POSES:
            return
        self.deck_seen, self.tilted = self.tilted, []
        self.deck_note = (f"the pad lay {min(r[3] for r in self.deck_seen):.1f}-{max(r[3] for r in self.deck_seen):.1f} "
                          f"deg from the IMU's up where {len(self.deck_seen)} poses fixed its tilt (a deck, a slope, or an AHRS that "
                          f"far off): taken for a deck "
                          f"tilting up to {self._seen_amplitude():.1f} deg from the next frame (state pad_tilt_deg; "
                          f"README: Landing on a ship)")

    def _seen_amplitude(self) -> float:
        return min(DECK_AMPLITUDE_SHARE * max(r[3] for r in self.deck_seen), 30.0)

    def _take_for_deck(self) -> None:
        """What the config would have had the localizer do had it said the pad tilts as far as
        :meth:`_pad_tilt_seen` saw, from this frame on; the poses, velocity and keyframe made on a
        level pad forgotten, and the AHRS's error no longer learnt."""
        a = self._seen_amplitude()
        self.told_config = self.config
        self.deck = DeckTilt(a, self.config.ahrs_tilt_sigma_deg)
        self._deck_amplitude(a)
        for t, n, s, _ in self.deck_seen:
            self.deck.update(t, n, s)
        self.deck_seen = []
        self.ahrs = AHRSTiltBias(0.0, self.config.ahrs_tilt_sigma_deg)
        self._forget_motion()

    def _forget_motion(self) -> None:
        """The last pose, the velocity and the flow's keyframe no longer steer what comes next."""
        self.last, self.velocity = None, None
        self.vfilter.reset()
        self.flow.reset()

    def _deck_amplitude(self, amplitude_deg: float) -> None:
        """From now on, the pad may tilt ``amplitude_deg`` (at most 30): as if the config said so."""
        a = min(float(amplitude_deg), 30.0)
        self.config = self.config.model_copy(update={"pad_tilt_deg": a, "ahrs_bias_time_s": 0.0})
        self.gates.config = self.config
        self.deck.widen(a)
        self.up_sigma_deg, self.up_tolerance_deg = self.config.up_sigma_deg(), a
        self.gates.tilt_allowance_deg = a
        self.flow.gravity_sigma_deg = self.up_sigma_deg

    def _update_twist(self, t: float, imu: bool) -> None:
        """The camera's motion at ``t`` for the rolling shutter's correction: its angular rate from
        the gyro; its velocity from a Kalman filter (:class:`hvloc.shutter.VelocityFilter`) that the
        IMU's accelerations since the last pose carry (:meth:`_imu_motion`) and each accepted pose's
        velocity-free position corrects, as sure as its covariance says (a flow pose's keyframe's
        doubt told apart: the same in every pose of that keyframe, a jump where it changes).  A
        velocity once two poses are in, at most :data:`TWIST_WINDOW_S` apart.  The filter predicts
        for every camera (the flow's guess reads its position, :meth:`_predicted`); the twist is
        set only where the shutter rolls.

        It was the slope of a line through the last 0.45 s of poses, carried from the line's mean
        time by the rows: every pose weighed alike.  On the airframe suite's 5 Hz camera (read in
        29 ms) markers poses at 5-9 m, 50-100 mm off, made velocities 0.5 m/s off, whose unrolling
        moved the next poses as much again.  Over 13 rolling-shutter descents (the airframe suite,
        bench_v2's two, unseen40) Adjustment RMSE 25.1 -> 19.5 mm, touchdown 3.0 -> 3.0 mm.

        The rate is not the one between two AHRS attitudes a frame apart: tried on bench_v2's
        x_field_rs_oblique, its noise moved poses more than the shutter does (a pose 2.4 mm off
        uncorrected was 23 mm off with that rate, 2.7 mm with the gyro's).  The IMU follows the
        drone, not the pad: a deck that accelerates is the filter's process noise, and in the
        covariance (:data:`SHUTTER_VELOCITY_DOUBT`).

        Nothing without the IMU's attitude this frame (``imu``): poses without gravity are too
        loose to tell the velocity (bench_v2's no_imu ablation on its two rolling-shutter datasets:
        107 -> 109 false accepts and touchdown 2.2 -> 5.7 mm with the velocity's correction)."""
        if not imu:
            self.twist = None
            self.vfilter.pred = self.vfilter.coast = None
            return
        if self.vfilter.t is not None:
            motion = self._imu_motion(self.vfilter.t, t)
            self.vfilter.predict(t, motion and motion[:2], motion[2] if motion else 0.0)
        if not self.shutter.active:
            return
        w = None if self.rate_B is None else self.T_B_C[:3, :3].T @ self.rate_B
        v = self.vfilter.velocity
        self.twist = None if v is None and w is None else Twist(v, w)

    def _imu_motion(self, t0: float, t: float):
        """``(dv, dp, q)``: the velocity the IMU's rows since ``t0`` added by ``t`` and the position
        that added, in the pad frame (the gates' vision-IMU heading), and the accelerometer's noise
        as the velocity filter's process noise (m^2/s^3: the rows' scatter about their mean, per
        axis averaged, times their spacing; a multirotor's vibration, 2 m/s^2 a sample at 200 Hz,
        gives 0.02); ``None`` where the rows do not cover that time at 50 Hz or more
        (:func:`imu_accel`) or the pad's heading is not known."""
        since = [(ta, a, dt) for ta, a, dt in self.accels if t0 < ta <= t + 1e-9 and dt <= IMU_DENSE_S]
        R_W_P = self.gates.pad_orientation(t) if self.gates.heading.turning() else self.gates.R_W_P
        if not since or R_W_P is None or sum(dt for _, _, dt in since) < 0.8 * (t - t0):
            return None
        ta, a, dt = (np.array(c) for c in zip(*since))
        q = float(a.var(axis=0, ddof=1).mean() * dt.mean()) if len(a) >= 4 else 0.0
        return R_W_P.T @ (a * dt[:, None]).sum(axis=0), R_W_P.T @ (a * (dt * (t - ta))[:, None]).sum(axis=0), q

    def _unrolled(self, px, cam2pad, pts_P):
        """``px`` as the rolling shutter's reference row would have seen them (:mod:`hvloc.shutter`)."""
        return self.shutter.unrolled(self.camera, cam2pad, pts_P, px, self.twist)

    def _velocity_free(self, pose: PoseResult, pts_P, px, solve, extras: dict, shared_cov=None,
                       shared_key=None) -> PoseResult:
        """``pose`` (of the unrolled pixels ``px``) as the shutter's velocity leaves it.  Solved again
        (``solve(pixels)``) with the velocity's share of the unrolling put back (the gyro's kept), its
        position goes to ``extras["still_p"]``: the shutter's velocity filter is told these, never
        poses that were themselves corrected with it.  That was a loop: a pose off by e moves
        the next velocity by ~e / dt, whose correction moves the next pose by ~fx * line_s * e / dt,
        the other way (the rows' skew read as a tilt); on a 1280x960 camera at 5 Hz read in 29 ms
        (fx 1545 px), poses at 1.7 m swung +-60 mm from frame to frame, growing, with markers
        fitting to 0.2 px.  Poses solved without the velocity carry its rows' skew (~fx * line_s *
        v, a constant while the velocity is), so their slope is off by ~fx * line_s times the
        acceleration (there: 1-2 cm/s while the drone slowed for touchdown).

        And the velocity is counted uncertain in the pose's covariance: by
        :data:`SHUTTER_VELOCITY_DOUBT` of its speed, spread over every direction (each axis a third
        of the variance).  The velocity is read from past poses and carried by the IMU; a drone that
        accelerates (a gust, a deck, the flare before touchdown) has moved on.  unseen28's texture
        poses at 0.3 m (a deck, 1.4 m/s^2 of relative acceleration) were 4.3 mm off with 0.1-0.2 mm
        stated, within 0.2 mm with the true velocity.  Counted along the velocity alone (stop 40) the
        covariance was a needle: poses whose velocity was off across its direction (a lateral gust)
        were 1-3 mm off across it with 0.05-0.2 mm stated (unseen38's texture at 0.25-0.6 m, NEES
        116-208).  Over six rolling-shutter scenes (unseen27/28/34/36/37/38, 16 descents) poses
        beyond 3 sigma went 1.7 -> 0.2 % in Adjustment and 4.0 -> 0 % in touchdown; the flow's
        NEES median fell 0.59 -> 0.14 (conservative: its keyframe's doubt is carried too).  Cost:
        two more solves a frame where the shutter rolls (~4 ms on 720p).

        ``pose`` as it is where no velocity moved it: a global shutter (whose flow poses tell the
        filter their keyframe's doubt apart all the same: told as their own, 10-20 mm a pose near the
        ground, they told it nothing); or none known yet, where its covariance counts the velocity it
        could have (:meth:`_velocity_unknown`).  And under a
        rolling shutter its covariance counts the gyro's rate as uncertain too (:meth:`_rate_spread`).
        ``shared_cov``: the part of its covariance the poses of ``shared_key`` share (a flow pose's
        keyframe's), which the velocity filter is told apart (``extras["still_shared"]``);
        ``shared_key``: ``(key, parent)``, the key its own was renewed from or ``None``."""
        if self.shutter.active:
            pose = self._rate_spread(pose, pts_P, px, solve)
        if pose.cov is not None and (self.shutter.active or shared_cov is not None):
            # what the velocity filter is told: the fit's doubt (and the rate's) apart from the shared
            extras["still_cov"] = pose.cov[:3, :3] - (0.0 if shared_cov is None else shared_cov[:3, :3])
            if shared_cov is not None:
                extras["still_shared"] = (shared_key[0], shared_cov[:3, :3], shared_key[1])
        return self._velocity_twin(pose, pts_P, px, solve, extras) if self.shutter.active else pose

    def _velocity_twin(self, pose: PoseResult, pts_P, px, solve, extras: dict) -> PoseResult:
        """:meth:`_velocity_free` under a rolling shutter: the twin and the velocity's doubt."""
        tw = self.twist
        if tw is None or tw.v_P is None:
            return self._velocity_unknown(pose, pts_P, px, solve, extras)
        d = self.shutter.shift(self.camera, pose.cam2pad, pts_P, px, Twist(tw.v_P, None))
        still = solve(np.where(np.isfinite(d), px + d, px))
        if still is None:
            return pose
        extras["still_p"] = still.cam2pad[:3, 3].copy()
        if extras.get("velocity_from_image_cov") is not None:  # the image's velocity: as sure as it and the prediction make it
            return self._velocity_spread(pose, pts_P, px, solve, 0.0, extras=extras,
                                         cov_mps=extras["velocity_from_image_cov"])
        speed = float(np.linalg.norm(tw.v_P))
        if pose.cov is None or speed == 0.0:
            return pose
        sigma = SHUTTER_VELOCITY_DOUBT * speed / math.sqrt(3.0)  # per axis: SHUTTER_VELOCITY_DOUBT of it in all
        moved = pose.cam2pad[:3, 3] - extras["still_p"]  # what the velocity itself moved it by: its own axis's share
        return self._velocity_spread(pose, pts_P, px, solve, sigma, (tw.v_P / speed, moved * sigma / speed), extras)

    def _velocity_from_image(self, pose: PoseResult, pts_P, px, solve):
        """``(pose, pixels, twist, cov)`` where ``pose`` (of the pixels ``px``, unrolled with the
        velocity filter's prediction) fits worse than the reprojection gate allows under a rolling
        shutter and a velocity within the prediction's doubt fits: the pose solved again with that
        velocity's unrolling, those pixels, the frame's twist with it, and that velocity's
        covariance (the prediction's narrowed by the pixels); else ``None``.  Flow poses, and
        pad poses of :data:`VELOCITY_FROM_IMAGE_MIN_POINTS` or more (a landed drone whose filter
        still carried its approach: unseen87's 284 texture points at 0.15 m refused at 5.6 px).

        The filter's velocity is the IMU's integral since the last pose, and a vibrating IMU's is
        50-90 mm/s off over 0.2 s (the airframe suite's 5 Hz camera, read in 29 ms, 2 m/s^2 of
        vibration): unrolled with it, the rows of a frame at 0.15-0.2 m are skewed 10-20 px across
        the tracks, the pose takes up part of it and the rest is a reprojection RMS of 3.1-3.7 px
        for tracks that fit to under 1 px.  Those right poses (1.5-4.3 mm off) were refused, the
        keyframe aged and the tracks ran out (8 of a_slow_vibrating's 33 touchdown frames).

        The residuals are nearly linear in the velocity's error: one solve for each principal axis
        of the prediction's covariance (one sigma along it) gives their change, and the velocity
        that minimises them, weighed against the prediction (:data:`SHUTTER_VELOCITY_SEARCH_PX` per
        track coordinate against its covariance), is taken when it lies within
        :data:`SHUTTER_VELOCITY_SEARCH_CHI2` of the prediction and its pose passes the gate.
        Gauss-Newton steps until it settles (at most :data:`VELOCITY_SEARCH_STEPS`): one step lands
        anywhere along what the image barely sees (unseen87's landed frame, the filter 0.17 m/s
        off: that velocity 0.1 m/s off along the optical axis, the pose 3.3 mm off; four steps, 0.6
        mm), and the pose counts the velocity's covariance, not half its speed (:meth:`_velocity_twin`).
        The image cannot ask for more than the doubt allows: tracks off for any other reason (a
        slipped cell, a wrong keyframe) are not skewed row by row as a velocity skews them, and
        stay refused.  Along the optical axis a velocity's skew looks like a tilt, and the
        prediction keeps most of it.  Four solves a step, on refused poses only."""
        tw, S, gate = self.twist, self.vfilter.velocity_cov, self.config.max_reprojection_px
        if not self.shutter.active or tw is None or tw.v_P is None or S is None or not pose.rms_px > gate:
            return None
        lam, U = np.linalg.eigh(S)
        axes = U * np.sqrt(np.clip(lam, 0.0, None))  # columns: one sigma along each principal axis

        def unrolled(v):
            return self.shutter.unrolled(self.camera, pose.cam2pad, pts_P, px, Twist(v, None))

        def residuals(at, seen):
            return (self.camera.project_from(at.cam2pad, pts_P) - seen).ravel()

        a, at, seen = np.zeros(3), pose, px
        s2 = SHUTTER_VELOCITY_SEARCH_PX ** 2
        for _ in range(VELOCITY_SEARCH_STEPS):
            r0 = residuals(at, seen)
            J = np.empty((len(r0), 3))
            for i in range(3):
                moved = unrolled(axes @ (a + np.eye(3)[i]))
                other = solve(moved)
                if other is None:
                    return None
                J[:, i] = residuals(other, moved) - r0
            if not (np.isfinite(J).all() and np.isfinite(r0).all()):
                return None
            # r(a + d) = r0 + J d, weighed against the prediction (a = 0)
            d = -np.linalg.solve(J.T @ J + s2 * np.eye(3), J.T @ r0 + s2 * a)
            a = a + d
            if float(a @ a) > SHUTTER_VELOCITY_SEARCH_CHI2:
                return None
            seen = unrolled(axes @ a)
            at = solve(seen)
            if at is None:
                return None
            if float(d @ d) < 1e-4:
                break
        if not at.rms_px <= gate:
            return None
        # its doubt: the prediction's, narrowed by what the pixels (each SHUTTER_VELOCITY_SEARCH_PX) tell
        cov = axes @ np.linalg.inv(J.T @ J / s2 + np.eye(3)) @ axes.T
        return at, seen, Twist(tw.v_P + axes @ a, tw.w_C), cov

    def _velocity_unknown(self, pose: PoseResult, pts_P, px, solve, extras: dict) -> PoseResult:
        """``pose`` under a rolling shutter before any velocity is known (a track's first two poses,
        the first after a loss; every pose without an IMU), its rows' skew left in.  Its covariance
        gains what a velocity of :data:`UNKNOWN_SPEED_MPS` along each pad axis would have
        moved it (solved again with each one's unrolling: three solves, on these poses only).  Those
        poses stated the covariance of a still camera: on unseen38 (read in 32 ms) two texture poses
        at 0.28 m, the track lost for 0.4 s and the drone at 0.65 m/s, were 6-8 mm off with 1 mm
        stated (NEES 59 and 158).  Where the last two accepted poses give a speed (without an IMU:
        too loose to unroll with, bench_v2's no_imu ablation), that speed spread over the three
        axes is counted instead: a descent at 0.2 m/s is not doubted as one at 0.9.  Only from the
        frame just before: after a loss the drone may be another speed (unseen38's texture poses
        above, after 0.4 s lost, read the speed before the loss as 0.2 m/s and were NEES 36-63)."""
        v = self._recent_velocity()
        if v is not None:
            speed = max(float(np.linalg.norm(v)), SHUTTER_MIN_SPEED_MPS)
            return self._velocity_spread(pose, pts_P, px, solve, speed / math.sqrt(3.0), extras=extras)
        return self._velocity_spread(pose, pts_P, px, solve, UNKNOWN_SPEED_MPS, extras=extras)

    def _velocity_spread(self, pose: PoseResult, pts_P, px, solve, sigma_mps: float, along=None,
                         extras: dict | None = None, cov_mps=None) -> PoseResult:
        """``pose`` with what an error of ``sigma_mps`` along each of three orthogonal directions in
        the shutter's velocity would move it in its covariance: the pad's axes, each solved again
        (three solves); or, given ``along`` = (a unit direction, the move along it, already known),
        that direction and two across it (two solves); or, given the velocity's covariance
        ``cov_mps`` (3x3), its principal axes, each by its own sigma (three solves).

        The same solves say how the pose's velocity-free twin (the pose itself where no velocity
        unrolled it) answers the true velocity: ``twin = p - M v`` to first order, ``M`` (3x3,
        m per m/s) to ``extras["still_dv"]``, so the velocity filter reads the twin for what it is.
        Left out, a change of solver (texture to flow: the flow's twin 22 mm off at 0.4 m and 0.5
        m/s, the texture's 4) read as a jump in position: the velocity 0.2 m/s off for 3-4 frames."""
        if pose.cov is None or (cov_mps is None and sigma_mps <= 0):
            return pose
        axes, known = [(axis, sigma_mps) for axis in np.eye(3)], None
        M = np.zeros((3, 3))
        if cov_mps is not None:
            lam, U = np.linalg.eigh(0.5 * (cov_mps + cov_mps.T))
            axes = [(U[:, i], math.sqrt(lam[i])) for i in range(3) if lam[i] > 0.0]
        elif along is not None:
            u, moved = along
            known = np.outer(moved, moved)
            M += np.outer(moved / sigma_mps, u)
            a = np.cross(u, np.eye(3)[int(np.argmin(np.abs(u)))])
            a /= np.linalg.norm(a)
            axes = [(a, sigma_mps), (np.cross(u, a), sigma_mps)]
        moves = []
        out = self._twist_spread(pose, pts_P, px, solve, [Twist(s * axis, None) for axis, s in axes], known,
                                 moves=moves)
        if extras is not None and len(moves) == len(axes):
            for (axis, s), delta in zip(axes, moves):
                M += np.outer(delta / s, axis)
            extras["still_dv"] = M
        return out

    def _image_motion(self, cam2pad: np.ndarray, motion: Twist | None, pts_P) -> np.ndarray | None:
        """``(N, 2)`` how far each of ``pts_P`` moves in the image over the exposure, seen from
        ``cam2pad`` under ``motion``; ``None`` with no exposure or no motion known."""
        e = self.exposure_s
        if not e > 0 or motion is None or (motion.v_P is None and motion.w_C is None):
            return None
        return (self.camera.project_from(motion.moved(cam2pad, 0.5 * e), pts_P)
                - self.camera.project_from(motion.moved(cam2pad, -0.5 * e), pts_P))

    def _motion(self) -> Twist:
        """The motion this frame is exposed under: the velocity filter's velocity for it (the poses
        carried by the IMU's rows, through a gap up to its coast), else the last two poses' where
        the frame before was posed, and the gyro's rate.  No velocity after a loss that nothing
        carried the motion through: the drone may be another speed there."""
        w = None if self.rate_B is None else self.T_B_C[:3, :3].T @ self.rate_B
        pred = None if self.last_t is None else self.vfilter.position(self.last_t)
        if pred is not None:
            return Twist(pred[2], w)
        return Twist(self._recent_velocity(), w)

    def _sure_rate_C(self) -> np.ndarray | None:
        """The gyro's rate for this frame (in the camera) as far as it is sure: less its doubt about
        each body axis (:func:`imu_turn`), as read where no doubt is known; ``None`` without one.

        What a drawing is smeared by, and what judges whether the motion smears a frame: a
        multirotor's vibration is most of one frame's rate.  A drawing smeared past the frame's
        own smear lays its streaks' ends on the frame's edges, and its tracks move half the miss:
        on fzu11 (a 95 degree lens 30 degrees off nadir, 20 ms exposures, a gyro vibrating 0.25
        rad/s) rates read 0.3-0.4 rad/s on 0.24-0.27 of doubt smeared the texture's drawing 5-6.5
        px where the pad moved 1.4-2.4 px over the exposure (its frames were rendered sharp, camera.json
        then still saying 20 ms), its tracks 2.7 px off along the smear in the
        median, and texture poses at 2.2-4.8 m 1.5-7 % of the height off stating a tenth of that
        (NEES 14-178).  fz313's 0.06-0.12 rad/s of doubt on 0.1-0.27 read predicted 1.0-1.7 px of
        smear where the pad moved 0.3-0.4 px over its 10 ms exposures.  A real turn (1 rad/s read on
        0.05 of doubt) keeps all but its doubt."""
        if self.rate_B is None:
            return None
        rate = self.rate_B
        if self.rate_doubt is not None:
            rate = np.sign(rate) * np.maximum(np.abs(rate) - self.rate_doubt, 0.0)
        return self.T_B_C[:3, :3].T @ rate

    def _drawn_motion(self) -> Twist:
        """The motion a drawing of the pad is smeared by: :meth:`_motion`'s velocity and the gyro's
        rate as far as it is sure (:meth:`_sure_rate_C`)."""
        return Twist(self._motion().v_P, self._sure_rate_C())

    def _recent_velocity(self) -> np.ndarray | None:
        """The last two accepted poses' velocity where the frame before this one was posed (or this
        one is): after a loss the drone may be another speed."""
        return self.velocity if self.unposed <= 1 else None

    def _smear_spread(self, pose: PoseResult, pts_P, px, solve, keyframe=None,
                      doubt: float = TRACK_SMEAR_DOUBT) -> PoseResult:
        """``pose`` with, in its position covariance, how far it moves when every one of its points
        ``px`` (tracked by Lucas-Kanade, solved by ``solve(pixels)``) shifts by
        :data:`TRACK_SMEAR_DOUBT` of how much more (or otherwise) it is smeared over the exposure than
        where it was tracked from: the keyframe's frame (``keyframe``, its motion known), or a
        sharp drawing; each smear as the last poses' velocity and the gyro's rate predict it (one
        solve; none where that differs by under :data:`TRACK_SMEAR_MIN_PX` for every point, no
        exposure is known or no motion is).  A feature's track lands where its smeared patch best
        matches the other, differently smeared one, which its shape decides; features alike move
        alike, and the pose takes their shared shift whole (two patches smeared alike match
        without it: a steady descent's flow is not doubted for its smear).  On the
        conditions suite's deck pitched 30 degrees under a 1 m/s relative motion (30-37 px of smear
        at 0.15-0.2 m), flow poses were 1.4-2.2 mm off with 1.1-1.3 mm stated (NEES up to 27); a
        texture pose at 0.25 m under some 20 px (unseen49) 1.1 mm off with 0.2-0.3 mm stated (NEES 61).

        With no velocity known (:meth:`_motion`: a track's first pose, the first after a loss the
        IMU did not carry the motion through) the smear of :data:`UNKNOWN_SPEED_MPS` along each pad
        axis is counted too (three more solves): unseen83's first texture poses at 0.3 m after 2 s
        lost in a gale stated a still camera's doubt, 1.3-3.4 mm off for 0.3-0.7 mm (NEES 18-99).
        With one known, the smear of one sigma of the filter's velocity along each of its principal
        axes (after a gap the IMU's rows carry it to a few tenths of a metre per second: unseen88's
        texture pose at 0.18 m, 0.53 mm off, stated 0.15 with the velocity taken as exact).

        ``doubt``: the share of the smear counted (:data:`TRACK_SMEAR_DOUBT` for tracked points;
        :data:`KEYPOINT_SMEAR_DOUBT` for ORB's keypoints, which land anywhere along a smear)."""
        if pose.cov is None:
            return pose
        motion = self._motion()
        smears = [self._image_motion(pose.cam2pad, motion, pts_P)]
        if keyframe is not None and smears[0] is not None:  # (no motion known for the keyframe: counted as sharp)
            then = self._image_motion(keyframe.cam2pad, keyframe.motion, pts_P)
            smears[0] = smears[0] if then is None else smears[0] - then
        if motion.v_P is None:  # no velocity known: what one of UNKNOWN_SPEED_MPS along each pad axis smears
            smears += [self._image_motion(pose.cam2pad, Twist(UNKNOWN_SPEED_MPS * a, None), pts_P) for a in np.eye(3)]
        else:  # a velocity known as well as the filter has it: what one sigma along each of its principal axes smears
            S = None if self.last_t is None else self.vfilter.velocity_doubt(self.last_t)
            if S is not None:
                lam, U = np.linalg.eigh(0.5 * (S + S.T))
                smears += [self._image_motion(pose.cam2pad, Twist(math.sqrt(lam[i]) * U[:, i], None), pts_P)
                           for i in range(3) if lam[i] > 0.0]
        cov = pose.cov.copy()
        for d in smears:
            fin = None if d is None else np.isfinite(d).all(axis=1)
            if d is None or not fin.any() or float(np.linalg.norm(d[fin], axis=1).max()) < TRACK_SMEAR_MIN_PX:
                continue
            other = solve(np.where(fin[:, None], px + doubt * np.nan_to_num(d), px))
            if other is not None:
                delta = other.cam2pad[:3, 3] - pose.cam2pad[:3, 3]
                cov[:3, :3] += np.outer(delta, delta)
        return replace(pose, cov=cov)

    def _edge_fit_outrun(self, pose: PoseResult, pts_P, read_px: float | None) -> str:
        """Why an outline whose sides an edge fit placed (``read_px``: the smear read on the image,
        which chose that fit; ``None`` for any other pose) cannot be taken, or ``""``: the last poses'
        velocity and the gyro's rate predict more smear across one of its sides than the fit holds to
        (:data:`hvloc.phases.EDGE_FIT_SMEAR_PX`) and over :data:`EDGE_FIT_OUTRUN` times what was read.
        The smear is read on the white field's edge, as one kernel for each pair of sides; a turn or a
        zoom smears each corner its own way, and a pad filling the view was read at 5-9 px under 20-40
        px of smear across its sides (unseen55: a 40 ms exposure in a gusty turn), its sides fitted
        7-21 px out and posed 98 mm off, beyond its 3 sigma.  Only with a velocity from the last poses
        (no motion is predicted whole without one: the first frame's gyro rate, a single row at a
        descent's start, read 2.2 rad/s where the frame was smeared 9-11 px, and the pad was lost).
        The gyro's part is what it surely says (:meth:`_sure_rate_C`): a vibrating gyro read whole
        predicts smear that is not there."""
        motion = self._drawn_motion()
        if read_px is None or motion.v_P is None:
            return ""
        d = self._image_motion(pose.cam2pad, motion, pts_P)
        if d is None:
            return ""
        n = ph.side_normals(self.camera.project_from(pose.cam2pad, pts_P))[1]  # side j smeared as its two ends are
        across = np.maximum(np.abs(np.sum(d * n, axis=1)), np.abs(np.sum(np.roll(d, -1, axis=0) * n, axis=1)))
        worst = float(np.max(np.nan_to_num(across)))
        if worst > max(ph.EDGE_FIT_SMEAR_PX, EDGE_FIT_OUTRUN * read_px):
            return (f"its sides edge-fitted under {read_px:.1f} px of smear as read, but the motion predicts "
                    f"{worst:.1f} px across one (> {ph.EDGE_FIT_SMEAR_PX:.0f})")
        return ""

    def _rate_spread(self, pose: PoseResult, pts_P, px, solve) -> PoseResult:
        """``pose`` with what the gyro's rate, off by its doubt (:func:`imu_rate_doubt`) about each
        body axis, would move it, in its covariance: each axis solved again with that rate's
        unrolling (three solves; none for an axis whose unrolling moves no point by
        :data:`RATE_SPREAD_MIN_PX`, as a quiet gyro's).  A pose is as sure as the rate it was unrolled
        with: on the airframe suite's 5 Hz camera (read in 29 ms) with a vibrating IMU, markers poses
        at 2-9 m were 30-90 mm off where the quiet IMU's were 10-40, and 9.6 % of its Adjustment
        poses lay beyond 3 sigma (0.3 % with this).  Nothing where the frame has no gyro rate or no
        doubt of it (a single row: :attr:`LocalizerConfig.imu_rows` off)."""
        s, tw = self.rate_doubt, self.twist
        if s is None or pose.cov is None or tw is None or tw.w_C is None:
            return pose
        R_C_B = self.T_B_C[:3, :3].T
        return self._twist_spread(pose, pts_P, px, solve, [Twist(None, R_C_B @ (s[i] * np.eye(3)[i])) for i in range(3)],
                                  min_px=RATE_SPREAD_MIN_PX)

    def _twist_spread(self, pose: PoseResult, pts_P, px, solve, twists: list, known=None,
                      min_px: float = 0.0, moves: list | None = None) -> PoseResult:
        """``pose`` with, in its position covariance, ``known`` (3x3) and, for each of ``twists``
        (one sigma of a doubt in the shutter's motion), how far the pose moves when its unrolling is
        added to the pixels and the pose solved again (``solve(pixels)``); a twist that moves no
        pixel by ``min_px`` is not solved.  ``moves`` gets each solved twist's move."""
        cov = pose.cov.copy()
        if known is not None:
            cov[:3, :3] += known
        for twist in twists:
            d = self.shutter.shift(self.camera, pose.cam2pad, pts_P, px, twist)
            if min_px > 0.0 and not (np.abs(np.nan_to_num(d)) >= min_px).any():
                continue
            other = solve(np.where(np.isfinite(d), px - d, px))
            if other is not None:
                delta = other.cam2pad[:3, 3] - pose.cam2pad[:3, 3]
                cov[:3, :3] += np.outer(delta, delta)
                if moves is not None:
                    moves.append(delta)
        return replace(pose, cov=cov)

    def _update_phase(self, h) -> None:
        self.phase = next_phase(self.phase, h, self.last.method if self.last is not None else "", self.config)

    def _prior(self):
        return self.last.cam2pad if self.last is not None else None

    def _design(self) -> ph.PadDesign:
        if self._design_cache is None:
            self._design_cache = ph.PadDesign(self.pad.texture_rgb)
        return self._design_cache

    def _heading_hint(self, found, R_W_B, up_C, t: float):
        """The pixel of the outline's TL corner as the IMU's heading names it, or ``None``.

        The pad's orientation in the world (the gates' running vision-IMU offset, confirmed by an
        accepted pose at most ``HEADING_MAX_AGE_S`` ago; a pad turns slowly if at all) and the AHRS's
        orientation of the body predict the camera's rotation in the pad frame.  Of the outline's four namings the one
        whose pose turns least from it wins, when it is within 30 degrees and the others are not:
        its turns are a quarter apart, so the AHRS's heading drift of a degree or two cannot swap
        them.  This names the outline where the cue cannot be read (a few pixels of yellow under
        JPEG's chroma) and the last pose is too old to be a prior."""
        R_W_P = self.gates.pad_orientation(t)
        if R_W_B is None or R_W_P is None or self.heading_t is None or not 0.0 <= t - self.heading_t <= HEADING_MAX_AGE_S:
            return None
        R_P_C = R_W_P.T @ R_W_B @ self.T_B_C[:3, :3]
        turns = []
        for k in range(4):
            pose = solve_planar_pose(self.camera, self.outer_P, np.roll(found.quad_px, -k, axis=0), up_C=up_C,
                                     gravity_sigma_deg=self.up_sigma_deg, relief_m=self.config.pad_relief_m)
            turns.append(rotation_angle(pose.cam2pad[:3, :3], R_P_C) if pose is not None else np.inf)
        k = int(np.argmin(turns))
        if turns[k] > math.radians(30) or np.partition(turns, 1)[1] < math.radians(60):
            return None
        return found.quad_px[k]

    def _cue_confirmed(self, det, why: str, found, scores: np.ndarray) -> tuple:
        """``(det, why)`` of an outline its yaw cue named on a first sight (no pose names it), where
        the pad's design (``scores``: :func:`hvloc.phases.name_by_design`'s, as good as it is
        readable) names it the same; ``(None, reason)`` where the design's best naming is another.

        With no pose before it, a misnamed first pose is a quarter turn off in yaw, metres off in
        position (the camera's offset from the pad turned about it), and every later frame read
        right is then refused as a jump from it.  Far away the cue is a few pixels: of 2,339
        outlines found in twelve scenes (19-1070 px, JPEG, shadows, clutter, dusk, decks), the cue's
        naming was right in 2,332 and the design's best naming agreed with every one; of the
        7 wrong, 5 (19-25 px, the cue read from brightness with hardly any colour, a bright
        speck of ground beside a corner) had the design naming another corner, by leads of 0.003-0.09
        (the other 2, colour alone on 320-340 px pads, the design did not tell apart).
        Two independent readings must agree, then; where they do not, the design names it only if
        it is sure on its own or over frames (:meth:`_named_by_design`)."""
        k, how = ph.cue_naming(found, self.geometry)
        if k is None or scores is None or not np.max(scores) >= ph.DESIGN_MIN_NCC:  # (a design too little seen has no say)
            return det, why
        best = int(np.argmax(scores))
        if best == k:
            return det, why
        return None, (f"its {how} names image corner {k} the pad's TL, its design corner {best} "
                      f"(correlations {np.round(scores, 2).tolist()}): no first pose from either")

    def _named_by_fit(self, found, rgb, up_C) -> tuple | None:
        """``(k, ratio)``: image corner ``k`` of ``found`` is the pad's TL corner where the pad's design
        fitted from each of the outline's four namings (:func:`hvloc.texfit.fit_pose_to_design`, with the
        IMU's gravity) fits best, the next naming's residual RMS ``ratio`` times its own (named alone
        from :data:`FIT_NAMING_RATIO`, a vote from :data:`FIT_VOTE_RATIO`); ``None`` without gravity,
        or for a pad the fit does not take.

        The correlation of the design resampled through the outline (:func:`hvloc.phases.name_by_design`)
        reads a 17-30 px pad's three markers as blots, and at dusk under JPEG 45 it leads by 0.01-0.05:
        a cold start waited 4-5 s for a naming.  Drawn, blurred and toned as the camera makes it and
        placed by the fit, the right naming's residual is half the others' from ~30 px
        (README, "Naming a far pad by its design fitted from each naming")."""
        if up_C is None or rgb is None or self.pad is None:
            return None
        field = found.field_px is not None
        quad, pts = (found.field_px, self.geometry.field_corners) if field else (found.quad_px, self.outer_P)
        rms, fits = np.full(4, np.inf), np.zeros(4, bool)
        for j in range(4):
            px = np.roll(quad, -j, axis=0)  # (the named outline's own: with shared image work its fit is not redone)
            start = solve_planar_pose(self.camera, pts, px, up_C=up_C, gravity_sigma_deg=self.up_sigma_deg,
                                      relief_m=self.config.pad_relief_m)
            if start is None:
                continue
            fitted, info = self._design_fit(start.cam2pad, rgb, up_C, ("design fit", array_key(pts), array_key(px)))
            rms[j], fits[j] = info.get("rms", np.inf), fitted is not None  # (a drawing that matched poorly: its RMS)
        k = int(np.argmin(rms))
        o = np.sort(rms)
        if not (fits[k] and np.isfinite(o[1]) and o[0] > 0):
            return None
        return k, float(o[1] / o[0])

    def _named_by_design(self, found, gray, t: float, R_W_B, up_C, why: str, scores=None, rgb=None) -> tuple:
        """``(Detection | None, reason)``: a cold start's outline named by the pad's whole design
        (:func:`hvloc.phases.name_by_design`; ``scores`` where already read), where this frame's naming
        is sure or agrees with those of the frames before (:class:`DesignVotes`: the pad's heading in
        the world each naming gives, from its pose with the IMU's gravity and the AHRS)."""
        if scores is None:
            _, scores = ph.name_by_design(gray, found.quad_px, self.geometry, self.camera, self._design())
        k = int(np.argmax(scores))
        o = np.sort(scores)
        side_px = float(np.mean(np.linalg.norm(found.quad_px - np.roll(found.quad_px, 1, axis=0), axis=1)))
        taken = self.design_votes.cast(t, self._heading_named(found, k, R_W_B, up_C), side_px, float(o[-1]),
                                       float(o[-1] - o[-2]))
        if taken is None:
            # (where the design's correlation says it is there at all: the fits cost 10-40 ms each)
            fit = self._named_by_fit(found, rgb, up_C) if o[-1] >= ph.DESIGN_MIN_NCC else None
            if fit is not None:  # named alone where its ratio is sure, else a vote (FIT_VOTE_RATIO)
                k = fit[0]
                taken = self.fit_votes.cast(t, self._heading_named(found, k, R_W_B, up_C), side_px, float(o[-1]),
                                            math.log(fit[1]))
            if taken is None:
                return None, why + (f"; nor does its design name it (correlations {np.round(scores, 2).tolist()}"
                                    + ("" if fit is None else f"; fitted, the best naming's RMS {fit[1]:.3f} times lower")
                                    + ")")
        return ph.name_outline(found, self.geometry, found.quad_px[k], hint_from=taken, use_cue=False)

    def _heading_named(self, found, k: int, R_W_B, up_C) -> float | None:
        """The pad's heading in the world (radians) where image corner ``k`` of ``found`` is its TL
        corner: the outline's pose so named, with the IMU's gravity, and the AHRS; ``None`` without
        an attitude or a pose."""
        if R_W_B is None or up_C is None:
            return None
        pose = solve_planar_pose(self.camera, self.outer_P, np.roll(found.quad_px, -k, axis=0), up_C=up_C,
                                 gravity_sigma_deg=self.up_sigma_deg, relief_m=self.config.pad_relief_m)
        if pose is None:
            return None
        R_W_P = R_W_B @ self.T_B_C[:3, :3] @ pose.cam2pad[:3, :3].T
        return math.atan2(R_W_P[1, 0], R_W_P[0, 0])

    def _try(self, method: str, rgb, gray, up_C, t: float, R_W_B=None, by_prior: bool = False):
        """``by_prior``: markers only, two of them may be named by the last pose, or on a cold start by the
        pad's design around them (the last resort)."""
        prior = self._prior()
        cfg = self.config
        if method == "flow":
            res, n, why = self.flow.track(gray, prior, up_C, self._predicted(t))
            if res is None:
                return None, why
            extras = {"keyframe_anchored": self.flow.kf.anchored, "tilt_noise_scale": res.tilt_noise_scale}
            if self.flow.fitted is not None:
                P, seen = self.flow.fitted
                def solve(px):
                    return ph.tracks_pose(self.camera, P, px, up_C, prior, self.flow.gravity_sigma)

                kf = self.flow.kf
                found = self._velocity_from_image(res, P, seen, solve)
                if found is not None:
                    again, seen, self.twist, extras["velocity_from_image_cov"] = found
                    res = self.flow.fitted_pose(again, P, seen)
                    extras["velocity_from_image"] = self.twist.v_P.copy()
                res = self._smear_spread(res, P, seen, solve, kf)
                res = self._velocity_free(res, P, seen, solve, extras, kf.cov, (kf.serial, kf.parent))
            return (res, n, extras), "ok"
        if method == "texture":
            det, why = None, ""
            if self._texture_allowed(self.policy_h, orb=True):
                h, motion = self.policy_h, self._drawn_motion()
                # a height from before the frame just gone: the drone may have come down since
                low = None if h is None or self.unposed < 2 else STALE_LOWEST_SHARE * h
                smear = self._smear_of(motion, up_C)
                det, why = self.work(lambda: ("texture", id(self._texture), self._texture.shrinks(self.camera, h, low), low,
                                              smear is not None and (array_key(motion.v_P), array_key(motion.w_C),
                                                                     self.exposure_s, array_key(up_C), self.up_sigma_deg)),
                                     self._texture.locate, gray, self.camera, h, smear, low)
            pred = None
            if det is None:  # the pad where the last pose predicts it: drawn smeared, or its design fitted when small
                pred, why0 = self._predicted_pose(t, R_W_B)
                det, why = self._synthesized(gray, pred, why or why0)
            if det is None and pred is not None and rgb is not None:
                return self._design_posed(rgb, t, pred[0], why, prior, up_C)
            return self._posed(det, why, prior, up_C, False)
        roi = ph.project_roi(self.camera, prior, self.outer_P, cfg.roi_margin) if prior is not None else None
        attempts = [roi, None] if roi is not None else [None]
        why = ""
        grey = method == "outline" and self.pad is not None and ph.is_grey(rgb)  # a monochrome camera's frame
        for r in attempts:
            # the image work is asked by everything it depends on (hvloc.work): the region, the gravity,
            # the corners found; the prior only names the corners or breaks IPPE's tie without gravity
            if method == "outline":
                if grey:  # the pad by its design, not its colour
                    found, why = self.work(lambda: ("grey outline", r), ph.find_grey_outline, rgb, gray, self.geometry,
                                           self.camera, r, self._design())
                else:
                    halved = self.work(lambda: ("chroma_halved",), ph.chroma_halved, rgb)
                    found, why = self.work(lambda: ("outline", r), ph.find_outline, rgb, self.geometry, self.camera, r,
                                           halved=halved)
                det = None
                if found is not None:
                    hint = self.camera.project_from(prior, self.outer_P) if prior is not None else None
                    hint = hint if hint is not None and np.isfinite(hint).all() else None
                    det, why = ph.name_outline(found, self.geometry, hint)
                    scores = None
                    if det is not None and hint is None and self.pad is not None:  # a first sight: the cue alone does not name it
                        scores = self.work(lambda: ("design naming", r, grey), ph.name_by_design, gray, found.quad_px,
                                           self.geometry, self.camera, self._design())[1]
                        det, why = self._cue_confirmed(det, why, found, scores)
                    if det is None and hint is None:  # no prior to name it by: the IMU's heading may
                        hint = self._heading_hint(found, R_W_B, up_C, t)
                        if hint is not None:
                            det, why = ph.name_outline(found, self.geometry, hint, hint_from="imu heading", use_cue=False)
                    if det is None and hint is None and self.pad is not None:  # a cold start: the whole design
                        det, why = self._named_by_design(found, gray, t, R_W_B, up_C, why, scores, rgb)
            else:
                use_rgb = rgb if cfg.use_outline else None
                named_by = prior if by_prior else None
                # a cold start's two markers: named by the pad's design around them (no pose names them)
                design = self._design() if by_prior and prior is None and self.pad is not None else None
                det, why = self.work(lambda: ("markers", r, cfg.binarization, use_rgb is not None, array_key(up_C),
                                              array_key(named_by), design is not None),
                                     ph.detect_markers, gray, self.geometry, self.camera, roi=r,
                                     method=cfg.binarization, rgb=use_rgb, up_C=up_C, prior=named_by, design=design)
            if det is not None and det.kind == "outline" and cfg.design_fit:
                det = self._design_fitted(det, rgb, up_C)
                if "design_disagrees" in det.info:  # (neither is taken: far_wide's 21 px pad, its corners kept, 11.5 % off)
                    det, why = None, _design_disagrees(det)
            # (a hull first: a grey blob's is read after its fit too, and refused unfitted for being a hull, not faint)
            if det is not None and det.info.get("hull_only") and not isinstance(det.info.get("design_fit"), dict):
                det, why = None, f"{det.info['hull_only']}, and its design not fitted there ({_design_note(det)})"
            if det is not None and det.info.get("read_after_fit"):
                det, why = self._read_where_fitted(det, gray, why)
            if det is not None and grey and self.deck is not None and not self.deck_known and "fitted_up_C" not in det.info:
                # the grey field's four corners on a tilted pad: 10-12 degrees off in tilt at 8 m on
                # deck_mono (both of IPPE's minima), stating 2.5.  Its design, where it fits the tilt
                # (hvloc.texfit.TILT_MIN_SIDE_PX and sharp), fixes it as on a colour camera's frame;
                # else the deck's tilt must be tracked first
                det, why = None, ("grey outline: its four corners do not fix a tilting deck's tilt, the deck's is "
                                  f"not tracked yet, and its design did not fit it ({_design_note(det)})")
            if det is not None and det.kind == "outline":
                det, why = self._small_field_refused(det, why)
            if det is not None:
                res, why = self._posed(det, why, prior, up_C, r is not None)
                square = res is not None and _rms_share(res[0].rms_px, det.info) <= cfg.max_outline_rms_share
                if res is not None and det.kind == "outline" and (
                        (not square and foreseen(res[0], self.vfilter.position(t)))
                        or (square and det.info.get("unsquare_start"))):
                    # corners that are no square's, which the gates refuse: where the velocity filter
                    # foresaw the pad, placed by its design instead (the gates then judge that pose);
                    # and corners the start found no square's but the refined pose, which the gates
                    # judge, finds square: placed by their design, as any square outline's
                    fitted = self._design_fitted(det, rgb, up_C, rescue=True)
                    if "design_disagrees" in fitted.info:
                        res, why = None, _design_disagrees(fitted)
                    elif fitted is not det and isinstance(fitted.info.get("design_fit"), dict):  # placed by the design
                        res, why = self._posed(fitted, why, prior, up_C, r is not None)
                if res is not None:
                    return res, why
        return None, why

    def _smear_of(self, motion, up_C):
        """:meth:`hvloc.texture.PadTexture.locate`'s ``smear``: for the texture's matches, their pose
        (with the IMU's gravity) and ``motion`` (the frame's: :meth:`_motion`) where it smears the
        pad :data:`TRACK_SMEAR_MIN_PX` or more (:meth:`_smear_plan`); ``None`` (the drawing left
        sharp) with no exposure or no motion known.  Under unseen85's 23-28 px
        the sharp drawing's corners were 0.3-2.5 mm off at 0.18-0.3 m, the smeared one's 0.03-0.2."""
        if not self.exposure_s > 0 or (motion.v_P is None and motion.w_C is None):
            return None

        def smear(pts_P, px):
            start = solve_planar_pose(self.camera, pts_P, px, up_C=up_C, gravity_sigma_deg=self.up_sigma_deg,
                                      relief_m=self.config.pad_relief_m)
            return None if start is None else self._smear_plan(start.cam2pad, motion, pts_P)

        return smear

    def _smear_plan(self, cam2pad, motion, pts_P=None):
        """``(cam2pad, motion, exposure_s, reach_px)`` where ``motion`` smears the pad seen from
        ``cam2pad`` :data:`TRACK_SMEAR_MIN_PX` or more in the median over its part in view (a grid of
        the frame's pixels on it, not where matches ``pts_P`` happen to lie: a turn smears the edges
        more than the centre), the reach twice RANSAC's threshold and half the longest smear (of
        ``pts_P``, else of the view); ``None`` otherwise or with no exposure or motion known."""
        from .texture import RANSAC_PX

        if not self.exposure_s > 0 or (motion.v_P is None and motion.w_C is None):
            return None
        seen = self._view_on_pad(cam2pad)
        if seen is None and pts_P is None:
            return None
        d = self._image_motion(cam2pad, motion, pts_P if seen is None else seen)
        if d is None or not np.nanmedian(np.linalg.norm(d, axis=1)) >= TRACK_SMEAR_MIN_PX:
            return None
        if pts_P is not None:
            d = self._image_motion(cam2pad, motion, pts_P)
        return cam2pad, motion, self.exposure_s, 2.0 * RANSAC_PX + 0.5 * float(np.nanmax(np.linalg.norm(d, axis=1)))

    def _view_on_pad(self, cam2pad: np.ndarray):
        """``(N, 3)`` the pad's points a 9x9 grid over the frame sees from ``cam2pad`` (on the pad,
        in front of the camera), or ``None`` where fewer than 4 are."""
        cam = self.camera
        u, v = np.meshgrid(np.linspace(0, cam.width - 1, 9), np.linspace(0, cam.height - 1, 9))
        px = np.column_stack([u.ravel(), v.ravel()])
        und = cam.undistort_pixels(px) if cam.has_distortion else px
        P = cv2.perspectiveTransform(und.reshape(-1, 1, 2), np.linalg.inv(pad_plane_homography(cam, cam2pad))).reshape(-1, 2)
        P = np.column_stack([P, np.zeros(len(P))])
        ok = np.isfinite(P).all(axis=1)
        ok[ok] = (transform_points(invert(cam2pad), P[ok])[:, 2] > 0.0) & (np.abs(P[ok, :2]).max(axis=1) <= self.pad.side_m / 2)
        return P[ok] if ok.sum() >= 4 else None

    def _untracked_deck(self) -> bool:
        """Whether the pad lies on a tilting deck whose tilt is not tracked this frame (and the frame is
        a global shutter's or one the design's drawing draws row by row, :meth:`_shutter_drawn`)."""
        return self.deck is not None and not self.deck_tracked and (not self.shutter.active or self._shutter_drawn())

    def _far_tilt_doubt(self, normal_C: np.ndarray, sigma_deg: float) -> tuple:
        """``(sigma deg, scatter deg | None)``: the doubt of a far pad's tilt fitted by its design on an
        untracked deck (``normal_C``, the pad's normal in the camera; its fit's ``sigma_deg``), at least
        how far the run of such fits up to this frame scatter (:data:`FAR_TILT_STEPS`: the RMS of their
        steps over sqrt 2, the pad's normal turned into the world by the AHRS); the deck's swing
        (:attr:`up_sigma_deg`) until that run is long enough."""
        t, R = self.frame_t, self.attitude
        if R is None or t is None or not math.isfinite(t):
            return max(sigma_deg, self.up_sigma_deg), None
        n = R @ self.T_B_C[:3, :3] @ np.asarray(normal_C, np.float64)
        run = [(t, n / np.linalg.norm(n))]
        for tt, nn in reversed([f for f in self.far_tilts if f[0] < t]):  # (an earlier fit of this frame is replaced)
            if run[-1][0] - tt > FAR_TILT_GAP_S or len(run) > FAR_TILT_KEEP:
                break
            run.append((tt, nn))
        self.far_tilts = run[::-1]
        steps = [math.acos(min(1.0, float(a[1] @ b[1]))) for a, b in zip(run, run[1:])]
        if len(steps) < FAR_TILT_STEPS:
            return max(sigma_deg, self.up_sigma_deg), None
        scatter = math.degrees(math.sqrt(float(np.mean(np.square(steps))) / 2.0))
        return max(sigma_deg, scatter), scatter

    def _design_fit(self, cam2pad: np.ndarray, rgb: np.ndarray, up_C, key: tuple) -> tuple:
        """``(cam2pad | None, info)``: :func:`hvloc.texfit.fit_pose_to_design` from the pose ``cam2pad``
        (its tilt the IMU's ``up_C``), asked of the image work by ``key`` (what made ``cam2pad``) and
        all else it depends on; pads up to :data:`hvloc.texfit.GLOBAL_MAX_SIDE_PX` under a global
        shutter (:data:`hvloc.texfit.MAX_SIDE_PX` under a rolling one), or
        :data:`hvloc.texfit.HALVED_MAX_SIDE_PX` where the frame's chroma is at half resolution (its
        colour edges smear) or the pad lies on a deck whose tilt is not tracked (only its design fixes it).  The pad's tilt is fitted too, weighed against the IMU's
        (:attr:`up_sigma_deg`), where the pad is large and sharp enough
        (:data:`hvloc.texfit.TILT_MIN_SIDE_PX`) and the frame's motion, where known, smears its outer
        corners at most :data:`TILT_MAX_SMEAR_PX` over the exposure; nothing is fitted where it smears
        one over :data:`DESIGN_FIT_MAX_SMEAR_SHARE` of the pad's side (``(None, {"why": ...})``), the
        motion known with a velocity from the last poses."""
        from .texfit import GLOBAL_MAX_SIDE_PX, HALVED_MAX_SIDE_PX, MAX_SIDE_PX, TILT_MIN_SIDE_PX, fit_pose_to_design

        halved = self.work(lambda: ("chroma_halved",), ph.chroma_halved, rgb)
        # ... and on a deck whose tilt is not tracked, where only the design fixes it: a 66-130 px pad's
        # corners on a deck tilting 6 degrees, a sharp colour frame, were posed 0.2-1.8 % of the height
        # off or refused as loose (3 of 10); its design fitted with the tilt, 0.04-0.3 % and none refused.
        # Under a rolling shutter only where the camera's turn is known (the gyro), each row drawn at its
        # own time (hvloc.texfit's ``shutter``; why, and why only to MAX_SIDE_PX elsewhere: its
        # GLOBAL_MAX_SIDE_PX)
        rolled = self._shutter_drawn()
        untracked = self._untracked_deck()
        top = HALVED_MAX_SIDE_PX if halved or untracked else MAX_SIDE_PX if self.shutter.active else GLOBAL_MAX_SIDE_PX
        # ... and there its tilt is fitted from UNTRACKED_TILT_MIN_SIDE_PX, not only where the image tells it
        # better than an AHRS does: what else fixes it is the deck's whole swing, and the fit's doubt (with
        # the drawing's own error, hvloc.texfit.DESIGN_MODEL_PX, and the scatter of the fits before it,
        # _far_tilt_doubt) says whether it is fixed well enough
        least = UNTRACKED_TILT_MIN_SIDE_PX if untracked else TILT_MIN_SIDE_PX

        # how far the motion surely moves a corner of the pad over the exposure (px): the gyro's rate less
        # its doubt (_sure_rate_C: fz313's vibrating gyro read whole predicted 1.0-1.7 px of smear where
        # the pad moved 0.3-0.4 px, and a deck's tilt went unfitted; fzu12's 0.3-0.4 rad/s on 0.25 of
        # doubt left 14 of 144 frames unfitted and their outlines refused, 73 -> 87 posed)
        motion = self._drawn_motion()
        d = self._image_motion(cam2pad, motion, self.outer_P)
        smear = 0.0 if d is None else float(np.nanmax(np.linalg.norm(d, axis=1), initial=0.0))
        # (only with a velocity from the last poses, as _edge_fit_outrun: a descent's first frame has one gyro
        # row, which read 1.19 rad/s on nested_deck_pitched where the frame was smeared 2.8 px)
        if motion.v_P is not None and smear > TILT_MAX_SMEAR_PX:
            quad = self.camera.project_from(cam2pad, self.outer_P)
            side = ph._mean_side(quad) if quad is not None else math.inf
            if smear > DESIGN_FIT_MAX_SMEAR_SHARE * side:
                return None, {"why": f"the frame's motion smears the pad {smear:.1f} px over the exposure, past what its "
                                     f"drawing's blur stands in for ({DESIGN_FIT_MAX_SMEAR_SHARE:g} of its {side:.0f} px side)"}
        tilt = not smear > TILT_MAX_SMEAR_PX
        shutter = (self.shutter.line_s, self.shutter.ref_row, self.twist) if rolled else None
        twist_key = None if shutter is None else (array_key(self.twist.v_P), array_key(self.twist.w_C))
        return self.work(lambda: key + (array_key(up_C), self.up_sigma_deg, self.response, top, tilt, least, twist_key),
                         fit_pose_to_design, rgb, self.camera, self._drawing(), cam2pad, self.response, top,
                         up_C if tilt else None, self.up_sigma_deg, least, shutter)

    def _shutter_drawn(self) -> bool:
        """Whether the design fit draws a rolling shutter's frame row by row, each row at its own time:
        its line time and the camera's turn rate known (the gyro's; its velocity, where known, too)."""
        return self.shutter.active and self.twist is not None and self.twist.w_C is not None

    def _fitted_px(self, fitted: np.ndarray, pts_P: np.ndarray, info: dict):
        """``pts_P``'s pixels under the design fit's pose ``fitted``: where the fit drew a rolling
        shutter's rows at their own times (``info["rolled"]``), where each row saw them, as any found
        corner is (the pose is unrolled from them later, with the same motion)."""
        px = self.camera.project_from(fitted, pts_P)
        if px is None or not info.get("rolled") or not np.isfinite(px).all():
            return px
        d = self.shutter.shift(self.camera, fitted, pts_P, px, self.twist)
        return np.where(np.isfinite(d), px + d, px)

    def _design_fitted(self, det, rgb: np.ndarray, up_C, rescue: bool = False):
        """``det`` (an outline) with its corners those of the pose fitted to the pad's printed design
        (:func:`hvloc.texfit.fit_pose_to_design`), started from the outline's pose with the IMU's
        gravity; ``det`` as it is without gravity, without the design, or when the fit fails, and
        with ``info["design_disagrees"]`` (px) where the fit moved a corner over
        :data:`DESIGN_FIT_MAX_MOVE` of the side (the caller refuses it: neither measure is sure).
        ``rescue``: corners that are no square's are fitted too (``info["rescued"]``), with
        :attr:`LocalizerConfig.design_fit` on or off (the caller asks only where the pad was foreseen)."""
        if up_C is None or self.pad is None:
            return det
        if det.info.get("washed"):
            # its band washed out by light the drawing does not hold (a glossy pad's highlight): fitted
            # anyway, fz216's 50-65 px pads were placed 2.6-2.9 % of the height off, NEES 28-53; by
            # their corners, where the field and the colour agree, 0.7 % and within their sigma
            return replace(det, info=dict(det.info, design_fit="its band washed out: not the design's drawing"))
        hull = bool(det.info.get("hull_only"))  # a hull's corners (a cut pad's hidden one a guess), started from with their doubt
        scale = np.asarray(det.info.get("px_sigma_scale", np.ones(len(det.px))), np.float64) if hull else None
        start = solve_planar_pose(self.camera, det.pts_P, det.px, up_C=up_C, gravity_sigma_deg=self.up_sigma_deg,
                                  relief_m=self.config.pad_relief_m, **({"sigma_px": HULL_CORNER_PX * scale} if hull else {}))
        if start is None:
            return det
        rescue = rescue or hull
        # corners that are no square's are left to the gates, which refuse them: a drawing fitted from
        # there would hide what the corners showed (unless the pad was foreseen there: ``rescue``).  The
        # gates judge the squareness on the refined pose, not on this start: flagged, so the caller asks
        # for the fit where that pose is square (on unseen47 a 26 px pad's field corners, 13 % too large,
        # were no square's here by a hair, 2.002 % of the side, and square there, 1.996 %: taken
        # unchecked, 12 % of the height off)
        square = _rms_share(start.rms_px, det.info) <= self.config.max_outline_rms_share
        if not (square or rescue):
            return replace(det, info=dict(det.info, unsquare_start=True))
        fitted, info = self._design_fit(start.cam2pad, rgb, up_C, ("design fit", array_key(det.pts_P), array_key(det.px)))
        if fitted is None:
            return replace(det, info=dict(det.info, design_fit=info.get("why", "failed")))
        px = self._fitted_px(fitted, det.pts_P, info)
        if px is None or not np.isfinite(px).all():
            return det
        seen = np.ones(len(px), bool) if not hull else scale <= 1.0  # (a hull's hidden corner is no measure)
        moved = float(np.abs(px - det.px)[seen].max())
        if moved > DESIGN_FIT_MAX_MOVE * det.info["side_px"]:  # two measures of one pad this far apart: neither is sure
            return replace(det, info=dict(det.info, design_fit=f"moved the corners {moved:.1f} px", design_disagrees=moved))
        from .texfit import TILT_MIN_SIDE_PX

        up = _fitted_up(fitted, info)
        believed = bool(up)
        if up and info["side_px"] < TILT_MIN_SIDE_PX:  # fitted there only on an untracked deck (_design_fit)
            sigma, scatter = self._far_tilt_doubt(up["fitted_up_C"], up["fitted_up_sigma_deg"])
            up = dict(up, fitted_up_sigma_deg=sigma, far_tilt_scatter_deg=scatter)
            believed = scatter is not None
        # a fit that held the start's tilt (the pad too small for the design to fix it) gives corners
        # that carry that tilt, the found corners' with their error, however well it placed the rest:
        # they are as noisy as the found corners showed themselves against the design (px_sigma_held).
        # So do a far fit's before its tilt is believed (_far_tilt_doubt): stated at the corners' 0.3 px,
        # they carried the tilt the prior no longer did (a 35 px pad seen 30 degrees obliquely, its first
        # frame: sideways sigma 2.7 % of the height, from the fitted tilt alone)
        held = {} if believed else {
            "px_sigma_held": round(float(np.sqrt(np.mean(np.sum((px - det.px) ** 2, axis=1)))), 3)}
        image = {}
        if believed and self.deck is not None:
            # a believed fit's tilt is the image's, once the IMU's up it was weighed against is taken out: a
            # deck's track takes it where it is sure (_accepted)
            image = _image_only_up(up["fitted_up_C"], up["fitted_up_sigma_deg"], up_C, self.up_sigma_deg)
            if image.get("design_tilt_sigma_deg", math.inf) >= SURE_TILT_DEG:
                image = {}
        return replace(det, px=px, info=dict(det.info, design_fit=info, **up, **held, **image,
                                             **({} if square else {"rescued": "design fit"})))

    def _read_where_fitted(self, det, gray: np.ndarray, why: str) -> tuple:
        """``(det | None, reason)``: a grey outline read as the pad's design only at the lower bar
        (:data:`hvloc.phases.GREY_NEAR_ASYM_NCC`) is taken where its design fit placed it and the image
        there reads as the design at the full bars (:func:`hvloc.phases._design_read`), or reads faintly
        and the fitted drawing correlates :data:`FAINT_READ_FIT_NCC` with the frame; refused where its
        design was not fitted or does not read so."""
        fit = det.info.get("design_fit")
        if not isinstance(fit, dict):
            return None, f"a grey frame's pad read faintly as its design, and its design not fitted ({fit or 'off'})"
        outer = ph._through_quad(det.px, self.geometry, self.camera, self.outer_P[:, :2], square=det.pts_P)
        level = 0 if outer is None or not np.isfinite(outer).all() else \
            ph._design_read(gray, outer, self.geometry, self.camera, self._design())[0]
        if level == ph.READS or (level == ph.READS_FAINTLY and fit.get("ncc", 0.0) >= FAINT_READ_FIT_NCC):
            return det, why
        return None, ("a grey frame's pad read faintly as its design, and not as it where its design fit puts it "
                      f"(its drawing correlating {fit.get('ncc', 0.0):.2f} there)")

    def _small_field_refused(self, det, why: str) -> tuple:
        """``(None, reason)`` for an outline placed by its white field's corners alone (its design not
        fitted) that puts the pad under :data:`FIELD_MIN_SIDE_PX`; ``(det, why)`` otherwise.  Summed in
        light, a 15-20 px pad's field comes out 7-9 % of its side too large (the border's checker
        averages to a bright grey beside it): on far_wide's spec such poses were 10-12 % of the height
        near, false accepts.  The design fit places those pads from 16 px (:data:`hvloc.texfit.MIN_SIDE_PX`);
        where it cannot (no gravity, a poor match, or under 16 px) the field's corners do not either."""
        if det.info.get("corners") != "field" or isinstance(det.info.get("design_fit"), dict):
            return det, why
        side = ph._mean_side(det.px) * self.geometry.side_m / self.geometry.field_side_m
        if side >= FIELD_MIN_SIDE_PX:
            return det, why
        return None, (f"its colour swelled past its white field, and a pad of {side:.0f} px (< {FIELD_MIN_SIDE_PX:g}) "
                      f"is not placed by the field's corners (its design not fitted: {det.info.get('design_fit', 'off')})")

    def _posed(self, det, why: str, prior, up_C, roi: bool):
        """``((pose, n, extras) | None, reason)``: the pose of a detection's correspondences."""
        if det is None:
            return None, why
        cfg = self.config
        sigma = corner_sigma_px(det.info)
        up_sigma, up_tolerance = self.up_sigma_deg, self.up_tolerance_deg
        if up_C is not None and "fitted_up_C" in det.info:  # the pad's tilt its design fit found (_fitted_up)
            up_C, up_sigma, up_tolerance = det.info["fitted_up_C"], det.info["fitted_up_sigma_deg"], 0.0

        def markers_seen(P):  # each point's marker (-1: none), and the markers with 4 points at least
            g = self._marker_of(P) if det.kind == "markers" else np.full(len(P), -1)
            return g, [m for m in np.unique(g) if m >= 0 and np.sum(g == m) >= 4]

        # the gravity prior (the AHRS's 0.5 degrees) is weighed against the noise the markers show,
        # not the 0.3 px floor every found corner gets: three markers' corners fit to ~0.1 px on a
        # clean image, whose tilt then counts (the AHRS's few tenths of a degree went into the
        # position almost whole), and to 0.2-0.3 px under JPEG and a wide lens, where the prior
        # should count more.  Three times the image-only fit's residual: JPEG's and the lens's
        # errors are correlated within a marker, and the residual shows only part of them
        # ORB's keypoints (a texture pose its drawing did not refine) are each placed on a pyramid's grid
        # and anywhere along a smear: their noise is what their fit shows, each its own (unseen85's at
        # 0.2 m under 28 px of smear: 26 keypoints fitting at 2.2 px, the pose 3.9 mm off in scale and
        # stated at the corners' 0.3 px, NEES 27)
        keypoints = det.kind == "texture" and "refined" not in det.info and det.info.get("by") != "synthesis"

        def weighable(P):
            return up_C is not None and np.ndim(sigma) == 0 and (keypoints or len(markers_seen(P)[1]) >= 3)

        # a pose from fewer than three markers is not weighed by its residual (too few to show the
        # noise); its markers' corners share errors besides their own (SharedNoise): MARKER_SHARED_PER_SIGMA
        # per unit of their noise, or, in a frame where a marker was left out for being off, as much
        # as that marker was off (the blur, the lens or the threshold that moved it reached the others).
        # A weighed one's share them too, MARKER_SHARED_PER_SIGMA of the noise its fit shows, in what
        # it states (not in its solve, whose weighing against the gravity prior stays as measured):
        # placed in light, unseen100's corners (a soft lens, JPEG 70, 1-10 px of smear) fit to
        # 0.08-0.15 px and lay 0.06-0.5 px radially inward of the labels, together; stated by their
        # scatter alone, its Adjustment poses were 2.4 times their sigma off (48 % beyond 3 sigma)
        shared_off = 0.0

        def outer_of(P):  # which points are the pad's outer corners
            return (np.abs(P[:, None, :] - self.geometry.outer_corners[None]).max(axis=2) < 1e-9).any(axis=1)

        def shared_for(P, s, weigh):  # (the outer corners, fitted on the border's colour, share theirs too)
            if det.kind != "markers":
                return None
            groups = np.where(outer_of(P), len(self.geometry.markers), markers_seen(P)[0])
            if weigh:  # stated, in units of the noise the fit shows (solve_planar_pose's stated_shared)
                return SharedNoise(groups, MARKER_SHARED_PER_SIGMA, MARKER_SHARED_PER_SIGMA)
            v = max(MARKER_SHARED_PER_SIGMA * float(np.mean(s)), shared_off / math.sqrt(3.0))
            return SharedNoise(groups, v, v)

        def pose_of(P, px, s, weigh=False, share=True):
            w = None if not weigh else (KEYPOINT_SIGMA_PER_RMS, PIXEL_SIGMA) if keypoints else (
                MARKER_SIGMA_PER_RMS, MARKER_MIN_SIGMA_PX)
            sh = shared_for(P, s, weigh) if share else None
            # without an IMU a drone flying level has its body's up, seen through the mount, as the
            # world's: it may choose between a far pad's pose and its mirror (hvloc.pose)
            level = self.T_B_C[:3, :3].T @ np.array([0.0, 0.0, 1.0]) if up_C is None else None
            return self.work(lambda: ("pose", array_key(P), array_key(px), array_key(up_C),
                                      array_key(prior) if up_C is None else None,
                                      array_key(level), array_key(s), w,
                                      None if sh is None else (sh.shift, sh.dilation), up_sigma, up_tolerance,
                                      self.config.pad_relief_m),
                             solve_planar_pose, self.camera, P, px, up_C=up_C, prev_cam2pad=prior, sigma_px=s,
                             sigma_from_fit=w, shared=None if weigh else sh, level_up_C=level,
                             gravity_sigma_deg=up_sigma, up_tolerance_deg=up_tolerance,
                             stated_shared=sh if weigh else None, relief_m=self.config.pad_relief_m)

        def refit(keep, weigh=True, share=True):  # the pose of the correspondences ``keep`` alone, with what they are
            s = sigma if np.ndim(sigma) == 0 else np.asarray(sigma)[keep]
            w = weigh and weighable(P[keep])
            p = pose_of(P[keep], px[keep], s, w, share)
            return None if p is None else (p, P[keep], px[keep], s, w)

        P, px = det.pts_P, det.px
        weighed = weighable(P)
        pose = pose_of(P, px, sigma, weighed)
        if pose is None:
            return None, "pose failed"
        # each row seen at its own time: all at the reference row's.  Not the smeared drawing's points
        # (hvloc.synthesis): it draws every band of rows at its own time and gives each point where
        # the reference row's projection lands, so they are unrolled already (unrolled again, a
        # spiral's turn at 0.35 m under 50-260 px of smear fitted at 3-5 px and was refused)
        twist = self.twist  # the frame's: its velocity may be the image's (kept only if this pose is returned)
        if self.shutter.active and self.twist is not None and det.info.get("by") != "synthesis":
            px = self._unrolled(px, pose.cam2pad, P)
            pose = pose_of(P, px, sigma, weighed)
            if pose is None:
                return None, "pose failed"
            # many points skewed row by row by a velocity the filter has wrong (a drone that stopped at
            # touchdown while the filter still carried its approach): the velocity they ask for
            found = self._velocity_from_image(pose, P, px, lambda seen: pose_of(P, seen, sigma, weighed)) \
                if len(P) >= VELOCITY_FROM_IMAGE_MIN_POINTS else None
            if found is not None:
                pose, px, twist, vcov = found
        refusal = _mirror_refusal(pose, up_tolerance if up_C is not None else 0.0) \
            or self._edge_fit_outrun(pose, P, det.info.get("edge_fit_smear_px"))
        if refusal:
            return None, refusal
        info = {k: v for k, v in det.info.items() if k not in ("fitted_up_C", "fitted_up_sigma_deg")}
        # a whole marker off (its contour pulled by something across it: 6-9 px on two corners of each
        # of its squares) is no scatter of points; with two others seen, its residuals stand out
        # (the joint fit leans toward it, so each suspect is judged by the fit of the others)
        groups, seen = markers_seen(P)
        r = point_residuals(self.camera, pose.cam2pad, P, px) if len(seen) >= 3 else None
        if r is not None and max(float(np.sqrt(np.mean(r[groups == g] ** 2))) for g in seen) > 1.0:
            best = None
            for g in seen:
                others = refit(np.nonzero(groups != g)[0], share=False)  # judged by the image's fit
                if others is None:
                    continue
                r = point_residuals(self.camera, others[0].cam2pad, P, px)
                off = float(np.sqrt(np.mean(r[groups == g] ** 2)))
                fits = float(np.sqrt(np.mean(r[groups != g] ** 2)))
                if off > max(1.5, 5.0 * fits) and (best is None or off / fits > best[0]):
                    best = (off / fits, g, others, off)
            if best is not None:
                found = {g: int(np.sum(groups == g)) for g in seen}  # how many of its corners each marker gave
                pose, P, px, sigma, weighed = best[2]
                info["marker_dropped"] = self.geometry.markers[best[1]].name
                # the errors the others share are what moved it only where it was found as they were
                # (as many of its squares): a marker found in part was off for its own finding (a
                # square taken from something else), which did not reach them.  Lent to them anyway,
                # a nested centre set's marker found by its outer square alone, 4 px off, made 2.3 px
                # of shift and swell the others share: their pose, whose 20 corners fit to 0.3 px,
                # came out 20 % high at 0.9 m, "ok" (`hvloc bench fuzz` seed 104: a barrel lens, JPEG 60, 10 Hz)
                if found[best[1]] >= max(found[g] for g in seen if g != best[1]):
                    shared_off = best[3]
                if not weighed:  # the others' pose again, with the errors that marker shows them to share
                    pose = pose_of(P, px, sigma, False) or pose
        # the pad's outer corners, fitted on the border's colour, double the markers' baseline; but
        # where chroma is kept at half resolution (JPEG, H.264) the border's colour edge smears and
        # they come out ~0.5 px outward (the markers, on luma, stay at ~0.1 px), and the joint fit
        # tilts toward them: judged by the markers' own fit, they go when they disagree with it
        outer = outer_of(P)
        if up_C is not None and outer.any() and len(markers_seen(P)[1]) >= 3:
            alone = refit(np.nonzero(~outer)[0], weigh=False, share=False)  # judged at the corners' floor noise
            if alone is not None:
                r = point_residuals(self.camera, alone[0].cam2pad, P[outer], px[outer])
                off = float(np.sqrt(np.mean(r**2)))
                # only where the markers alone pin the pose: with the IMU's gravity, and where their
                # pose's own uncertainty puts the outer corners well inside the disagreement
                sure = float(np.sqrt(np.mean(projection_sigma_px(self.camera, alone[0].cam2pad, alone[0].cov,
                                                                 P[outer]) ** 2)))
                if off > max(OUTER_AGREE_PX, 3.0 * sure):
                    pose, P, px, sigma, weighed = alone
                    info["outer_dropped_px"] = round(off, 3)
        n0 = len(P)
        # many points: a few mislocated ones (marker corners pulled 10 px, an outline corner
        # extrapolated off the image) show against the rest; the fit they pulled hides some of them,
        # so again on the rest, while at most a quarter of all are dropped
        for _ in range(3):
            if n0 < 12:
                break
            bad = outlying_points(self.camera, pose.cam2pad, P, px, max_share=0.25 * n0 / len(P))
            if bad is None:
                break
            better = refit(np.setdiff1d(np.arange(len(P)), bad))
            if better is None:
                break
            pose, P, px, sigma, weighed = better
            info["outliers_dropped"] = n0 - len(P)
        if not weighed and weighable(P):  # the outer corners dropped: the markers' pose weighed in turn
            again = pose_of(P, px, sigma, True)
            if again is not None:
                pose, weighed = again, True
        if weighed and np.ndim(pose.sigma_px) == 0:
            info["px_sigma"] = round(float(pose.sigma_px), 3)
        textured = det.kind == "texture" and info.get("by") != "synthesis"  # its points tracked from a sharp drawing
        # doubts the fit cannot show: every pose from the pad is seen from its surface, not the plane it
        # lies on (the tracker's poses inherit this from their keyframe); a texture pose's place on the
        # pad is known to a fraction of a texel (per axis, m)
        doubt = np.array([self.config.pad_relief_m / 2.0] * 3)
        if textured:
            doubt[:2] = np.hypot(doubt[:2], TEXTURE_TEXEL_DOUBT / self.pad.ppm)
        if pose.cov is not None and doubt.any():  # (a copy: the pose may be shared image work)
            cov = pose.cov.copy()
            cov[:3, :3] += np.diag(doubt ** 2)
            pose = replace(pose, cov=cov)
        if textured:
            pose = self._smear_spread(pose, P, px, lambda seen: pose_of(P, seen, sigma, weighed),
                                      doubt=TRACK_SMEAR_DOUBT if "refined" in info else KEYPOINT_SMEAR_DOUBT)
        if twist is not self.twist:
            info["velocity_from_image"], info["velocity_from_image_cov"] = twist.v_P.copy(), vcov
        self.twist = twist
        pose = self._velocity_free(pose, P, px, lambda seen: pose_of(P, seen, sigma, weighed), info)
        spread = float(np.sqrt(np.mean(np.sum((P[:, :2] - P[:, :2].mean(axis=0)) ** 2, axis=1)) / 2.0))
        return (pose, len(P), dict(info, roi=roi, spread_m=spread, tilt_err_deg=pose.tilt_err_deg,
                                   tilt_sigma_deg=pose.tilt_sigma_deg, normal_img_C=pose.normal_img_C,
                                   mirror_normal_img_C=pose.mirror_normal_img_C,
                                   mirror_chi2_gap=pose.mirror_chi2_gap)), "ok"

    def _marker_of(self, pts_P: np.ndarray) -> np.ndarray:
        """``(N,)`` index in the pad's markers of the marker each pad point lies on, -1 for none."""
        out = np.full(len(pts_P), -1)
        for i, m in enumerate(self.geometry.markers):
            inside = np.all(np.abs(pts_P[:, :2] - m.center[:2]) <= m.size_m / 2 + 1e-9, axis=1)
            out[inside & (out < 0)] = i
        return out

    def _texture_allowed(self, h: float | None, orb: bool = False) -> bool:
        """The texture is tried near the ground: by ORB (``orb``) below the height where ORB's
        pyramids on the image and on the texture still meet, and drawn at the predicted pose
        (:meth:`_synthesized`) wherever a recent pose predicts one.  With no recent height: every
        frame past Approaching (a chain broken near the ground), and in Approaching (a start or a
        reset near the ground, where neither outline nor markers fit in the image) on the first
        frame without a pose and every ``TEXTURE_COLD_EVERY``-th after, so that high up, where it
        finds nothing, it costs a fraction of its ~50 ms."""
        if self._texture is None:
            from .texture import PadTexture

            self._texture = PadTexture(self.pad)
        if not self._texture.usable:
            return False
        if h is not None:
            return h <= self._texture.max_height_m(self.camera) or (not orb and self._drawn_position(self.last_t) is not None)
        return self.phase != "approaching" or self.unposed % TEXTURE_COLD_EVERY == 1

    def _drawn_position(self, t: float | None):
        """``(position, velocity)`` the pad is drawn at and smeared by (:meth:`_synthesized`), or
        ``None``: within :data:`SYNTHESIS_MAX_AGE_S` of the last pose, where the velocity filter
        predicts it (the poses carried by the IMU's rows), else moved on at the last two poses'
        velocity; and up to :data:`SYNTHESIS_COAST_S` where the filter's position is carried by the
        rows alone and its doubt (1 sigma) is within the alignment's reach
        (:meth:`hvloc.synthesis.PadSynthesis.reach_m`).

        A gust that swings the pad out of the frame near the ground breaks the flow's chain, and
        when the pad comes back, smeared, only the drawing places it: gusty_blur lost 8 frames in a
        row at 0.67-0.41 m, 0.1-0.8 s after the last pose (the last 5, the pad back in view, are
        drawn and posed now)."""
        if self.last is None or t is None or self.pad is None or not 0.0 < t - self.last.t <= SYNTHESIS_COAST_S:
            return None
        pred = self.vfilter.position(t)
        if pred is not None:
            p, P, v = pred
            if t - self.last.t <= SYNTHESIS_MAX_AGE_S or (
                    math.sqrt(max(np.linalg.eigvalsh(P)[-1], 0.0)) <= self._drawing().reach_m(self.camera, p[2])):
                return p, v
        if t - self.last.t > SYNTHESIS_MAX_AGE_S:
            return None
        p = self.last.cam2pad[:3, 3].copy()
        if self.velocity is not None:
            p += self.velocity * (t - self.last.t)
        return p, self.velocity

    def _drawing(self):
        """The pad's drawing (:class:`hvloc.synthesis.PadSynthesis`), made when first needed."""
        if self._synthesis is None:
            from .synthesis import PadSynthesis

            self._synthesis = PadSynthesis(self.pad)
        return self._synthesis

    def _predicted_pose(self, t: float, R_W_B):
        """``((T_P_C, velocity) | None, reason)``: the last pose moved on (:meth:`_drawn_position`)
        and turned as the AHRS has turned since (the pad's orientation in the world as expected
        now); ``None`` without a recent pose or without an attitude."""
        drawn = self._drawn_position(t)
        if drawn is None:
            return None, "no recent pose to draw the pad at"
        if R_W_B is None:
            return None, "no attitude to draw the pad at"
        T = self.last.cam2pad.copy()
        T[:3, 3], velocity = drawn
        if self.gates.R_W_P is not None:  # the pad's orientation in the world, as expected now
            T[:3, :3] = self.gates.pad_orientation(t).T @ R_W_B @ self.T_B_C[:3, :3]
        return (T, velocity), ""

    def _design_posed(self, rgb, t: float, T: np.ndarray, why: str, prior, up_C):
        """``((pose, n, extras) | None, reason)``: a pad predicted too small for its smeared drawing to
        be aligned (:data:`hvloc.synthesis.MIN_PAD_PX`), yet large enough for its printed design to
        be fitted (:data:`hvloc.texfit.MIN_SIDE_PX`), posed by that design fitted from the predicted
        pose ``T`` (:meth:`_predicted_pose`; its position and yaw, and its tilt where :meth:`_design_fit`
        fits it), where the pose lands where the velocity filter
        foresaw it (:func:`foreseen`).  Its outer corners stand in for the outline's, each as noisy
        as the blur the fit found (:data:`DESIGN_SIGMA_PER_BLUR`).  ``(None, why)`` otherwise.

        Where the outline of a 20-45 px pad is not found (its border band missing beside a corner
        under JPEG's chroma, its smear misread from the pad's own structure, its sides and hull at
        odds: the conditions suite's far, dusk and deck scenes) the frame was lost, though the
        filter knew where the pad was to 1-3 % of the height."""
        from .synthesis import MIN_PAD_PX
        from .texfit import MIN_SIDE_PX

        if self.pad is None:
            return None, why
        quad = self.camera.project_from(T, self.outer_P)
        if quad is None or not np.isfinite(quad).all() or not MIN_SIDE_PX <= ph._mean_side(quad) < MIN_PAD_PX:
            return None, why
        fitted, info = self._design_fit(T, rgb, up_C, ("design at the prediction", array_key(T)))
        px = None if fitted is None else self._fitted_px(fitted, self.outer_P, info)
        if px is None or not np.isfinite(px).all():
            return None, f"{why}; its design fitted from the predicted pose: {info.get('why', 'out of view')}"
        det = ph.Detection(self.outer_P, px, "outline", {
            "side_px": ph._mean_side(px),
            "by": "design at the predicted pose", "design_fit": info,
            "px_sigma_blur": DESIGN_SIGMA_PER_BLUR * float(info["blur_px"]), **_fitted_up(fitted, info)})
        res, why2 = self._posed(det, why, prior, up_C, False)
        if res is None:
            return None, why2
        if not foreseen(res[0], self.vfilter.position(t)):
            return None, f"{why}; its design fitted from the predicted pose: not where the pad was foreseen"
        return res, "ok"

    def _synthesized(self, gray, pred, why: str):
        """``(Detection | None, reason)``: the pad drawn where ``pred`` (:meth:`_predicted_pose`: the
        last pose, moved on and turned as the AHRS has turned since) puts it, smeared by that
        velocity and the gyro's rate over the exposure, and aligned to the frame
        (:mod:`hvloc.synthesis`); only with an attitude: without one the drawing's tilt is the last
        pose's, which alone (no gravity to choose between a pose and its mirror) can be degrees off
        (bench_v1's no_imu ablation: 1.4 m at 19.8 m, accepted)."""
        if pred is None:
            return None, why
        T, velocity = pred
        rate_C = self._sure_rate_C()  # (smeared by what the gyro surely says)
        sh = self.shutter
        det, why2 = self.work(lambda: ("synthesis", array_key(T), array_key(velocity), array_key(rate_C),
                                       self.exposure_s),
                              self._drawing().locate, gray, self.camera, T, velocity, rate_C, self.exposure_s,
                              sh.line_s if sh.active else 0.0, sh.ref_row)
        if det is None:
            return None, f"{why}; drawn at the predicted pose: {why2}" if why else f"drawn at the predicted pose: {why2}"
        return det, "ok"

    def _gate(self, est: Estimate, R_W_B) -> str:
        if self.deck_seen:  # (_pad_tilt_seen, earlier this frame)
            return "the image has just shown the pad tilting: no pose drawn to a level pad's up is taken this frame"
        return self.gates.check(est, R_W_B, self.last, self.attitude)

    def _after_accept(self, method: str, est: Estimate, gray) -> None:
        """Keep the flow tracker ready near the ground: a keyframe from an anchored (markers, outline,
        texture) pose, renewed when the view has changed enough; flow poses advance the tracks.

        A smeared drawing's pose (:mod:`hvloc.synthesis`) anchors one too, tried only after the
        drawing (``Keyframe.drawn``): its frame's corners are smeared, and tracks from it were 5-11 mm
        off at 0.5-0.8 m where the drawing was within a millimetre; but where the pad runs out of the
        frame no drawing places it, and without such a keyframe every frame down to 0.5 m was lost
        (unseen57: 15 frames of 78 in touchdown, the frames before posed by the drawing under 25-30
        px of smear).  The tracks' poses are doubted for the smear they differ by from it
        (:meth:`_smear_spread`, the keyframe's motion) and carry its covariance."""
        cfg = self.config
        h = est.height
        if not cfg.use_flow or (not cfg.anchor_once and h > cfg.touchdown_height_m * 1.5 + cfg.hysteresis_m):
            self.flow.reset()
            return
        f = self.flow
        serial = None if f.kf is None else f.kf.serial

        def anchor():  # a keyframe from this pose, with how far off its image saw the AHRS
            f.anchor(gray, est.cam2pad, anchored=True, cov=est.cov, ahrs_off_deg=ahrs_off_deg(est))

        if method == "flow":
            f.accept(est.cam2pad, est.rms_px, est.cov)
        elif est.extras.get("by") == "synthesis" or (f.kf is not None and f.kf.drawn):
            # a drawn frame's keyframe is kept the last frame (the flow is tried after the drawing), and
            # gives way to the first pose of another method: kept, the flow stayed behind the drawing
            # (unseen59: a slow descent drawn at 1.6-2.8 m, 45 frames drawn after a markers pose that
            # would have anchored a keyframe the flow tracked, 200+ ms a frame where the flow took 11)
            anchor()
        else:
            f.frames_since_kf += 1
            if (method == "texture" or f.kf is None or not f.kf.anchored or f.frames_since_kf > 10
                    or not (1 / 1.1 < f.kf.cam2pad[2, 3] / max(h, 1e-6) < 1.1)):
                if not f.reaches(est.cam2pad) or _surer(f.kf, est.cov):  # (out of its reach it is renewed anyway)
                    anchor()
        if f.kf is not None and f.kf.serial != serial:  # a keyframe from this frame: the motion it was exposed under
            f.kf.motion = self._motion()
            f.kf.drawn = est.extras.get("by") == "synthesis"


def _design_disagrees(det) -> str:
    """Why an outline whose design fit moved a corner past :data:`DESIGN_FIT_MAX_MOVE` of its side is refused."""
    return (f"its design, fitted from its corners, moved one {det.info['design_disagrees']:.1f} px "
            f"(> {DESIGN_FIT_MAX_MOVE:g} of its side): neither is sure")


def _design_note(det) -> str:
    """What the design fit of an outline said, for a reason: why it failed or did not fit the tilt."""
    fit = det.info.get("design_fit", "not fitted")
    if not isinstance(fit, dict):
        return str(fit)
    side = det.info.get("side_px")
    return f"a {side:.0f} px pad: its tilt held" if side else "its tilt held"


def ahrs_off_deg(est: "Estimate") -> float:
    """How far the IMU's gravity is off, at the least, by what ``est``'s image alone fixes of the pad's
    tilt: its disagreement less two of its sigmas (degrees; 0 where it says nothing, as a far pad's
    four corners or a pose made without an IMU).  Markers below a metre fix the tilt to a few
    hundredths of a degree; an AHRS stated 0.5 degrees was 0.7-1.2 off there (unseen48)."""
    err, sigma = est.extras.get("tilt_err_deg", float("nan")), est.extras.get("tilt_sigma_deg", float("nan"))
    off = float(err) - 2.0 * float(sigma)
    return off if math.isfinite(off) and off > 0.0 else 0.0


def _surer(kf, cov) -> bool:
    """Whether a pose of covariance ``cov`` would make a surer keyframe than ``kf`` (whose error the
    tracker's poses carry): its position's doubt no larger.  A keyframe with no covariance, or a
    pose with none, is no comparison (the pose is taken)."""
    if kf is None or kf.cov is None or cov is None:
        return True
    return float(np.trace(cov[:3, :3])) <= float(np.trace(kf.cov[:3, :3]))


class GatedLocalizer:
    """Any localizer behind the ``process(image, t, imu) -> Estimate`` protocol with hvloc's
    false-pose gates (:class:`FalsePoseGates`) in front: an ``ok`` pose they refuse becomes
    ``rejected`` with the reason.  So a benchmark can tell what a pad design is worth apart from
    what the gating is worth.  The gates see the IMU only when the caller passes it."""

    def __init__(self, inner, config: LocalizerConfig | None = None, T_B_C: np.ndarray | None = None):
        self.inner = inner
        self.config = config or LocalizerConfig()
        self.T_B_C = DEFAULT_T_B_C if T_B_C is None else np.asarray(T_B_C, np.float64)
        self.gates = FalsePoseGates(self.config, self.T_B_C)
        self.last: Estimate | None = None
        self.last_t: float | None = None

    def reset(self) -> None:
        if hasattr(self.inner, "reset"):
            self.inner.reset()
        self.gates.reset()
        self.last, self.last_t = None, None

    IMU_BLOCK = True  # its gates read the block's last row; the inner localizer gets what it takes (imu_for)

    def process(self, image, t: float, imu=None) -> Estimate:
        t0 = time.perf_counter()
        est = guarded_process(self.inner.process, image, t, imu_for(self.inner, imu), "")
        tf, bad_time = frame_time(est.t)
        if not bad_time:
            event, _ = clock_event(self.last_t, self.last, tf, self.config.prior_timeout_s)
            if event == "reset":
                self.gates.reset()
            if event:
                self.last = None
            self.last_t = tf
        if est.status == "ok":
            try:
                self._gate(est, imu)
            except Exception as err:  # never raise on an image
                est.status, est.reason = "lost", f"internal error in the gates: {type(err).__name__}: {err}"
        est.ms = (time.perf_counter() - t0) * 1000.0
        return est

    def _gate(self, est: Estimate, imu) -> None:
        if est.cam2pad is None or np.shape(est.cam2pad) != (4, 4) or not np.all(np.isfinite(est.cam2pad)):
            est.status, est.reason = "lost", "the localizer said ok without a finite pose"
            return
        verdict = self.gates.check(est, imu_check(imu)[0], self.last)
        if verdict:
            est.status, est.reason = "rejected", verdict
        else:
            self.last = est
