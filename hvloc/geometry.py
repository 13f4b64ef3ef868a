"""Shared geometry leaf: camera model, SE(3) and quaternions in hvloc's conventions.

This module imports only numpy, so every package may use it (see DESIGN.md).

Conventions
-----------
* A transform ``T_A_B`` (4x4) maps coordinates in frame B to frame A:
  ``p_A = T_A_B @ p_B``.  In names: ``cam2pad`` is ``T_P_C``.
* Quaternions are Hamilton, stored ``(qx, qy, qz, qw)`` (TUM order).
* Camera frame is OpenCV's: x right, y down, z along the optical axis.
* Pixels are OpenCV's: the centre of the top-left pixel is (0, 0).
* Distortion is OpenCV's 5-parameter model ``(k1, k2, p1, p2, k3)``.
"""
from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

__all__ = [
    "CAMERA_MODELS",
    "Camera",
    "as_points",
    "compose",
    "invert",
    "make_transform",
    "quat_xyzw_from_matrix",
    "matrix_from_quat_xyzw",
    "transform_from_tum",
    "tum_from_transform",
    "so3_exp",
    "so3_log",
    "rotation_angle",
    "transform_points",
    "look_at_cam2world",
    "rotation_z",
    "heading_turn",
    "focal_from_hfov",
    "focal_from_hfov_equidistant",
    "continuous_quaternions",
    "GRAVITY_MPS2",
]

GRAVITY_MPS2 = 9.80665  # standard gravity (m/s^2): the world's z is up, so gravity is (0, 0, -GRAVITY_MPS2)


# ----------------------------------------------------------------------------- validation

def as_points(points, dim: int, name: str = "points") -> np.ndarray:
    """Return ``points`` as a float64 ``(N, dim)`` array, or raise ``ValueError`` naming it."""
    arr = np.asarray(points, dtype=np.float64)
    if arr.ndim == 1 and arr.shape[0] == dim:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise ValueError(f"{name} must have shape (N, {dim}), got {np.shape(points)}")
    return arr


def _as_transform(T, name: str = "T") -> np.ndarray:
    arr = np.asarray(T, dtype=np.float64)
    if arr.shape != (4, 4):
        raise ValueError(f"{name} must be a 4x4 transform, got shape {arr.shape}")
    return arr


# ----------------------------------------------------------------------------- SO(3) / SE(3)

def make_transform(R, t) -> np.ndarray:
    """4x4 transform from a 3x3 rotation and a 3-vector translation."""
    T = np.eye(4)
    T[:3, :3] = np.asarray(R, dtype=np.float64).reshape(3, 3)
    T[:3, 3] = np.asarray(t, dtype=np.float64).reshape(3)
    return T


def invert(T) -> np.ndarray:
    """Inverse of a rigid transform: ``invert(T_A_B) == T_B_A``."""
    T = _as_transform(T)
    R, t = T[:3, :3], T[:3, 3]
    return make_transform(R.T, -R.T @ t)


def pad_plane_homography(camera, cam2pad) -> np.ndarray:
    """3x3 homography: pad-plane (x, y) metres -> undistorted (ideal pinhole) image pixels of
    ``camera`` posed at ``cam2pad`` (``T_P_C``)."""
    T = invert(cam2pad)
    return camera.K @ np.column_stack([T[:3, 0], T[:3, 1], T[:3, 3]])


def compose(*Ts) -> np.ndarray:
    """``compose(T_A_B, T_B_C) == T_A_C``."""
    out = np.eye(4)
    for T in Ts:
        out = out @ _as_transform(T)
    return out


def transform_points(T_A_B, points_B) -> np.ndarray:
    """Map ``(N, 3)`` points from frame B to frame A."""
    T = _as_transform(T_A_B)
    P = as_points(points_B, 3)
    return P @ T[:3, :3].T + T[:3, 3]


def _skew(w) -> np.ndarray:
    x, y, z = w
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def so3_exp(rotvec) -> np.ndarray:
    """Rotation matrix of a rotation vector (axis * angle, radians), Rodrigues' formula."""
    w = np.asarray(rotvec, dtype=np.float64).reshape(3)
    theta = float(np.linalg.norm(w))
    K = _skew(w)
    if theta < 1e-8:
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + (math.sin(theta) / theta) * K + ((1 - math.cos(theta)) / theta**2) * K @ K


def so3_log(R) -> np.ndarray:
    """Rotation vector of a rotation matrix (inverse of :func:`so3_exp`), stable near 0 and pi."""
    q = quat_xyzw_from_matrix(R)
    v, w = q[:3], q[3]
    if w < 0:
        v, w = -v, -w
    s = float(np.linalg.norm(v))
    if s < 1e-12:
        return 2.0 * v
    angle = 2.0 * math.atan2(s, w)
    return v / s * angle


def rotvec_between(a, b) -> np.ndarray:
    """``(3,)``: the rotation vector of the least rotation that takes direction ``a`` onto direction
    ``b`` (about ``a x b``, by the angle between them); zero where they are parallel (or opposite: no
    axis is least there)."""
    a = np.asarray(a, dtype=np.float64) / np.linalg.norm(a)
    b = np.asarray(b, dtype=np.float64) / np.linalg.norm(b)
    axis = np.cross(a, b)
    s = float(np.linalg.norm(axis))
    return axis / s * math.atan2(s, float(a @ b)) if s > 1e-12 else np.zeros(3)


def rotation_angle(R_a, R_b=None) -> float:
    """Geodesic angle (radians) of ``R_a`` or, given ``R_b``, of ``R_a^T R_b``."""
    R = np.asarray(R_a, dtype=np.float64)[:3, :3]
    if R_b is not None:
        R = R.T @ np.asarray(R_b, dtype=np.float64)[:3, :3]
    return float(np.linalg.norm(so3_log(R)))


def heading_turn(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """How far ``R_b`` is turned from ``R_a`` about the world's z (radians, in (-pi, pi]): the turn
    of their x axes' horizontal parts, whatever their tilts (a deck's roll and pitch, say)."""
    d = math.atan2(R_b[1, 0], R_b[0, 0]) - math.atan2(R_a[1, 0], R_a[0, 0])
    return math.atan2(math.sin(d), math.cos(d))


def rotation_z(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def quat_xyzw_from_matrix(R) -> np.ndarray:
    """Hamilton unit quaternion ``(qx, qy, qz, qw)`` with ``qw >= 0`` of a rotation matrix."""
    m = np.asarray(R, dtype=np.float64)[:3, :3]
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        q = [0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        q = [(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        q = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def matrix_from_quat_xyzw(q) -> np.ndarray:
    """Rotation matrix of a Hamilton quaternion ``(qx, qy, qz, qw)`` (normalised first)."""
    x, y, z, w = np.asarray(q, dtype=np.float64).reshape(4) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def continuous_quaternions(q_xyzw) -> np.ndarray:
    """``(N, 4)`` quaternions with each row's sign chosen to stay in the hemisphere of the last
    finite row before it (``q`` and ``-q`` are one rotation; trajectories and filters want no sign
    jumps).  Rows with NaN are left as they are."""
    q = np.array(q_xyzw, dtype=np.float64).reshape(-1, 4)
    prev = None
    for k in range(len(q)):
        if not np.all(np.isfinite(q[k])):
            continue
        if prev is not None and float(q[k] @ prev) < 0:
            q[k] = -q[k]
        prev = q[k]
    return q


def focal_from_hfov(width: float, hfov_rad: float) -> float:
    """Focal length in pixels of a pinhole whose horizontal field of view across ``width`` px is ``hfov_rad``."""
    return (width / 2.0) / math.tan(hfov_rad / 2.0)


def focal_from_hfov_equidistant(width: float, hfov_rad: float) -> float:
    """Focal length in pixels of an equidistant fisheye (r = f * theta) whose horizontal field of view is ``hfov_rad``."""
    return (width / 2.0) / (hfov_rad / 2.0)


CAMERA_MODELS = {"pinhole": 5, "fisheye": 4}  # model -> number of distortion coefficients


def transform_from_tum(row) -> np.ndarray:
    """``(tx, ty, tz, qx, qy, qz, qw)`` -> 4x4."""
    r = np.asarray(row, dtype=np.float64).reshape(7)
    return make_transform(matrix_from_quat_xyzw(r[3:]), r[:3])


def tum_from_transform(T) -> np.ndarray:
    """4x4 -> ``(tx, ty, tz, qx, qy, qz, qw)``."""
    T = _as_transform(T)
    return np.concatenate([T[:3, 3], quat_xyzw_from_matrix(T[:3, :3])])


def look_at_cam2world(eye, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """OpenCV camera (z forward, y down) at ``eye`` looking at ``target``: returns ``T_W_C``."""
    eye = np.asarray(eye, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - eye
    z /= np.linalg.norm(z)
    up = np.asarray(up, dtype=np.float64)
    x = np.cross(z, -up)
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0]))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return make_transform(np.column_stack([x, y, z]), eye)


# ----------------------------------------------------------------------------- camera

@dataclass(frozen=True)
class Camera:
    """A central camera in the OpenCV pixel convention, one of two OpenCV lens models:

    - ``pinhole``: radial-tangential distortion, ``dist = (k1, k2, p1, p2, k3)`` (``cv2.projectPoints``);
    - ``fisheye``: Kannala-Brandt / equidistant, ``dist = (k1, k2, k3, k4)``: a ray at angle theta
      from the axis lands at radius ``theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 +
      k4 theta^8)`` on the normalised plane (``cv2.fisheye.projectPoints``, no skew).

    Everything else (poses, homographies, line fits) works on undistorted normalised coordinates
    ``(x/z, y/z)``, which both models map to and from; rays at or beyond 90 degrees have none.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple = field(default=(0.0, 0.0, 0.0, 0.0, 0.0))
    model: str = "pinhole"

    def __post_init__(self):
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"camera width/height must be positive, got {self.width}x{self.height}")
        if not (self.fx > 0 and self.fy > 0):
            raise ValueError(f"camera fx, fy must be positive, got {self.fx}, {self.fy}")
        if self.model not in CAMERA_MODELS:
            raise ValueError(f"camera model must be one of {sorted(CAMERA_MODELS)}, got {self.model!r}")
        d = tuple(float(v) for v in self.dist)
        if self.model == "fisheye" and d == (0.0,) * 5:
            d = (0.0,) * 4  # the default of the dataclass is the pinhole's
        n = CAMERA_MODELS[self.model]
        if len(d) != n:
            names = "k1 k2 p1 p2 k3" if self.model == "pinhole" else "k1 k2 k3 k4"
            raise ValueError(f"camera dist must have {n} values for the {self.model} model ({names}), got {len(d)}")
        object.__setattr__(self, "dist", d)

    # -- construction / io
    @classmethod
    def from_hfov(cls, width: int, height: int, hfov_rad: float, dist=(0, 0, 0, 0, 0),
                  model: str = "pinhole") -> "Camera":
        """Square pixels, principal point at the image centre, horizontal field of view given (of the
        pinhole, or for ``fisheye`` of the equidistant projection before its ``k`` terms)."""
        f = focal_from_hfov(width, hfov_rad) if model == "pinhole" else focal_from_hfov_equidistant(width, hfov_rad)
        return cls(width, height, f, f, (width - 1) / 2.0, (height - 1) / 2.0, tuple(dist), model)

    def to_dict(self) -> dict:
        return {"width": self.width, "height": self.height, "fx": self.fx, "fy": self.fy,
                "cx": self.cx, "cy": self.cy, "model": self.model, "dist": list(self.dist)}

    @classmethod
    def from_dict(cls, d: dict) -> "Camera":
        model = str(d.get("model", "pinhole"))
        dist = d.get("dist", (0,) * CAMERA_MODELS.get(model, 5))
        return cls(int(d["width"]), int(d["height"]), float(d["fx"]), float(d["fy"]),
                   float(d["cx"]), float(d["cy"]), tuple(dist), model)

    @classmethod
    def from_json(cls, path) -> "Camera":
        return cls.from_dict(json.loads(Path(path).read_text()))

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def has_distortion(self) -> bool:
        """Whether pixels differ from the ideal pinhole's (always so for a fisheye)."""
        return self.model != "pinhole" or any(abs(v) > 0 for v in self.dist)

    @property
    def conventions(self) -> str:
        """The one-line description of this camera's conventions that ``camera.json`` carries."""
        lens = ("OpenCV pinhole + (k1 k2 p1 p2 k3)" if self.model == "pinhole"
                else "OpenCV fisheye (Kannala-Brandt: theta_d = theta (1 + k1 theta^2 + .. + k4 theta^8))")
        return f"{lens}; pixel centre of top-left pixel at (0,0); T_B_C maps camera (OpenCV) to body (FLU)"

    @property
    def size_wh(self) -> tuple:
        return (self.width, self.height)

    def scaled(self, factor: float) -> "Camera":
        """The same camera at ``factor`` times the resolution (pixel-centre convention kept)."""
        return replace(self, width=int(round(self.width * factor)), height=int(round(self.height * factor)),
                       fx=self.fx * factor, fy=self.fy * factor,
                       cx=(self.cx + 0.5) * factor - 0.5, cy=(self.cy + 0.5) * factor - 0.5)

    def shifted(self, x0: float, y0: float) -> "Camera":
        """The same camera seeing the crop whose top-left pixel is ``(x0, y0)``."""
        return replace(self, cx=self.cx - x0, cy=self.cy - y0)

    def without_distortion(self) -> "Camera":
        return Camera(self.width, self.height, self.fx, self.fy, self.cx, self.cy)

    # -- normalised-plane distortion
    def distort_normalized(self, xy) -> np.ndarray:
        """Apply the lens model to ``(N, 2)`` undistorted normalised coordinates."""
        xy = as_points(xy, 2, "xy")
        if self.model == "fisheye":
            r = np.hypot(xy[:, 0], xy[:, 1])
            th = np.arctan(r)
            th2 = th * th
            k1, k2, k3, k4 = self.dist
            th_d = th * (1 + th2 * (k1 + th2 * (k2 + th2 * (k3 + th2 * k4))))
            with np.errstate(divide="ignore", invalid="ignore"):
                s = np.where(r > 1e-12, th_d / np.where(r > 1e-12, r, 1.0), 1.0)
            return xy * s[:, None]
        k1, k2, p1, p2, k3 = self.dist
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return np.column_stack([xd, yd])

    def undistort_normalized(self, xy_d, iterations: int = 20) -> np.ndarray:
        """Invert :meth:`distort_normalized` by Newton / Gauss-Newton (~1e-12 in the lens's domain).

        Fisheye points whose ray would be at 90 degrees or more from the axis come back as NaN."""
        xy_d = as_points(xy_d, 2, "xy_d")
        if not self.has_distortion:
            return xy_d.copy()
        if self.model == "fisheye":
            return self._undistort_fisheye(xy_d, iterations)
        k1, k2, p1, p2, k3 = self.dist
        xy = xy_d.copy()
        for _ in range(iterations):
            x, y = xy[:, 0], xy[:, 1]
            r2 = x * x + y * y
            radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
            dradial = k1 + r2 * (2 * k2 + 3 * k3 * r2)  # d radial / d r2
            fx_ = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) - xy_d[:, 0]
            fy_ = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y - xy_d[:, 1]
            a = radial + 2 * x * x * dradial + 2 * p1 * y + 6 * p2 * x
            b = 2 * x * y * dradial + 2 * p1 * x + 2 * p2 * y
            c = 2 * x * y * dradial + 2 * p1 * x + 2 * p2 * y
            d = radial + 2 * y * y * dradial + 6 * p1 * y + 2 * p2 * x
            det = a * d - b * c
            det = np.where(np.abs(det) < 1e-12, 1e-12, det)
            dx = (d * fx_ - b * fy_) / det
            dy = (-c * fx_ + a * fy_) / det
            xy[:, 0] -= dx
            xy[:, 1] -= dy
            if np.max(np.abs(dx) + np.abs(dy)) < 1e-14:
                break
        return xy

    def _undistort_fisheye(self, xy_d: np.ndarray, iterations: int) -> np.ndarray:
        k1, k2, k3, k4 = self.dist
        rd = np.hypot(xy_d[:, 0], xy_d[:, 1])
        th = np.minimum(rd, 1.5)  # theta_d ~ theta near the axis
        for _ in range(max(iterations, 30)):
            th2 = th * th
            f = th * (1 + th2 * (k1 + th2 * (k2 + th2 * (k3 + th2 * k4)))) - rd
            df = 1 + th2 * (3 * k1 + th2 * (5 * k2 + th2 * (7 * k3 + th2 * 9 * k4)))
            step = f / np.where(np.abs(df) < 1e-12, 1e-12, df)
            th = np.clip(th - step, 0.0, math.pi)
            if np.max(np.abs(step), initial=0.0) < 1e-15:
                break
        th2 = th * th
        ok = (np.abs(th * (1 + th2 * (k1 + th2 * (k2 + th2 * (k3 + th2 * k4)))) - rd) < 1e-9) & (th < math.pi / 2)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(rd > 1e-12, np.tan(th) / np.where(rd > 1e-12, rd, 1.0), 1.0)
        out = xy_d * s[:, None]
        out[~ok] = np.nan
        return out

    # -- pixels
    def project(self, points_C) -> np.ndarray:
        """``(N, 3)`` points in the camera frame -> ``(N, 2)`` distorted pixels (NaN behind the camera)."""
        P = as_points(points_C, 3, "points_C")
        z = P[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = P[:, :2] / z[:, None]
        xy = self.distort_normalized(xy)
        px = np.column_stack([self.fx * xy[:, 0] + self.cx, self.fy * xy[:, 1] + self.cy])
        px[z <= 0] = np.nan
        return px

    def project_from(self, cam2frame, points_F) -> np.ndarray:
        """Project points given in frame F, with the camera pose ``T_F_C`` (e.g. ``cam2pad``)."""
        return self.project(transform_points(invert(cam2frame), points_F))

    def normalized_from_pixels(self, px) -> np.ndarray:
        """Distorted pixels -> undistorted normalised coordinates ``(x/z, y/z)``."""
        px = as_points(px, 2, "px")
        xy_d = np.column_stack([(px[:, 0] - self.cx) / self.fx, (px[:, 1] - self.cy) / self.fy])
        return self.undistort_normalized(xy_d)

    def undistort_pixels(self, px) -> np.ndarray:
        """Distorted pixels -> pixels of the ideal pinhole camera with the same K."""
        xy = self.normalized_from_pixels(px)
        return np.column_stack([self.fx * xy[:, 0] + self.cx, self.fy * xy[:, 1] + self.cy])

    def distort_pixels(self, px) -> np.ndarray:
        """Pixels of the ideal pinhole camera with the same K -> distorted pixels (the inverse of
        :meth:`undistort_pixels`)."""
        px = as_points(px, 2, "px")
        return self.project(np.column_stack([(px[:, 0] - self.cx) / self.fx, (px[:, 1] - self.cy) / self.fy,
                                             np.ones(len(px))]))

    def ideal_pixel_grid(self) -> np.ndarray:
        """``(H, W, 2)`` float64: every pixel's place in the ideal pinhole image (itself without
        distortion); to warp a drawing made for the pinhole through the lens."""
        u, v = np.meshgrid(np.arange(self.width, dtype=np.float64), np.arange(self.height, dtype=np.float64))
        px = np.column_stack([u.ravel(), v.ravel()])
        und = self.undistort_pixels(px) if self.has_distortion else px
        return und.reshape(self.height, self.width, 2)

    def unproject(self, px, depth) -> np.ndarray:
        """Distorted pixels and z-depths -> ``(N, 3)`` points in the camera frame."""
        xy = self.normalized_from_pixels(px)
        z = np.broadcast_to(np.asarray(depth, dtype=np.float64), (xy.shape[0],))
        return np.column_stack([xy * z[:, None], z])

    def in_image(self, px, margin: float = 0.0) -> np.ndarray:
        """Boolean mask of pixels inside the image (pixel centres from 0 to size-1), with a margin."""
        px = as_points(px, 2, "px")
        with np.errstate(invalid="ignore"):
            return ((px[:, 0] >= -0.5 + margin) & (px[:, 0] <= self.width - 0.5 - margin)
                    & (px[:, 1] >= -0.5 + margin) & (px[:, 1] <= self.height - 0.5 - margin))


@functools.lru_cache(maxsize=8)
def ideal_grid(camera: Camera, step: int = 1, dtype=np.float64) -> np.ndarray:
    """``(ny, nx, 2)``: where every ``step``-th pixel of ``camera``'s frame lies in the ideal pinhole
    image (:meth:`Camera.ideal_pixel_grid` at ``step`` 1; past 1, from pixel 0 to one node past the
    frame's right and bottom edges), made once per camera and kept: undistorting a 1280x720 frame's every
    pixel takes 0.6 s, and the texture, the smeared drawing and the flow each warp through it.
    Shared: read it, do not write to it."""
    if step == 1:
        return camera.ideal_pixel_grid().astype(dtype, copy=False)
    u, v = np.meshgrid(np.arange(0, camera.width + step, step, dtype=np.float64),
                       np.arange(0, camera.height + step, step, dtype=np.float64))
    g = np.column_stack([u.ravel(), v.ravel()])
    return (camera.undistort_pixels(g) if camera.has_distortion else g).reshape(u.shape + (2,)).astype(dtype, copy=False)
