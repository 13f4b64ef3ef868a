"""Pose from 2D-3D correspondences on the pad plane (z = 0).

Normalised DLT homography -> decomposition into R, t with orthonormalisation (our own, used by
the tracker and as a check); IPPE (OpenCV's ``SOLVEPNP_IPPE``, both solutions) for the two
candidate poses of a planar target; with an IMU, both refined to the reprojection error's minima
(OpenCV's VVS) and the one whose pad lies nearer the gravity direction taken (the nadir "flip"
ambiguity), then a Levenberg-Marquardt step that adds the AHRS gravity direction as a prior on
the pad's tilt; without one, the choice by the previous pose or the fit, refined by OpenCV's
Levenberg-Marquardt; a 6x6 covariance from the reprojection Jacobian.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .geometry import Camera, invert, make_transform, rotation_angle, so3_exp


@dataclass
class PoseResult:
    cam2pad: np.ndarray        # T_P_C
    rms_px: float              # reprojection RMS in pixels
    n: int                     # correspondences used
    cov: np.ndarray            # 6x6 covariance of (position xyz in P [m], rotation vector [rad])
    other_rms_px: float        # RMS of the rejected flip solution (inf if none)
    flip_choice: str           # how the flip was resolved: gravity, previous, level, rms, ambiguous, single
    tilt_err_deg: float = float("nan")    # image-only pose's pad normal vs the IMU's up (nan: no IMU)
    tilt_sigma_deg: float = float("nan")  # that tilt's standard deviation, from the image-only fit
    normal_img_C: np.ndarray | None = None  # the image-only pose's pad normal in C (with an IMU)
    image_rms_px: float = float("nan")    # the image-only pose's reprojection RMS (with an IMU)
    sigma_px: object = None               # the pixel noise the refinement and covariance used (scalar or per point)
    other_cam2pad: np.ndarray | None = None  # the rejected flip solution (None if none)
    mirror_normal_img_C: np.ndarray | None = None  # that solution's image-only pad normal in C (with an IMU)
    mirror_chi2_gap: float = float("inf")  # how much worse it fits than the chosen one, in squared noise units
    tilt_noise_scale: float = 1.0          # how much the image's noise was widened for its tilt to meet gravity's
    relief_tilt_deg: float = 0.0           # on a wrinkled pad: how far the patch the points lie on may tilt (relief_tilt_rad)
    patch_tilt_deg: float = 0.0            # ... and how far it was found tilted


PIXEL_SIGMA = 0.3  # px: how well a found corner is known, at least (the fit's own residuals when larger)
FLIP_MARGIN_SIGMAS = 2.0  # with nothing but the fit to choose, a mirror pose within this many noise units ...
FLIP_APART = 0.05  # ... and further than this share of the height from the chosen one makes the pose ambiguous
LEVEL_TILT_DEG = 30.0  # without an IMU, a pad within this of the mount's level up may be taken as lying level ...
FLIP_LEVEL_GAP_DEG = 15.0  # ... when its mirror's pad lies this much further off
LEVEL_SIGMA_DEG = 10.0  # without an IMU, how far from level a drone's body is tilted (1 sigma), as a soft prior
# the squared disagreement, in its sigmas, an image's tilt may have with the IMU's gravity before the
# image's noise is taken to be larger than its residuals show (``solve_planar_pose``'s ``tilt_chi2``):
# two sigmas of the two together
TILT_CONSISTENT_CHI2 = 4.0

# A wrinkled pad (``LocalizerConfig.pad_relief_m``) stands 0 to its relief off its plane, and the
# plane through any of its points tilts with the wrinkles under them (:func:`relief_tilt_rad`).  Its
# height is taken for a random field: RELIEF_HEIGHT_SHARE of half the relief (one sigma), correlated
# as exp(-d^2 / 2 RELIEF_CORRELATION_M^2) between points d apart.  Against 120 reliefs drawn as the
# renderer draws them (render.relief.PadRelief: 3-20 mm, wrinkles 0.15-0.5 m long, a sag) the RMS
# tilt of the plane through a point set was 0.55-1.0 times what the field states (test:
# test_a_wrinkles_tilt_is_as_large_as_drawn_reliefs_give): a 10 cm marker's corners 0.72, two
# markers 0.83, three 0.89, the outer corners 0.73, texture points over 0.2 m 1.0 and over 0.7 m
# 0.55.  (A plainer rule, a share of half the relief over the points' spread, was off 9-fold
# between those: it cannot see that points spread over several wrinkles average them out, nor
# that two markers leave the tilt across them to their own width.)  Longer waves than these (a pad
# bent over a kerb) tilt wide point sets more than stated.
RELIEF_HEIGHT_SHARE = 0.5
RELIEF_CORRELATION_M = 0.04
MAX_RELIEF_TILT_DEG = 30.0  # (a few points close together: the image says nothing of the pad's tilt)
RELIEF_POINTS = 200  # at most so many of the points weighed (evenly taken): the field's matrix grows as their square


def relief_tilt_rad(pts_P: np.ndarray, relief_m: float) -> float:
    """How far (one sigma per axis, radians) the plane through pad points ``pts_P`` may be tilted
    from the pad's own by a relief of ``relief_m`` (the surface 0 to that off the plane): what the
    image of those points cannot tell from the pad's tilt.  The least-squares plane's slope under
    the height field of :data:`RELIEF_HEIGHT_SHARE` and :data:`RELIEF_CORRELATION_M`; 0 for a flat
    pad.  (A variant of `hvloc bench fuzz` seed 143's scene, a 17 mm relief over 0.3-0.47 m
    wrinkles: below 0.65 m the one nested marker seen lay on a patch 4 degrees off the pad's plane,
    and its poses, fitted to that patch, were 10 % of the height off, "ok".)"""
    if not relief_m > 0:
        return 0.0
    xy = np.asarray(pts_P, np.float64).reshape(-1, 3)[:, :2]
    xy = xy[:: max(1, -(-len(xy) // RELIEF_POINTS))]
    d = xy - xy.mean(axis=0)
    try:
        slope = np.linalg.pinv(np.column_stack([d, np.ones(len(d))]))[:2]  # (2, n): the plane's slope from the heights
    except np.linalg.LinAlgError:
        return math.radians(MAX_RELIEF_TILT_DEG)
    gap2 = np.sum((xy[:, None, :] - xy[None, :, :]) ** 2, axis=-1)
    heights = (RELIEF_HEIGHT_SHARE * relief_m / 2.0) ** 2 * np.exp(-gap2 / (2.0 * RELIEF_CORRELATION_M ** 2))
    var = float(np.trace(slope @ heights @ slope.T)) / 2.0
    return min(math.atan(math.sqrt(max(var, 0.0))), math.radians(MAX_RELIEF_TILT_DEG))


def _normals_along(cands, up_C: np.ndarray) -> np.ndarray:
    """(len(cands),) the cosine between each candidate pose's pad normal (in the camera frame) and ``up_C``."""
    return np.array([float((c[:3, :3].T @ np.array([0.0, 0.0, 1.0])) @ up_C) for c in cands])


def _mirror_fits_alike(cands, rms, best: int) -> bool:
    """Whether the two planar solutions cannot be told apart by their fit, yet lie apart.  On a far
    pad seen from the side the two fit alike: without an IMU, the first pose of bench_v2's
    x_wide_oblique_dusk (a 20-23 px pad at 20 m, pitched 40 degrees) fit to 0.33 px and its mirror
    to 0.40; the mirror was taken, 140 % of the height off, and every later pose followed it as the
    previous one (126 false accepts).  Alike: the mirror within ``FLIP_MARGIN_SIGMAS`` times the
    noise (the corners' floor, or the fit's own residual where larger); apart: further than
    ``FLIP_APART`` of the height.  (Seen square on, the two lie close together and either will do:
    a nadir view at 3 m, 0.02 and 0.33 px.)"""
    other = 1 - best
    alike = rms[other] <= rms[best] + FLIP_MARGIN_SIGMAS * max(PIXEL_SIGMA, rms[best])
    apart = np.linalg.norm(cands[other][:3, 3] - cands[best][:3, 3]) > FLIP_APART * abs(float(cands[best][2, 3]))
    return bool(alike and apart)


def _tilting_choice(cands, rms, best: int) -> tuple:
    """``(index, flip_choice)`` between two solutions whose pads both lie as near up as a tilting
    deck's may: the better fit where the two do not fit alike ("rms"), else ``(best, "ambiguous")``.
    Not the previous pose: on rolling-deck renders a far outline's wrong mirror, taken as the
    previous pose, chose every marker pose after it (deck_mono: 14 false accepts, 12-16 degrees off)."""
    if not _mirror_fits_alike(cands, rms, best):
        return best, "rms"
    return best, "ambiguous"


def _previous_choice(cands, prev_cam2pad: np.ndarray) -> int:
    """The candidate nearer the previous pose: by position where the two lie apart (further than
    ``FLIP_APART`` of the height: a far pad seen obliquely, whose previous pose, an outline's perhaps,
    has its position far surer than its tilt), else by rotation.  By rotation alone, conditions'
    snow_airframe_offnadir without an IMU took a markers pose's mirror, 54 % of the height off, after
    an outline pose 1.8 % off in position but tilted toward the mirror; the right one lay 2.2 % off."""
    apart = np.linalg.norm(cands[1][:3, 3] - cands[0][:3, 3]) > FLIP_APART * abs(float(cands[0][2, 3]))
    if apart:
        return int(np.argmin([np.linalg.norm(c[:3, 3] - prev_cam2pad[:3, 3]) for c in cands]))
    return int(np.argmin([rotation_angle(c[:3, :3], prev_cam2pad[:3, :3]) for c in cands]))


def _level_choice(cands, level_up_C: np.ndarray, best: int) -> tuple:
    """``(index, "level")``: the candidate whose pad lies level for a drone that flies level
    (``level_up_C``: the body's up in the camera frame, the mount alone): within ``LEVEL_TILT_DEG``
    of it (what a multirotor tilts in flight), the other's ``FLIP_LEVEL_GAP_DEG`` further off.  The
    mirror's pad is tilted by about twice the angle the pad is seen at from the optical axis: 20-40
    degrees for a far pad seen obliquely, where the two fit alike.  ``(best, "ambiguous")`` when
    that does not decide."""
    a = np.degrees(np.arccos(np.clip(_normals_along(cands, level_up_C), -1.0, 1.0)))
    for k in (0, 1):
        if a[k] <= LEVEL_TILT_DEG and a[1 - k] >= a[k] + FLIP_LEVEL_GAP_DEG:
            return k, "level"
    return best, "ambiguous"


def tilt_disagreement(camera: Camera, cam2pad: np.ndarray, pts_P: np.ndarray, px: np.ndarray, up_C: np.ndarray,
                      sigma_px: float, shared: "SharedNoise | None" = None) -> tuple:
    """``(angle, sigma)`` in degrees: how far the pad normal of an image-only pose is from the IMU's
    up direction, and how well the image fixes that normal (from the reprojection Jacobian with
    pixel noise ``sigma_px`` or the fit's own residuals, whichever is larger)."""
    z = cam2pad[:3, :3].T @ np.array([0.0, 0.0, 1.0])  # pad normal in C
    up = np.asarray(up_C, np.float64) / np.linalg.norm(up_C)
    ang = float(np.degrees(np.arccos(np.clip(z @ up, -1.0, 1.0))))
    cov = pose_covariance(camera, cam2pad, pts_P, px, min_sigma_px=sigma_px, shared=shared)[3:, 3:]  # about C's axes
    if not np.isfinite(cov).all():
        return ang, float("inf")
    # a rotation tilts the normal by its part across the normal (about the normal it does nothing):
    # the covariance projected on the plane across the normal, per axis.  Any camera mount: the
    # normal is C's z only for a camera looking straight down
    P = np.eye(3) - np.outer(z, z)
    var = float(np.trace(P @ cov @ P)) / 2.0
    return ang, float(np.degrees(np.sqrt(max(var, 0.0))))


def normalized_dlt_homography(src_xy: np.ndarray, dst_xy: np.ndarray) -> np.ndarray | None:
    """Homography mapping ``src`` to ``dst`` (N >= 4) by Hartley-normalised DLT."""
    if len(src_xy) < 4:
        return None

    def norm(p):
        c = p.mean(axis=0)
        s = np.sqrt(2) / max(np.mean(np.linalg.norm(p - c, axis=1)), 1e-12)
        return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1]])

    Ts, Td = norm(src_xy), norm(dst_xy)
    s = (Ts @ np.column_stack([src_xy, np.ones(len(src_xy))]).T).T
    d = (Td @ np.column_stack([dst_xy, np.ones(len(dst_xy))]).T).T
    A = np.zeros((2 * len(s), 9))
    A[0::2, 0:3] = s
    A[0::2, 6:9] = -d[:, 0:1] * s
    A[1::2, 3:6] = s
    A[1::2, 6:9] = -d[:, 1:2] * s
    _, sv, vt = np.linalg.svd(A)
    if sv[-2] < 1e-12:
        return None
    H = np.linalg.inv(Td) @ vt[-1].reshape(3, 3) @ Ts
    return H / H[2, 2] if abs(H[2, 2]) > 1e-15 else H


def pose_from_homography(H_norm: np.ndarray) -> np.ndarray | None:
    """``T_C_P`` from a homography mapping pad (x, y) to normalised image coordinates.

    ``H ~ [r1 r2 t]``: scale so that r1, r2 have unit norm on average, choose the sign that
    puts the pad in front of the camera, orthonormalise ``[r1 r2 r1 x r2]`` by SVD.
    """
    h1, h2, h3 = H_norm[:, 0], H_norm[:, 1], H_norm[:, 2]
    s = 2.0 / (np.linalg.norm(h1) + np.linalg.norm(h2))
    if not np.isfinite(s):
        return None
    if h3[2] * s < 0:
        s = -s
    r1, r2, t = h1 * s, h2 * s, h3 * s
    R = np.column_stack([r1, r2, np.cross(r1, r2)])
    U, _, Vt = np.linalg.svd(R)
    R = U @ np.diag([1, 1, np.linalg.det(U @ Vt)]) @ Vt
    return make_transform(R, t)


def _residuals(camera: Camera, cam2pad: np.ndarray, pts_P: np.ndarray, px: np.ndarray) -> np.ndarray:
    return (camera.project_from(cam2pad, pts_P) - px).ravel()


def _perturbed(cam2pad: np.ndarray, eps: float) -> np.ndarray:
    """``(7, 4, 4)``: the pose, then +eps on each of (position xyz, rotation vector) in turn."""
    Ts = np.repeat(cam2pad[None], 7, axis=0)
    for i in range(3):
        Ts[1 + i, i, 3] += eps
        d = np.zeros(3)
        d[i] = eps
        Ts[4 + i, :3, :3] = cam2pad[:3, :3] @ so3_exp(d)
    return Ts


def _project_poses(camera: Camera, Ts: np.ndarray, pts_P: np.ndarray) -> np.ndarray:
    """Pixels ``(k, n, 2)`` of ``pts_P`` seen from ``k`` poses ``T_P_C`` in one vectorised pass."""
    R = Ts[:, :3, :3]
    t = Ts[:, :3, 3]
    Pc = np.einsum("kji,knj->kni", R, pts_P[None, :, :] - t[:, None, :])  # R^T (P - t)
    return camera.project(Pc.reshape(-1, 3)).reshape(len(Ts), -1, 2)


def reprojection_rms(camera: Camera, cam2pad: np.ndarray, pts_P: np.ndarray, px: np.ndarray) -> float:
    r = _residuals(camera, cam2pad, pts_P, px)
    return float(np.sqrt(np.mean(r * r))) if r.size else float("inf")


def point_residuals(camera: Camera, cam2pad: np.ndarray, pts_P: np.ndarray, px: np.ndarray) -> np.ndarray:
    """``(N,)`` reprojection error of each correspondence, pixels."""
    return np.linalg.norm(_residuals(camera, cam2pad, pts_P, px).reshape(-1, 2), axis=1)


RAYLEIGH_MEDIAN = math.sqrt(2.0 * math.log(2.0))  # the median length of a 2-D normal error, in sigmas (1.1774)


def robust_sigma(r: np.ndarray) -> float:
    """The per-axis noise that 2-D residual lengths ``r`` show, read from their median (robust to
    the outliers among them while they are fewer than half)."""
    return float(np.median(r)) / RAYLEIGH_MEDIAN


def outlying_points(camera: Camera, cam2pad: np.ndarray, pts_P: np.ndarray, px: np.ndarray,
                    floor_px: float = 1.0, k: float = 4.0, max_share: float = 0.25) -> np.ndarray | None:
    """Indices of correspondences that a pose from many points shows to be wrong: reprojected
    more than ``k`` robust sigmas (from the median residual) and ``floor_px`` off, or ``None``
    when there are none, or too many to call outliers (more than ``max_share``: then the pose
    itself is in doubt)."""
    r = point_residuals(camera, cam2pad, pts_P, px)
    if not np.isfinite(r).all():
        return None
    sigma = robust_sigma(r)
    bad = np.nonzero(r > max(floor_px, k * sigma))[0]
    return bad if 0 < len(bad) <= max_share * len(r) else None


def _on_patch(pts_P: np.ndarray, delta) -> np.ndarray:
    """Pad points on a patch of the surface tilted by ``delta`` (rotation about the pad's x and y,
    radians) about their centroid: where a wrinkle puts them (:func:`relief_tilt_rad`)."""
    c = pts_P.mean(axis=0)
    return c + (pts_P - c) @ so3_exp(np.array([delta[0], delta[1], 0.0])).T


def _linearised(camera: Camera, cam2pad: np.ndarray, pts_P: np.ndarray, px: np.ndarray, eps: float = 1e-6,
                delta=None) -> tuple:
    """The reprojection and gravity-prior problems linearised at ``cam2pad`` by forward differences
    over (position, rotation vector of ``R_P_C @ exp(d)``): ``(pixel residuals (2n,), their
    Jacobian (2n, 6), the pad's normal in C (3,), its Jacobian (3, 6))``.  ``delta``: the points
    lie on a patch tilted so (:func:`_on_patch`), and the Jacobians have two more columns, for it."""
    Ts = _perturbed(cam2pad, eps)
    P = pts_P if delta is None else _on_patch(pts_P, delta)
    proj = _project_poses(camera, Ts, P)
    normal = np.einsum("kji,j->ki", Ts[:, :3, :3], np.array([0.0, 0.0, 1.0]))  # R^T z
    J, Jn = ((proj[1:] - proj[0]).reshape(6, -1) / eps).T, ((normal[1:] - normal[0]) / eps).T
    if delta is not None:
        tilted = [_project_poses(camera, cam2pad[None], _on_patch(pts_P, np.asarray(delta) + eps * e))[0]
                  for e in np.eye(2)]
        J = np.column_stack([J] + [((q - proj[0]) / eps).ravel() for q in tilted])
        Jn = np.column_stack([Jn, np.zeros((3, 2))])
    return (proj[0] - px).ravel(), J, normal[0], Jn


def _row_sigmas(sigma_px, n: int) -> np.ndarray:
    """(2n,) pixel noise per residual row from a scalar or one value per point."""
    return np.repeat(np.broadcast_to(np.asarray(sigma_px, np.float64), (n,)), 2)


@dataclass(frozen=True)
class SharedNoise:
    """Errors that a group of points (a marker's corners) share, besides each point's own: the whole
    group shifted by ``shift`` px (standard deviation per axis) and grown or shrunk by ``dilation``
    px (at the group's RMS radius about its centroid).  A marker's corners are found
    on one blurred, compressed, thresholded patch: blur across it, JPEG's blocks and a binarising
    threshold off by a little move or swell all of them together.  Two markers' relative size is
    what fixes the tilt between them, so independent noise alone reads it far too sure.

    ``groups``: (N,) the group of each point, -1 for points on their own."""
    groups: np.ndarray
    shift: float
    dilation: float


def _whitener(sigma_px, px: np.ndarray, shared: SharedNoise | None = None) -> np.ndarray:
    """What whitens the (2n,) pixel residuals and their Jacobian's rows: ``(2n,)`` sigmas to divide
    by when the points' errors are independent, else a ``(2n, 2n)`` block-diagonal matrix to
    multiply by (the inverse Cholesky factor of each group's noise covariance)."""
    n = len(px)
    s = _row_sigmas(sigma_px, n)
    if shared is None or not (shared.shift > 0 or shared.dilation > 0):
        return s
    W = np.diag(1.0 / s)
    groups = np.asarray(shared.groups)
    for g in np.unique(groups[groups >= 0]):
        idx = np.nonzero(groups == g)[0]
        if len(idx) < 2:
            continue
        rows = np.stack([2 * idx, 2 * idx + 1], axis=1).ravel()
        d = px[idx] - px[idx].mean(axis=0)
        radius = math.sqrt(max(float(np.mean(np.sum(d * d, axis=1))), 1e-12))
        T = np.tile(np.eye(2), (len(idx), 1))
        D = d.reshape(-1, 1) / radius
        C = np.diag(s[rows] ** 2) + shared.shift ** 2 * (T @ T.T) + shared.dilation ** 2 * (D @ D.T)
        W[np.ix_(rows, rows)] = np.linalg.inv(np.linalg.cholesky(C))
    return W


def _whiten(W: np.ndarray, r: np.ndarray, J: np.ndarray) -> tuple:
    return (r / W, J / W[:, None]) if W.ndim == 1 else (W @ r, W @ J)


def pose_covariance(camera: Camera, cam2pad: np.ndarray, pts_P: np.ndarray, px: np.ndarray,
                    min_sigma_px: float = 0.1, up_C: np.ndarray | None = None,
                    sigma_up_rad: float | None = None, shared: SharedNoise | None = None,
                    relief_tilt: float = 0.0, delta=None) -> np.ndarray:
    """6x6 covariance of (camera position in P, rotation vector of ``R_P_C @ exp(d)``, i.e. about
    the camera's axes) from the reprojection Jacobian, scaled by the residual variance (at least
    ``min_sigma_px`` squared: a scalar, or one per point where some are less sure than others).
    With ``up_C`` and ``sigma_up_rad`` it is the covariance of the
    gravity-refined pose (:func:`refine_with_gravity`): the IMU's up direction is information too.
    ``shared``: errors groups of points share (:class:`SharedNoise`).  ``relief_tilt`` (radians,
    one sigma): the points lie on a patch of a wrinkled pad that may be tilted so from the pad's
    plane (:func:`relief_tilt_rad`; ``delta``, the patch's tilt the refinement found), which the
    image cannot tell from the pad's own tilt: marginalised out."""
    patch = relief_tilt > 0
    if patch and delta is None:
        delta = np.zeros(2)
    r0, J, Jn = _whitened(camera, cam2pad, pts_P, px, min_sigma_px, shared, delta if patch else None)
    info = J.T @ J / _residual_scale(r0) ** 2
    if up_C is not None and sigma_up_rad:
        info = info + Jn.T @ Jn / sigma_up_rad ** 2
    if patch:
        info[6:, 6:] += np.eye(2) / relief_tilt ** 2
    try:
        return np.linalg.inv(info)[:6, :6]
    except np.linalg.LinAlgError:
        return np.full((6, 6), np.inf)


def _whitened(camera: Camera, cam2pad: np.ndarray, pts_P: np.ndarray, px, sigma_px, shared, delta=None) -> tuple:
    """The pixel residuals and their Jacobian whitened by the noise, and the normal's Jacobian."""
    r0, J, _, Jn = _linearised(camera, cam2pad, pts_P, px, delta=delta)
    r0, J = _whiten(_whitener(sigma_px, np.asarray(px, np.float64).reshape(-1, 2), shared), r0, J)
    return r0, J, Jn


def _residual_scale(r_white: np.ndarray) -> float:
    """How much larger than stated the noise shows itself in whitened residuals: their RMS over
    the degrees of freedom left (a pose takes 6), at least 1."""
    return math.sqrt(max(float(r_white @ r_white) / max(r_white.size - 6, 1), 1.0))


def projection_sigma_px(camera: Camera, cam2pad: np.ndarray, cov: np.ndarray, pts_P: np.ndarray) -> np.ndarray:
    """``(N,)`` how far (px, RMS over x and y) the images of pad points ``pts_P`` may lie from where
    the pose ``cam2pad`` puts them, by its covariance ``cov`` (:func:`pose_covariance`'s)."""
    pts_P = np.asarray(pts_P, np.float64).reshape(-1, 3)
    J = _linearised(camera, cam2pad, pts_P, np.zeros((len(pts_P), 2)))[1]
    var = np.einsum("ij,jk,ik->i", J, cov, J).reshape(-1, 2)
    return np.sqrt(np.maximum(var, 0.0).mean(axis=1))


def refine_with_gravity(camera: Camera, cam2pad: np.ndarray, pts_P: np.ndarray, px: np.ndarray, up_C: np.ndarray,
                        sigma_px: float, sigma_up_rad: float, iterations: int = 4,
                        shared: SharedNoise | None = None, relief_tilt: float = 0.0) -> np.ndarray:
    """Levenberg-Marquardt on the reprojection error plus a prior that the pad's normal is the IMU's up.

    With few, close-together correspondences (the pad outline far away) the tilt of a planar
    target is weakly observed and couples into a lateral position error of height x tilt; the
    AHRS knows roll and pitch to a fraction of a degree, so this prior removes that coupling.
    ``relief_tilt`` (radians, one sigma): the points lie on a patch of a wrinkled pad, tilted from
    its plane by as much (:func:`relief_tilt_rad`), solved for alongside (the image fixes the
    patch's tilt; the IMU's up the pad's).
    """
    return _refine_with_gravity(camera, cam2pad, pts_P, px, up_C, sigma_px, sigma_up_rad, iterations, shared,
                                relief_tilt)[0]


def _refine_with_gravity(camera, cam2pad, pts_P, px, up_C, sigma_px, sigma_up_rad, iterations=4, shared=None,
                         relief_tilt=0.0) -> tuple:
    """:func:`refine_with_gravity`'s pose and the patch's tilt it found (None for a flat pad)."""
    T = cam2pad.copy()
    up = np.asarray(up_C, np.float64) / np.linalg.norm(up_C)
    patch = relief_tilt > 0
    delta = np.zeros(2) if patch else None

    W = _whitener(sigma_px, np.asarray(px, np.float64).reshape(-1, 2), shared)

    def system(T, delta):  # whitened residuals and Jacobian: pixels, the normal's distance from up, the patch's tilt
        r, J, n, Jn = _linearised(camera, T, pts_P, px, delta=delta)
        r, J = _whiten(W, r, J)
        rows, Js = [r, (n - up) / sigma_up_rad], [J, Jn / sigma_up_rad]
        if patch:
            rows.append(delta / relief_tilt)
            Js.append(np.column_stack([np.zeros((2, 6)), np.eye(2) / relief_tilt]))
        return np.concatenate(rows), np.concatenate(Js, axis=0)

    r0, J = system(T, delta)
    lam = 1e-6
    for _ in range(iterations * 3):
        # Levenberg-Marquardt: a disagreement of many sigmas between the image-only tilt and the IMU
        # is far from linear, and a plain Gauss-Newton step that overshoots used to stop the refinement
        # at the image-only pose (13 degrees off with a wrong corner, the IMU ignored)
        A = J.T @ J
        try:
            step = -np.linalg.solve(A + lam * np.diag(np.diag(A) + 1e-12), J.T @ r0)
        except np.linalg.LinAlgError:
            break
        if np.abs(step).max() < 1e-10:  # converged: a step this small is below what the cost can show
            break
        Tn = T.copy()
        Tn[:3, 3] += step[:3]
        Tn[:3, :3] = Tn[:3, :3] @ so3_exp(step[3:6])
        dn = delta + step[6:] if patch else None
        rn, Jn = system(Tn, dn)
        if not rn @ rn < r0 @ r0:
            lam *= 10.0
            if lam > 1e6:
                break
            continue
        T, delta, r0, J = Tn, dn, rn, Jn
        lam = max(lam / 10.0, 1e-9)
        if np.abs(step).max() < 1e-9:
            break
    return T, delta


def planar_pose_candidates(camera: Camera, pts_P: np.ndarray, px: np.ndarray, xy: np.ndarray | None = None) -> list:
    """The (one or two) poses ``T_P_C`` that fit planar correspondences: IPPE's two solutions
    (the flip ambiguity), or our DLT homography decomposition when IPPE fails."""
    if xy is None:
        xy = camera.normalized_from_pixels(px)
    obj = np.ascontiguousarray(np.asarray(pts_P, np.float64)[:, :3])
    try:
        ok, rvecs, tvecs, _ = cv2.solvePnPGeneric(obj, np.ascontiguousarray(xy.reshape(-1, 1, 2)), np.eye(3), None,
                                                  flags=cv2.SOLVEPNP_IPPE)
    except cv2.error:
        ok = 0
    cands = []
    if ok:
        for rv, tv in zip(rvecs, tvecs):
            R, _ = cv2.Rodrigues(rv)
            T_C_P = make_transform(R, tv.ravel())
            if T_C_P[2, 3] > 0:
                cands.append(invert(T_C_P))
    if not cands:
        H = normalized_dlt_homography(obj[:, :2], xy)
        T = pose_from_homography(H) if H is not None else None
        if T is not None:
            cands = [invert(T)]
    return cands


def solve_planar_pose(camera: Camera, pts_P: np.ndarray, px: np.ndarray, up_C: np.ndarray | None = None,
                      prev_cam2pad: np.ndarray | None = None, refine: bool = True,
                      gravity_sigma_deg: float | None = 0.5, sigma_px=PIXEL_SIGMA,
                      sigma_from_fit: tuple | None = None, shared: SharedNoise | None = None,
                      level_up_C: np.ndarray | None = None, tilt_chi2: float | None = None,
                      up_tolerance_deg: float = 0.0, stated_shared: SharedNoise | None = None,
                      relief_m: float = 0.0) -> PoseResult | None:
    """Camera pose ``T_P_C`` from pad points (z = 0) and their distorted pixels, each known to
    ``sigma_px`` (a scalar, or one per point).  ``sigma_from_fit = (k, floor)``, with ``up_C`` and a
    scalar ``sigma_px``: the pixel noise is instead ``k`` times the image-only fit's residual RMS,
    at least ``floor``, so that the gravity prior is weighed against the noise the image shows (in
    the same solve: the image-only fit is made anyway).  ``shared``: errors groups of the points
    share (:class:`SharedNoise`).  ``stated_shared``: errors groups share that the covariance counts
    and the solve does not weigh by, its shift and dilation in units of the pixel noise (the one the
    fit shows, with ``sigma_from_fit``).

    ``up_C``: the world's up direction in the camera frame (from the IMU), used to choose between
    the two IPPE solutions (the pad lies flat: its normal is up).  Else ``prev_cam2pad``.  Else
    the lower reprojection error, unless the two fit alike and lie apart (:func:`_mirror_fits_alike`)
    and ``level_up_C`` is given: the body's up seen through the mount, where a drone that flies
    level has the world's (:func:`_level_choice`; ``flip_choice`` "level", or "ambiguous" when it
    does not decide either, the lower error's pose returned).

    ``up_tolerance_deg``, with ``up_C``: how far the pad's normal may lie from up (a tilting deck).
    Where both solutions' normals lie within it, gravity does not choose: the fit does where the two
    do not fit alike (``flip_choice`` "rms"), else nothing ("ambiguous").

    ``tilt_chi2``, with ``up_C``: where the image-only tilt disagrees with the IMU's up by more than
    this chi-square (two degrees of freedom, in the two's sigmas together), the image's noise is
    widened until it does not (:func:`_tilt_noise_scale`), in the refinement and the covariance: the
    image's errors are larger than its residuals show, and smooth (a bias that fits a homography,
    as tracks between frames smeared differently do, leaves no residual).

    ``relief_m``: the pad's surface stands up to this off its plane (a wrinkled pad): the points lie
    on a patch whose tilt the image cannot tell from the pad's (:func:`relief_tilt_rad`).  It is in
    the image-only tilt's sigma, solved for beside the pose against the gravity prior, and
    marginalised out of the covariance.
    """
    pts_P = np.asarray(pts_P, np.float64).reshape(-1, 3)
    px = np.asarray(px, np.float64).reshape(-1, 2)
    n = len(pts_P)
    if n < 4 or not np.all(np.isfinite(px)):
        return None
    xy = camera.normalized_from_pixels(px)
    obj = np.ascontiguousarray(pts_P[:, :3])
    cands = planar_pose_candidates(camera, obj, px, xy)
    if not cands:
        return None
    if refine and up_C is not None:
        # each candidate to its minimum before gravity chooses: IPPE's two poses are only starting
        # points, on a far pad a few degrees from the fit's minima, and the one nearer gravity may
        # lie in the basin further from it (36 corners over 0.6 m at 7.5 m: in 114 of 300 views the
        # normal taken was further from up than the other minimum)
        cands = [_refine_image_only(c, obj, xy) for c in cands]
    rms = [reprojection_rms(camera, c, obj, px) for c in cands]
    choice = "single"
    best = int(np.argmin(rms))
    if len(cands) == 2:
        if up_C is not None:
            # the pad's normal (z of P) in the camera frame should point up
            along = _normals_along(cands, up_C)
            best_rms, best, choice = best, int(np.argmax(along)), "gravity"
            if up_tolerance_deg > 0 and np.degrees(np.arccos(np.clip(along.min(), -1.0, 1.0))) <= up_tolerance_deg:
                best, choice = _tilting_choice(cands, rms, best_rms)
        elif prev_cam2pad is not None:
            best, choice = _previous_choice(cands, prev_cam2pad), "previous"
        elif level_up_C is not None and _mirror_fits_alike(cands, rms, best):
            best, choice = _level_choice(cands, level_up_C, best)
        else:
            choice = "rms"
    T = cands[best]
    other = rms[1 - best] if len(cands) == 2 else float("inf")
    other_T = cands[1 - best] if len(cands) == 2 else None
    if refine and up_C is None:
        # without an IMU, as it was: the chosen one refined by OpenCV's LM, which may stop short.
        # Taken to its minimum, bench_v1's no_imu field1080 Adjustment RMSE went 56.0 -> 59.0 mm;
        # both refined before choosing, far mirrors fell into one minimum and were no longer
        # refused as ambiguous (availability 72 -> 99 %, false accepts 8 -> 17)
        T = _refine_image_only(T, obj, xy, converge=False)
    tilt = (float("nan"), float("nan"))
    sigma_up = None
    normal_img = mirror_normal = None
    mirror_gap = float("inf")
    image_rms = float("nan")
    noise_scale = 1.0
    prior_up = up_C
    relief_tilt = relief_tilt_rad(obj, relief_m)
    delta = None  # the patch's tilt the refinement finds
    if up_C is None and level_up_C is not None and LEVEL_SIGMA_DEG:
        # without an IMU, a drone that flies nearly level has the body's up, seen through the mount,
        # as a soft prior: a far pad's four corners fix its tilt to several degrees, which moves the
        # pose sideways by the height times that tilt.  It refines the image's own least-squares pose
        # (not weighed by ``shared``, as that pose is not: weighed so, field1080's markers at 1-3 m,
        # whose tilt the prior cannot move, came out 2.1 -> 5.5 mm off; the covariance holds both)
        prior_up, sigma_up = level_up_C, np.radians(LEVEL_SIGMA_DEG)
        T, delta = _refine_with_gravity(camera, T, obj, px, level_up_C, sigma_px, sigma_up, relief_tilt=relief_tilt)
    elif up_C is not None:
        image_rms = reprojection_rms(camera, T, obj, px)
        if sigma_from_fit is not None and np.ndim(sigma_px) == 0 and np.isfinite(image_rms):
            sigma_px = max(sigma_from_fit[0] * image_rms, sigma_from_fit[1])
        angle, image_sigma = tilt_disagreement(camera, T, obj, px, up_C, sigma_px, shared)
        tilt = (angle, math.hypot(image_sigma, math.degrees(relief_tilt)))  # (how far a wrinkle may tilt the patch too)
        normal_img = T[:3, :3].T @ np.array([0.0, 0.0, 1.0])
        if other_T is not None and refine:
            mirror_normal = other_T[:3, :3].T @ np.array([0.0, 0.0, 1.0])
            mirror_gap = _chi2(camera, other_T, obj, px, sigma_px) - _chi2(camera, T, obj, px, sigma_px)
        # (what a wrinkle may tilt is no noise of the image's: it stands with the IMU's doubt)
        k = _tilt_noise_scale(angle, image_sigma, math.hypot(gravity_sigma_deg, math.degrees(relief_tilt)), tilt_chi2) \
            if tilt_chi2 and gravity_sigma_deg else 1.0
        if k > 1.0:
            # the tilt's sigma was the noise as the residuals showed it: widened from there
            noise_scale = k * _residual_scale(_whitened(camera, T, obj, px, sigma_px, shared)[0])
            sigma_px = np.asarray(sigma_px, np.float64) * noise_scale
            sigma_px = float(sigma_px) if sigma_px.ndim == 0 else sigma_px
            if shared is not None:
                shared = SharedNoise(shared.groups, shared.shift * noise_scale, shared.dilation * noise_scale)
        if gravity_sigma_deg:
            sigma_up = np.radians(gravity_sigma_deg)
            T, delta = _refine_with_gravity(camera, T, obj, px, up_C, sigma_px, sigma_up, shared=shared,
                                            relief_tilt=relief_tilt)
    # (on a wrinkled pad, as the points lie on the patch it found: its tilt is no error of theirs)
    rms_best = reprojection_rms(camera, T, obj if delta is None else _on_patch(obj, delta), px)
    if stated_shared is not None and shared is None:
        v = float(np.mean(sigma_px))
        shared = SharedNoise(stated_shared.groups, stated_shared.shift * v, stated_shared.dilation * v)
    cov = pose_covariance(camera, T, obj, px, min_sigma_px=sigma_px, up_C=prior_up, sigma_up_rad=sigma_up, shared=shared,
                          relief_tilt=relief_tilt, delta=delta)
    return PoseResult(T, rms_best, n, cov, other, choice, *tilt, normal_img, image_rms, sigma_px, other_T,
                      mirror_normal, mirror_gap, noise_scale, math.degrees(relief_tilt),
                      0.0 if delta is None else float(np.degrees(np.linalg.norm(delta))))


def _tilt_noise_scale(angle_deg: float, sigma_deg: float, gravity_sigma_deg: float, chi2: float) -> float:
    """By how much an image's tilt sigma must grow for its ``angle_deg`` from the IMU's up (whose
    own sigma is ``gravity_sigma_deg``) to be within ``chi2`` of the two together; 1 if it is."""
    if not (np.isfinite(angle_deg) and np.isfinite(sigma_deg) and sigma_deg > 0):
        return 1.0
    need = angle_deg ** 2 / chi2 - gravity_sigma_deg ** 2
    return max(math.sqrt(max(need, 0.0)) / sigma_deg, 1.0)


# how far the image-only refinement goes: far enough to reach the minimum of a far pad's flat tilt
VVS_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-12)


def _refine_image_only(T: np.ndarray, obj: np.ndarray, xy: np.ndarray, converge: bool = True) -> np.ndarray:
    """``T_P_C`` refined to the reprojection error's minimum on the image alone (normalised
    coordinates), by OpenCV's virtual visual servoing; ``T`` itself where that fails or puts the pad
    behind the camera.

    It was OpenCV's Levenberg-Marquardt (``solvePnPRefineLM``), which on a far pad's tilt, a long
    flat valley, stops early whatever its criteria: 36 corners at 7.5 m, started from IPPE's two
    poses, ended 0.22 degrees from the minimum in the median and up to 6.6 (each further call
    moved them on), so an image-only normal was wherever it stopped, and the two starting points
    looked like two minima where the cost has one.  VVS: within 0.1 degrees, 0.6 ms a call.
    ``converge=False``: that LM (the poses made without an IMU; see :func:`solve_planar_pose`)."""
    T_C_P = invert(T)
    rv, _ = cv2.Rodrigues(T_C_P[:3, :3])
    tv = T_C_P[:3, 3].reshape(3, 1).copy()
    img = np.ascontiguousarray(xy.reshape(-1, 1, 2))
    try:
        if converge:
            rv, tv = cv2.solvePnPRefineVVS(obj, img, np.eye(3), None, rv, tv, criteria=VVS_CRITERIA)
        else:
            rv, tv = cv2.solvePnPRefineLM(obj, img, np.eye(3), None, rv, tv)
    except cv2.error:
        return T
    if not (np.all(np.isfinite(rv)) and np.all(np.isfinite(tv)) and tv.ravel()[2] > 0):
        return T
    R, _ = cv2.Rodrigues(rv)
    return invert(make_transform(R, tv.ravel()))


def _chi2(camera: Camera, cam2pad: np.ndarray, pts_P: np.ndarray, px: np.ndarray, sigma_px) -> float:
    """The sum of squared reprojection errors in units of each point's noise (scalar or per point)."""
    r = _residuals(camera, cam2pad, pts_P, px).reshape(-1, 2)
    s = np.asarray(sigma_px, np.float64)
    return float(np.sum((r / (s.reshape(-1, 1) if s.ndim else s)) ** 2))
