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

from .geometry import Camera, so3_exp


@dataclass(frozen=True)
class Twist:
    """The camera's motion: ``v_P`` its velocity in the pad frame (m/s), ``w_C`` its angular rate
    in its own frame (rad/s, ``R_P_C(t + dt) = R_P_C(t) exp(w_C dt)``); either may be unknown."""

    v_P: np.ndarray | None
    w_C: np.ndarray | None

    def moved(self, cam2pad: np.ndarray, dt: float) -> np.ndarray:
        """``T_P_C`` ``dt`` seconds after ``cam2pad`` under this motion (an unknown part: none)."""
        T = np.array(cam2pad, np.float64, copy=True)
        if self.v_P is not None:
            T[:3, 3] += np.asarray(self.v_P, np.float64) * dt
        if self.w_C is not None:
            T[:3, :3] = T[:3, :3] @ so3_exp(np.asarray(self.w_C, np.float64) * dt)
        return T


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


VELOCITY_Q_IMU = 0.05  # m^2/s^3: what the IMU's rows leave unknown of the motion relative to the pad (~0.2 m/s^2 over a second: bias, tilt, heading)
VELOCITY_Q_FREE = 4.0  # m^2/s^3: a drone's manoeuvres (2 m/s^2 over a second) where no rows cover the time
VELOCITY_PRIOR_MPS = 1.0  # per axis: the velocity relative to the pad before two poses have told it
ACCEL_BIAS_PRIOR_MPS2 = 0.2  # per axis: the IMU's acceleration error (its bias, the AHRS's tilt x g) before poses tell it
ACCEL_BIAS_WALK = 0.02  # m/s^2 per sqrt(s): how fast that error drifts


def _key_jump(S, S_old, chained: bool) -> np.ndarray:
    """The covariance of the jump in a pose's shared error where its key changes from one of
    covariance ``S_old`` to one of ``S`` (either ``None``: none shared): both, for keys whose errors
    are unrelated; for a key renewed from a pose of the old one (``chained``), only what it adds
    to it (``S - S_old``, its negative part dropped).

    A chain of keyframes carries its first key's error in every later one.  Counted afresh at each
    renewal, it cut the filter loose from the poses wherever the flow renewed its keyframe every
    frame (a 5 Hz descent below 0.3 m: a keyframe's doubt of 20 mm, its poses 1-3 mm off); the
    filter then ran on the IMU's accelerations alone, and a vibrating airframe's put the flow's
    guess 60-180 px off (the airframe suite's a_slow_vibrating)."""
    S = None if S is None else np.asarray(S, np.float64)[:3, :3]
    S_old = None if S_old is None else np.asarray(S_old, np.float64)[:3, :3]
    if chained and S is not None and S_old is not None:
        w, V = np.linalg.eigh(0.5 * ((S - S_old) + (S - S_old).T))
        return (V * np.clip(w, 0.0, None)) @ V.T
    return sum((c for c in (S, S_old) if c is not None), np.zeros((3, 3)))


class VelocityFilter:
    """The camera's position and velocity relative to the pad (pad frame), for the shutter's correction.

    A Kalman filter of nine states: position, velocity, and the error in the IMU's acceleration (its
    bias; the AHRS's tilt, which turns gravity into an acceleration the drone does not have).  The
    IMU's accelerations between frames carry it (where its rows cover the time; else it coasts,
    less sure), and each accepted pose corrects it by its position, as sure as that pose's
    covariance says, each read as its solver answers the velocity (``p - M v``: a rolling-shutter
    pose's velocity-free twin keeps the rows' skew).  A pose's error that it shares with others (a
    flow pose's keyframe's) is told apart: constant while its key is, it moves the position alone
    where the key changes.

    A line through the last poses weighed every pose alike: at 5 Hz two poses 0.2 s apart, each
    50-100 mm off at 7 m (a small pad far off, its tilt barely seen), made a velocity 0.5 m/s off,
    and its unrolling moved the next poses as much again (the airframe suite's 5 Hz camera).
    Weighed, far poses barely move the velocity and near ones (1 mm off at 0.3 m) set it.  The
    filter forgets everything after ``max_gap_s`` without a pose (``coast_s`` where the IMU's rows
    carry it: below), and a pose or covariance that is not finite starts it again (nothing is
    learnt from it).

    ``predict(t, motion)`` before a frame (``motion``: the IMU's ``(dv, dp)`` since the last pose,
    in the pad frame, or ``None``), ``update(t, p, cov)`` with the frame's accepted position;
    ``velocity`` is the prediction's, once two poses are in.

    Past ``max_gap_s`` and up to ``coast_s`` without a pose, the IMU's rows still carry the last
    state to the frame (:attr:`coast`, for a guess of where the pad is: :meth:`position`, once two
    poses are in), and the next pose updates it as any prediction; no velocity is read from a
    coasting state (the shutter's correction).  A single pose's state coasts too, its velocity
    unknown: a camera at 2 Hz has no two poses within ``max_gap_s``, and started again at every
    pose its filter never had a velocity (unseen84: the pad's drawing and the smear's doubt had
    none to go by, and one descent lost its last 8 frames).  Without the rows, or past
    ``coast_s``, the next pose starts it again.  (Tried in b004f14 and withdrawn in f67181f: a
    flow chain on unseen85 went 3-6 mm off stating 1.8; that was RANSAC keeping a chance subset
    of noisy tracks, mended in 7511434, not the filter.)"""

    def __init__(self, max_gap_s: float, q_imu: float = VELOCITY_Q_IMU, q_free: float = VELOCITY_Q_FREE,
                 coast_s: float = 0.0):
        self.max_gap_s, self.q_imu, self.q_free = float(max_gap_s), float(q_imu), float(q_free)
        self.coast_s = max(float(coast_s), self.max_gap_s)
        self.reset()

    def reset(self) -> None:
        self.t: float | None = None   # the last pose's time
        self.x = np.zeros(9)          # position, velocity, the IMU's acceleration error (pad frame) at t
        self.P = np.zeros((9, 9))
        self.n = 0                    # poses since the filter started
        self.pred: tuple | None = None  # (t, x, P) predicted for the frame at hand
        self.coast: tuple | None = None  # ... the same past max_gap_s, carried by the IMU's rows alone
        self.shared: tuple = (None, None)  # the last pose's error shared with others: (what names it, its covariance)

    def predict(self, t: float, motion=None, q_extra: float = 0.0) -> None:
        self.pred = self.coast = None
        if self.t is None:
            return
        D = t - self.t
        if self.max_gap_s < D <= self.coast_s and motion is not None:
            self.coast = (t, *self._propagated(D, motion, q_extra))
            return
        if not 0.0 < D <= self.max_gap_s:
            if D > self.coast_s or D <= 0.0:
                self.reset()
            return
        self.pred = (t, *self._propagated(D, motion, q_extra))

    def position(self, t: float):
        """``(p, P, v)``: the position for ``t`` (predicted within the gap or coasting on the IMU's
        rows, or the estimate once a pose at ``t`` updated it), its covariance and the velocity
        there; ``None`` before two poses or for another time."""
        x_t = self._state(t)
        return None if x_t is None else (x_t[1][:3].copy(), x_t[2][:3, :3].copy(), x_t[1][3:6].copy())

    def velocity_doubt(self, t: float):
        """``(3, 3)``: the covariance of the velocity :meth:`position` gives for ``t``; ``None`` where
        it gives none."""
        x_t = self._state(t)
        return None if x_t is None else x_t[2][3:6, 3:6].copy()

    def _state(self, t: float):
        """``(t, x, P)`` for ``t``: the prediction, the coast, or the last pose's estimate, whichever
        is for that time; ``None`` before two poses or for another time."""
        for x_t in (self.pred, self.coast, (self.t, self.x, self.P)):
            if x_t is not None and x_t[0] is not None and self.n >= 2 and abs(x_t[0] - t) < 1e-9:
                return x_t
        return None

    def _propagated(self, D: float, motion, q_extra: float):
        F = np.eye(9)
        F[:3, 3:6] = D * np.eye(3)
        q = self.q_free
        if motion is not None:  # the rows' integral, less the error they carry
            dv, dp = motion
            F[:3, 6:] = -0.5 * D * D * np.eye(3)
            F[3:6, 6:] = -D * np.eye(3)
            q = self.q_imu + q_extra
        x = F @ self.x
        if motion is not None:
            x[:3] += dp
            x[3:6] += dv
        Q = np.zeros((9, 9))
        Q[:6, :6] = np.kron(np.array([[D ** 3 / 3.0, D ** 2 / 2.0], [D ** 2 / 2.0, D]]) * q, np.eye(3))
        Q[6:, 6:] = ACCEL_BIAS_WALK ** 2 * D * np.eye(3)
        return x, F @ self.P @ F.T + Q

    @property
    def velocity(self) -> np.ndarray | None:
        return self.pred[1][3:6].copy() if self.pred is not None and self.n >= 2 else None

    @property
    def velocity_cov(self) -> np.ndarray | None:
        """``(3, 3)``: how far :attr:`velocity` may be off (the prediction's covariance), where it is given."""
        return self.pred[2][3:6, 3:6].copy() if self.pred is not None and self.n >= 2 else None

    def update(self, t: float, p, cov, shared=(None, None), dv=None) -> None:
        """``p``: a position measured as ``p = position - dv @ velocity`` (``dv``, 3x3, m per m/s: a
        rolling-shutter pose's velocity-free twin answers the velocity by its own solver's skew;
        ``None``: zero).  ``cov``: its own doubt; ``shared``: ``(key, covariance)`` of an error it
        shares with the poses of the same ``key`` (a flow pose's keyframe's): constant while the key
        is, it moves the position alone where the key changes.  ``(key, covariance, parent)``: a key
        renewed from the pose of one of ``parent``'s (a chained keyframe): its error is that key's
        and the pose's own, so where it follows ``parent`` the position jumps by the difference of
        their covariances alone, not by both."""
        p = np.asarray(p, np.float64)
        R = np.asarray(cov, np.float64)[:3, :3]
        key, S = shared[:2]
        parent = shared[2] if len(shared) > 2 else None
        M = np.zeros((3, 3)) if dv is None else np.asarray(dv, np.float64).reshape(3, 3)
        if not (np.isfinite(p).all() and np.isfinite(R).all() and (S is None or np.isfinite(S).all())
                and np.isfinite(M).all()):
            self.reset()
            return
        H = np.hstack([np.eye(3), -M, np.zeros((3, 3))])
        pred = next((c for c in (self.pred, self.coast) if c is not None and abs(c[0] - t) < 1e-9), None)
        if pred is not None:  # (carried through a gap by the IMU's rows, the state goes on from there)
            _, x, P = pred
            if key is None or key != self.shared[0]:  # the shared error changed: the position jumps by it
                P = P.copy()
                P[:3, :3] += _key_jump(S, self.shared[1], parent is not None and parent == self.shared[0])
            PH = P @ H.T
            K = PH @ np.linalg.inv(H @ PH + R)
            x = x + K @ (p - H @ x)
            P = P - K @ PH.T
            self.x, self.P, self.n = x, 0.5 * (P + P.T), self.n + 1
        else:  # the first pose (or the first after a gap): where it is, the velocity not known
            self.x = np.concatenate([p, np.zeros(6)])
            Pv = VELOCITY_PRIOR_MPS ** 2 * np.eye(3)
            self.P = np.zeros((9, 9))
            self.P[:3, :3] = R + (0.0 if S is None else np.asarray(S, np.float64)[:3, :3]) + M @ Pv @ M.T
            self.P[:3, 3:6] = M @ Pv
            self.P[3:6, :3] = Pv @ M.T
            self.P[3:6, 3:6] = Pv
            self.P[6:, 6:] = ACCEL_BIAS_PRIOR_MPS2 ** 2 * np.eye(3)
            self.n = 1
        self.t, self.pred, self.coast, self.shared = t, None, None, (key, S)
