"""Image motion over the exposure from one render's depth, and the motion blur it makes.

Every visible surface point is either static in the world or moves with the platform (the pad,
the platform box, what lies on them).  With the depth of a frame rendered at its time ``t``, the
point seen at pixel ``x`` is known in 3D, so its image at another time ``t + tau`` follows from
the known camera (and platform) motion: ``x + v(tau, x)``.  The motion blur of an exposure is the
average of the sharp image moved along these paths (a velocity-buffer blur):
``B(y) = mean_i I(y - v(tau_i, y))``, the same sample times as rendering sub-frames would use.

Flow is computed exactly at the nodes of a coarse grid and interpolated between them, except in
grid cells where depth or the motion class jumps (object and platform edges): there every pixel
is computed exactly.  The path over the exposure is the parabola through the flows at the
shutter's opening, the frame time (zero) and its closing.  Samples are read bicubically.

What the one-render blur cannot do, stated so its numbers are read right: it cannot show what
the motion uncovers (the ground behind a moving edge), and surfaces whose texture moves on its
own (the drone's shadow) are moved like the surface they lie on.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from hvloc.geometry import Camera, invert

STATIC, MOVING, ATTACHED = 0, 1, 2  # still in the world, moving with the platform, rigid with the camera
MAX_SAMPLES = 256
SAMPLE_SPACING_PX = 0.5


@dataclass
class Motion:
    """Relative motions of one frame: ``M[c][i]`` maps camera coordinates at the frame time to
    camera coordinates at sample time ``tau[i]``, for points of motion class ``c``."""

    tau: np.ndarray            # (S,) seconds relative to the frame time
    static: np.ndarray         # (S, 4, 4)
    moving: np.ndarray         # (S, 4, 4)


def relative_motion(cam2world_t: np.ndarray, cam2world_tau: np.ndarray, pad2world_t: np.ndarray,
                    pad2world_tau: np.ndarray, tau: np.ndarray) -> Motion:
    """``cam2world_*`` ``T_W_C`` and ``pad2world_*`` ``T_W_P`` at the frame time ``t`` (4, 4) and at
    the sample times ``tau`` (S, 4, 4)."""
    world2cam_tau = np.stack([invert(T) for T in cam2world_tau])
    static = world2cam_tau @ cam2world_t
    moving = world2cam_tau @ pad2world_tau @ invert(pad2world_t) @ cam2world_t
    return Motion(np.asarray(tau, np.float64), static, moving)


def _project(camera: Camera, xn, yn, z, M) -> tuple:
    """Pixels of the points ``z * (xn, yn, 1)`` moved by ``M`` (4, 4); float64 arrays of any shape."""
    zc = np.minimum(z, 1e5)  # the sky: directions (translation no longer matters)
    X, Y = xn * zc, yn * zc
    Xp = M[0, 0] * X + M[0, 1] * Y + M[0, 2] * zc + M[0, 3]
    Yp = M[1, 0] * X + M[1, 1] * Y + M[1, 2] * zc + M[1, 3]
    Zp = M[2, 0] * X + M[2, 1] * Y + M[2, 2] * zc + M[2, 3]
    Zp = np.where(Zp > 1e-6, Zp, 1e-6)
    x1 = np.column_stack([(Xp / Zp).ravel(), (Yp / Zp).ravel()])
    xy = camera.distort_normalized(x1)
    if any(camera.dist):
        xy = _guard_runaway(camera, np.column_stack([np.ravel(xn), np.ravel(yn)]), x1, xy)
    u = camera.fx * xy[:, 0] + camera.cx
    v = camera.fy * xy[:, 1] + camera.cy
    return u.reshape(np.shape(xn)), v.reshape(np.shape(xn))


def _guard_runaway(camera: Camera, x0: np.ndarray, x1: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Distorted positions ``xy`` of rays ``x1`` that moved from ``x0`` (seen in the image), with
    the ones the distortion polynomial sent astray replaced by its first-order step from ``x0``.

    A ray that leaves the field over the exposure can pass the radius where the polynomial stops
    growing; there it returns anything (1e10 px was seen), which made the whole frame's blur
    samples run to the limit or its motion vanish.  A real lens is smooth there: the linear step
    is what it does to first order.  Positions within a few pixels of the polynomial's own step
    (every ray that stays in the field) are left exactly as they were."""
    eps = 1e-6
    d0 = camera.distort_normalized(x0)
    jx = (camera.distort_normalized(x0 + [eps, 0.0]) - d0) / eps
    jy = (camera.distort_normalized(x0 + [0.0, eps]) - d0) / eps
    dx = x1 - x0
    lin = d0 + jx * dx[:, :1] + jy * dx[:, 1:]
    step = np.linalg.norm(lin - d0, axis=1)
    tol = 2.0 * step + 2.0 / camera.fx
    bad = ~(np.linalg.norm(xy - lin, axis=1) <= tol)  # NaN and inf count as astray
    if bad.any():
        xy = xy.copy()
        xy[bad] = lin[bad]
    return xy


def pixel_rays(camera: Camera) -> tuple:
    """``(xn, yn)`` ``(H, W)`` float32: every pixel's undistorted normalised ray ``(x/z, y/z)``."""
    u, v = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
    full = camera.normalized_from_pixels(np.column_stack([u.ravel(), v.ravel()]))
    return (full[:, 0].reshape(camera.height, camera.width).astype(np.float32),
            full[:, 1].reshape(camera.height, camera.width).astype(np.float32))


class FlowField:
    """Per-pixel flow of one camera at ``(H, W)`` from depth and a motion class per pixel.

    ``classify(points_C (N, 3)) -> (N,) int`` says which points move with the platform; it is
    called on 3D points in the camera frame at the frame time.  The grid step grows with the
    image (about 40k nodes) so the cost stays bounded."""

    def __init__(self, camera: Camera, step: int | None = None, rays: tuple | None = None):
        self.camera = camera
        H, W = camera.height, camera.width
        self.step = step = step or max(2, int(round(math.sqrt(H * W / 40000.0))))
        self.gh, self.gw = -(-H // step), -(-W // step)
        # grid nodes at pixel (step * i + (step - 1) / 2): cv2.resize by `step` then lands exactly
        gx = np.minimum(step * np.arange(self.gw) + (step - 1) / 2.0, W - 1)
        gy = np.minimum(step * np.arange(self.gh) + (step - 1) / 2.0, H - 1)
        self.grid_px = np.stack(np.meshgrid(gx, gy), axis=-1)  # (gh, gw, 2)
        self.grid_ix = np.round(self.grid_px).astype(np.int64)
        n = camera.normalized_from_pixels(self.grid_px.reshape(-1, 2))
        self.grid_xn = n[:, 0].reshape(self.gh, self.gw)
        self.grid_yn = n[:, 1].reshape(self.gh, self.gw)
        self.xn, self.yn = rays if rays is not None else pixel_rays(camera)
        u, v = np.meshgrid(np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32))
        self.base = np.dstack([u, v])  # (H, W, 2): each pixel's own position

    def points(self, xn, yn, z) -> np.ndarray:
        zc = np.minimum(z, 1e5)
        return np.stack([xn * zc, yn * zc, zc], axis=-1)

    def flows(self, z: np.ndarray, classify, motion: Motion) -> tuple:
        """``(flows (S, H, W, 2) float32, longest path over the exposure (px))``: the image motion of
        every pixel to each sample time (for two samples, the shutter's opening and closing, the
        path is the parabola through them and the frame time)."""
        H, W = z.shape
        s = self.step
        gz = z[self.grid_ix[..., 1], self.grid_ix[..., 0]].astype(np.float64)
        gcls = classify(self.points(self.grid_xn, self.grid_yn, gz).reshape(-1, 3)).reshape(gz.shape)
        S = len(motion.tau)
        coarse = np.zeros((S, self.gh, self.gw, 2), np.float32)
        for i in range(S):
            for c, Ms in ((STATIC, motion.static), (MOVING, motion.moving)):
                sel = gcls == c
                if sel.any():
                    u, v = _project(self.camera, self.grid_xn[sel], self.grid_yn[sel], gz[sel], Ms[i])
                    coarse[i, sel, 0] = u - self.grid_px[sel][:, 0]
                    coarse[i, sel, 1] = v - self.grid_px[sel][:, 1]
        longest = float(path_length_px(coarse[0], coarse[-1]).max()) if S == 2 else float("nan")
        out = np.empty((S, H, W, 2), np.float32)
        for i in range(S):
            out[i] = cv2.resize(coarse[i], (self.gw * s, self.gh * s), interpolation=cv2.INTER_LINEAR)[:H, :W]
        # cells where the depth or the class jumps: every pixel exactly
        zc = np.minimum(gz, 1e5)
        jump = np.zeros((self.gh, self.gw), bool)
        for a, b in (((slice(None), slice(1, None)), (slice(None), slice(None, -1))),
                     ((slice(1, None), slice(None)), (slice(None, -1), slice(None)))):
            j = (np.abs(zc[a] - zc[b]) > 0.03 * np.minimum(zc[a], zc[b])) | (gcls[a] != gcls[b])
            jump[a] |= j
            jump[b] |= j
        if jump.any():
            # a node's cells are the ones it interpolates: its 3x3 neighbourhood of cells, in pixels
            cells = cv2.dilate(jump.astype(np.uint8), np.ones((3, 3), np.uint8))
            mask = cv2.resize(cells, (self.gw * s, self.gh * s), interpolation=cv2.INTER_NEAREST)[:H, :W]
            ys, xs = np.nonzero(mask)
            zz = z[ys, xs].astype(np.float64)
            xn, yn = self.xn[ys, xs].astype(np.float64), self.yn[ys, xs].astype(np.float64)
            cls = classify(self.points(xn, yn, zz))
            for i in range(S):
                for c, Ms in ((STATIC, motion.static), (MOVING, motion.moving)):
                    sel = cls == c
                    if sel.any():
                        u, v = _project(self.camera, xn[sel], yn[sel], zz[sel], Ms[i])
                        out[i, ys[sel], xs[sel], 0] = u - xs[sel]
                        out[i, ys[sel], xs[sel], 1] = v - ys[sel]
                out[i, ys[cls == ATTACHED], xs[cls == ATTACHED]] = 0.0  # the airframe does not move in the image
            if S == 2:
                longest = max(longest, float(path_length_px(out[0, ys, xs], out[1, ys, xs]).max()))
        return out, longest


def exposure_times(exposure_s: float) -> np.ndarray:
    """The three times the exposure's path is known at: shutter open, frame time, shutter close."""
    return np.array([-exposure_s / 2.0, 0.0, exposure_s / 2.0])


def sample_times(exposure_s: float, n: int) -> np.ndarray:
    """``n`` sample times over the exposure, centred in equal parts (as sub-frame renders are)."""
    if n <= 1 or exposure_s <= 0:
        return np.zeros(1)
    return ((np.arange(n) + 0.5) / n - 0.5) * exposure_s


def _lagrange(s: float) -> tuple:
    """Weights of the flows at s = -1 (open) and s = +1 (close) on the parabola through them and 0."""
    return 0.5 * s * (s - 1.0), 0.5 * s * (s + 1.0)


def path_length_px(v_open: np.ndarray, v_close: np.ndarray, pieces: int = 8) -> np.ndarray:
    """Length (px) of each pixel's parabolic path over the exposure; ``v_*`` (..., 2)."""
    s = np.linspace(-1.0, 1.0, pieces + 1)
    wa, wb = 0.5 * s * (s - 1.0), 0.5 * s * (s + 1.0)
    da, db = np.diff(wa), np.diff(wb)  # each piece is da * v_open + db * v_close
    total = np.zeros(v_open.shape[:-1], np.float64)
    for a, b in zip(da, db):
        dx = a * v_open[..., 0] + b * v_close[..., 0]
        dy = a * v_open[..., 1] + b * v_close[..., 1]
        total += np.sqrt(dx * dx + dy * dy)
    return total


def samples_needed(max_path_px: float, floor: int = 1) -> int:
    """Sub-frames (or blur samples) so that consecutive images of any point are at most
    ``SAMPLE_SPACING_PX`` apart, at least ``floor``, at most ``MAX_SAMPLES``."""
    if not math.isfinite(max_path_px) or max_path_px <= 0:
        return max(1, floor)
    return int(min(MAX_SAMPLES, max(floor, math.ceil(max_path_px / SAMPLE_SPACING_PX))))


def velocity_blur(linear: np.ndarray, v_open: np.ndarray, v_close: np.ndarray, n: int, base: np.ndarray,
                  row_s: np.ndarray | None = None, exposure_s: float = 2.0) -> np.ndarray:
    """The exposure's blur of a sharp linear-light image ``(H, W, C)`` float32 with ``n`` samples
    along each pixel's path (``v_open``/``v_close`` (H, W, 2): the flow to the path's two ends, at
    s = -1 and +1; ``base`` (H, W, 2): each pixel's own position).  Global shutter: the ends are
    the shutter's opening and closing.  Rolling shutter: ``row_s`` (H,) is each row's own time
    and ``exposure_s`` the exposure, both in the units of s.  ``n <= 1`` without ``row_s``
    returns the image."""
    if n <= 1 and row_s is None:
        return linear
    acc = np.zeros_like(linear)
    m, vb = np.empty_like(v_open), np.empty_like(v_close)
    for tau in sample_times(exposure_s if row_s is not None else 2.0, max(n, 1)):
        if row_s is None:  # one time for every pixel
            a, b = _lagrange(float(tau))
            cv2.addWeighted(v_open, -a, v_close, -b, 0.0, dst=m)
        else:  # each row at its own time (float32 throughout: float64 temporaries cost 2x)
            a, b = (np.asarray(w, np.float32)[:, None, None] for w in _lagrange(row_s + tau))
            np.multiply(v_open, -a, out=m)
            np.multiply(v_close, b, out=vb)
            m -= vb
        m += base
        # bicubic: bilinear samples at fractional offsets smooth the image a little more each, which
        # widens edge ramps and, after the tone curve, moves edges by ~0.1 px (bicubic: ~0.04 px)
        cv2.add(acc, cv2.remap(linear, m, None, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE), dst=acc)
    acc *= 1.0 / max(n, 1)
    return acc
