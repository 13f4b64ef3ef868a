"""Rolling shutter: each row of a frame is exposed at its own time, and a pose is that of one row.

A rolling-shutter sensor reads its rows one after another, ``line_s`` apart: row ``r`` of a frame
stamped ``t`` is exposed at ``t + (r - ref_row) * line_s`` (the dataset's convention, DESIGN.md;
the labels are the pose at ``ref_row``'s time).  While the camera moves, every point is seen where
it was at its own row's time: a 1080p sensor read in 21.6 ms, descending at 0.5 m/s at 0.6 m,
sees its image's top and bottom rows 1 % apart in scale, 4 to 5 px at the edges.  A pose fitted to
those pixels as if they were one instant is off by millimetres with a fit that shows nothing
wrong, so its covariance is too small (bench_v2's x_field_rs_oblique: 100 % of touchdown poses
beyond their 3 sigma).

:func:`unrolled` moves each pixel to where the point was at ``ref_row``'s time, to first order in
the camera's motion (its velocity relative to the pad and its angular rate, a ``Twist``): the
pose is then fitted as for a global shutter.  Over the ~10 ms between a row and the reference
row the first order is exact to a few hundredths of a pixel at the rates a drone turns.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import Camera


@dataclass(frozen=True)
class Twist:
    """The camera's motion: ``v_P`` its velocity in the pad frame (m/s), ``w_C`` its angular rate
    in its own frame (rad/s, ``R_P_C(t + dt) = R_P_C(t) exp(w_C dt)``); either may be unknown."""

    v_P: np.ndarray | None
    w_C: np.ndarray | None


@dataclass(frozen=True)
class RollingShutter:
    line_s: float     # time between consecutive rows (s); 0 for a global shutter
    ref_row: float    # the row whose time a frame's stamp (and its pose) is

    @property
    def active(self) -> bool:
        return self.line_s != 0.0

    def shift(self, camera: Camera, cam2pad: np.ndarray, pts_P: np.ndarray, px: np.ndarray, twist: Twist) -> np.ndarray:
        """``(N, 2)``: how far each point's pixel moved from ``ref_row``'s time to its own row's
        (read off its observed pixel ``px``), the camera at ``cam2pad`` at ``ref_row``'s time."""
        pts_P = np.asarray(pts_P, np.float64).reshape(-1, 3)
        dt = (np.asarray(px, np.float64).reshape(-1, 2)[:, 1] - self.ref_row) * self.line_s
        R, p = cam2pad[:3, :3], cam2pad[:3, 3]
        X0 = (pts_P - p) @ R  # the points in the camera frame at the reference time
        # at t + dt: R' = R exp(w dt), p' = p + v dt, so X = exp(-w dt) R^T (P - p - v dt), to first order
        dX = np.zeros_like(X0)
        if twist.w_C is not None:
            dX -= np.cross(np.asarray(twist.w_C, np.float64), X0)
        if twist.v_P is not None:
            dX -= np.asarray(twist.v_P, np.float64) @ R
        return camera.project(X0 + dX * dt[:, None]) - camera.project(X0)

    def unrolled(self, camera: Camera, cam2pad: np.ndarray | None, pts_P: np.ndarray, px: np.ndarray,
                 twist: Twist | None) -> np.ndarray:
        """``px`` moved to where each point was at ``ref_row``'s time (``px`` itself where nothing
        is known to move it: no motion, no pose, a point behind the camera)."""
        px = np.asarray(px, np.float64)
        if not self.active or twist is None or cam2pad is None or (twist.v_P is None and twist.w_C is None):
            return px
        d = self.shift(camera, cam2pad, pts_P, px, twist)
        return np.where(np.isfinite(d), px - d, px)
