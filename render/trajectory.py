"""Continuous-time landing trajectories: one model gives poses, velocities, accelerations and
angular rates, so labels, motion blur and IMU data agree.

A trajectory is the body's path relative to the pad (pad-aligned ENU axes; the platform moves
at a constant velocity) plus a heading.  A deck may also heave, roll and pitch (:class:`DeckMotion`):
the descent follows its heave (a deck-tracking controller; the path's heights stay heights above
the pad's centre) but not its roll and pitch, which tilt the pad about its centre.  Attitude is what a multirotor flies: the thrust axis (body z)
follows the total acceleration plus gravity, body x follows the heading (Mellinger et al. 2011).
Gusts are smooth sums of sinusoids added to the path, so the tilt follows them too.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hvloc.geometry import GRAVITY_MPS2 as GRAVITY, make_transform, so3_log
MAX_TILT_DEG = 90.0  # how far a planned flight may tilt the body: past it the thrust points down, the drone upside down


def min_snap(tau):
    """Rest-to-rest minimum-snap profile on [0, 1]: 0 -> 1 with zero velocity, acceleration and jerk
    at both ends.  The attitude follows the acceleration, so the body's rate follows the jerk: joined
    end to end (keyframes, a move that ends before the descent does), these profiles keep the rate
    continuous.  Minimum-jerk ones (render revisions up to 13) end with a jerk of 60 x the move over
    its duration cubed: the rate stepped at every join (4.7 rad/s between two 200 Hz IMU rows on a
    hover-and-correct descent), an angular acceleration no multirotor makes."""
    t = np.clip(tau, 0.0, 1.0)
    return t**4 * (35 - 84 * t + 70 * t * t - 20 * t**3)


class KeyframePath:
    """Piecewise rest-to-rest minimum-snap between keyframes ``(t, x, y, z, yaw)``."""

    def __init__(self, keys):
        k = np.asarray(keys, np.float64)
        if k.ndim != 2 or k.shape[1] != 5 or np.any(np.diff(k[:, 0]) <= 0):
            raise ValueError("keyframes must be (t, x, y, z, yaw) rows with increasing t")
        self.k = k

    @property
    def duration(self) -> float:
        return float(self.k[-1, 0])

    def __call__(self, t):
        t = np.asarray(t, np.float64)
        k = self.k
        i = np.clip(np.searchsorted(k[:, 0], t, side="right") - 1, 0, len(k) - 2)
        t0, t1 = k[i, 0], k[i + 1, 0]
        s = min_snap((t - t0) / (t1 - t0))[..., None]
        v = k[i, 1:] + s * (k[i + 1, 1:] - k[i, 1:])
        return v[..., :3], v[..., 3]


@dataclass
class Gusts:
    amp: np.ndarray    # (n, 3) acceleration amplitudes, m/s^2
    omega: np.ndarray  # (n,) rad/s
    phase: np.ndarray  # (n, 3)
    fade_in: float
    fade_out_start: float
    fade_out_end: float

    def displacement(self, t):
        t = np.asarray(t, np.float64)[..., None, None]
        # a displacement whose acceleration has amplitude amp: d = -amp / w^2 sin(w t + phi)
        d = (self.amp / self.omega[:, None] ** 2 * np.sin(self.omega[:, None] * t + self.phase)).sum(axis=-2)
        # the envelope is a product of two smooth ramps: smooth also where they overlap (descents
        # shorter than fade-in plus fade-out).  It used to ramp a product of a linear ramp, whose
        # kink then reached the acceleration as a spike: a 54 deg tilt for one frame of a 4 s descent.
        ramp_in = min_snap(np.clip(t[..., 0, 0] / max(self.fade_in, 1e-9), 0, 1))
        ramp_out = min_snap(1 - min_snap((t[..., 0, 0] - self.fade_out_start)
                                         / max(self.fade_out_end - self.fade_out_start, 1e-9)))
        return d * (ramp_in * ramp_out)[..., None]


@dataclass
class DeckMotion:
    """A ship's deck under the pad: heave (metres, up), roll (about the pad's x), pitch (about its y)
    and yaw (about its normal), each a sinusoid of its own amplitude, period and phase.
    ``R_W_P = R_z(yaw) R_y(pitch) R_x(roll)``."""

    roll_rad: float = 0.0
    pitch_rad: float = 0.0
    heave_m: float = 0.0
    periods_s: tuple = (8.0, 6.0, 7.0)  # roll, pitch, heave (, yaw)
    phases: tuple = (0.0, 0.0, 0.0)     # (the same)
    yaw_rad: float = 0.0

    def _wave(self, i: int, t):
        w = 2 * math.pi / self.periods_s[i]
        return np.sin(w * np.asarray(t, np.float64) + self.phases[i])

    def heave(self, t) -> np.ndarray:
        return self.heave_m * self._wave(2, t)

    def heave_rate(self, t) -> np.ndarray:
        w = 2 * math.pi / self.periods_s[2]
        return self.heave_m * w * np.cos(w * np.asarray(t, np.float64) + self.phases[2])

    def rotations(self, t) -> np.ndarray:
        """``R_W_P`` (N, 3, 3) at times ``t``."""
        t = np.atleast_1d(np.asarray(t, np.float64))
        r, p = self.roll_rad * self._wave(0, t), self.pitch_rad * self._wave(1, t)
        cr, sr, cp, sp = np.cos(r), np.sin(r), np.cos(p), np.sin(p)
        z, o = np.zeros_like(t), np.ones_like(t)
        Rx = np.stack([np.stack([o, z, z], -1), np.stack([z, cr, -sr], -1), np.stack([z, sr, cr], -1)], -2)
        Ry = np.stack([np.stack([cp, z, sp], -1), np.stack([z, o, z], -1), np.stack([-sp, z, cp], -1)], -2)
        if not self.yaw_rad:
            return Ry @ Rx
        y = self.yaw_rad * self._wave(3, t)
        cy, sy = np.cos(y), np.sin(y)
        Rz = np.stack([np.stack([cy, -sy, z], -1), np.stack([sy, cy, z], -1), np.stack([z, z, o], -1)], -2)
        return Rz @ Ry @ Rx


@dataclass
class TrajectoryState:
    """Arrays over N times.  ``R_W_B`` (N, 3, 3); vectors (N, 3); ``omega_B`` body rates, rad/s."""

    t: np.ndarray
    pos_W: np.ndarray
    vel_W: np.ndarray
    acc_W: np.ndarray
    R_W_B: np.ndarray
    omega_B: np.ndarray
    pad_W: np.ndarray  # (N, 3) pad origin in the world


def attitude_from_acc(acc_W: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Body-to-world rotations of a multirotor with total acceleration ``acc_W`` and heading ``yaw``."""
    thrust = acc_W + np.array([0.0, 0.0, GRAVITY])
    zb = thrust / np.linalg.norm(thrust, axis=-1, keepdims=True)
    xc = np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], axis=-1)
    yb = np.cross(zb, xc)
    yb /= np.linalg.norm(yb, axis=-1, keepdims=True)
    xb = np.cross(yb, zb)
    return np.stack([xb, yb, zb], axis=-1)


class Trajectory:
    """``path(t) -> (pos_rel (N,3), yaw (N,))`` relative to the pad; platform moving at ``pad_vel``."""

    def __init__(self, path, duration: float, gusts: Gusts | None, pad_height: float, pad_vel=(0.0, 0.0),
                 family: str = "", aim_axis_B=None, body_above_cam: float = 0.0, deck: DeckMotion | None = None):
        self.path, self.duration, self.gusts = path, float(duration), gusts
        self.deck = deck
        self.pad_height, self.pad_vel, self.family = pad_height, np.asarray(pad_vel, float), family
        # an off-nadir camera looks at the pad: the path moves back by where its optical axis meets the pad plane
        self.aim_axis_B = None if aim_axis_B is None else np.asarray(aim_axis_B, float) / np.linalg.norm(aim_axis_B)
        self.body_above_cam = float(body_above_cam)

    def _rel(self, t):
        p, yaw = self.path(t)
        if self.aim_axis_B is not None:
            d = self.aim_axis_B
            c, s = np.cos(yaw), np.sin(yaw)
            dx, dy = c * d[0] - s * d[1], s * d[0] + c * d[1]
            reach = (p[..., 2] - self.body_above_cam) / max(-d[2], 0.2)  # along the axis to the pad plane
            p = p - np.stack([dx * reach, dy * reach, np.zeros_like(reach)], axis=-1)
        if self.gusts is not None:
            p = p + self.gusts.displacement(t)
        if self.deck is not None and self.deck.heave_m > 0:  # the descent follows the deck's heave
            p = p + np.stack([np.zeros_like(p[..., 2]), np.zeros_like(p[..., 2]), self.deck.heave(t)], axis=-1)
        return p, yaw

    def pad_origin(self, t) -> np.ndarray:
        """The deck's mean position (``(N, 3)``, world): its constant velocity, without its heave."""
        t = np.asarray(t, np.float64)
        return np.stack([self.pad_vel[0] * t, self.pad_vel[1] * t, np.full_like(t, self.pad_height)], axis=-1)

    def pad_velocities(self, t) -> np.ndarray:
        """``(N, 3)`` the pad centre's velocity in the world: the platform's, plus the deck's heave."""
        t = np.atleast_1d(np.asarray(t, np.float64))
        v = np.tile(np.append(self.pad_vel, 0.0), (len(t), 1))
        if self.deck is not None:
            v[:, 2] = self.deck.heave_rate(t)
        return v

    @property
    def pad_moves(self) -> bool:
        """Whether the pad moves at all: the platform's velocity, or a deck's motion (one is given only
        where the spec's deck moves: render.plan)."""
        return bool(np.any(self.pad_vel != 0)) or self.deck is not None

    def state(self, t, h: float = 1e-3) -> TrajectoryState:
        t = np.atleast_1d(np.asarray(t, np.float64))
        p0, pm, pp, acc, R = self._attitude(t, h)
        vel = (pp - pm) / (2 * h) + np.append(self.pad_vel, 0.0)
        Rm = self._attitude(t - h)[-1]
        Rp = self._attitude(t + h)[-1]
        omega = np.stack([so3_log(a.T @ b) for a, b in zip(Rm, Rp)]) / (2 * h)
        pad = self.pad_origin(t)
        centre = pad.copy()
        if self.deck is not None:
            centre[:, 2] += self.deck.heave(t)
        return TrajectoryState(t, p0 + pad, vel, acc, R, omega, centre)

    def _attitude(self, t, h: float = 1e-3) -> tuple:
        """``(p, p(t - h), p(t + h), acc, R_W_B)`` at times ``t``, positions relative to the pad."""
        p0, yaw = self._rel(t)
        pm, _ = self._rel(t - h)
        pp, _ = self._rel(t + h)
        acc = (pp - 2 * p0 + pm) / (h * h)
        return p0, pm, pp, acc, attitude_from_acc(acc, yaw)

    def body_poses(self, t) -> np.ndarray:
        """``T_W_B`` (N, 4, 4): the poses of :meth:`state`, without its rates (a third of the work)."""
        t = np.atleast_1d(np.asarray(t, np.float64))
        p0, _, _, _, R = self._attitude(t)
        return np.stack([make_transform(Ri, p) for Ri, p in zip(R, p0 + self.pad_origin(t))])

    def pad_poses(self, t) -> np.ndarray:
        """``T_W_P`` (N, 4, 4): the platform's translation, and the deck's heave, roll and pitch about
        the pad's centre."""
        t = np.atleast_1d(np.asarray(t, np.float64))
        o = self.pad_origin(t)
        if self.deck is None:
            return np.stack([make_transform(np.eye(3), p) for p in o])
        o[:, 2] += self.deck.heave(t)
        return np.stack([make_transform(R, p) for R, p in zip(self.deck.rotations(t), o)])


# ----------------------------------------------------------------------------- families

def _descent_profile(tau, h0, h1):
    """Height with a quick start and a slow, careful end (min-snap in a warped time)."""
    return h1 + (h0 - h1) * (1.0 - min_snap(np.clip(tau, 0, 1) ** 0.8))


def make_trajectory(spec, rng: np.random.Generator, family: str, body_above_cam: float,
                    pad_height: float, pad_vel=(0.0, 0.0), optical_axis_B=None,
                    deck: DeckMotion | None = None) -> Trajectory:
    """Draw one trajectory of ``family`` from the spec's ranges with ``rng``.

    Heights in the spec are camera heights above the pad; ``body_above_cam`` converts them to the
    body origin's (the camera hangs below the body by the mount's z offset).
    """
    tr = spec
    u = lambda r: rng.uniform(r[0], r[1]) if r[1] > r[0] else r[0]  # noqa: E731
    h0 = tr.start_height_m + body_above_cam
    h1 = tr.touchdown_height_m + body_above_cam
    D = u(tr.duration_s)
    r0 = u(tr.lateral_offset_m)
    a0 = rng.uniform(0, 2 * math.pi)
    x0, y0 = r0 * math.cos(a0), r0 * math.sin(a0)
    rf = u(tr.final_offset_m)
    af = rng.uniform(0, 2 * math.pi)
    xf, yf = rf * math.cos(af), rf * math.sin(af)
    yaw0 = math.radians(u(tr.yaw_deg))
    dyaw = math.radians(u(tr.yaw_change_deg))

    if family == "straight":
        def path(t):
            tau = np.asarray(t, np.float64) / D
            s_lat = min_snap(tau / 0.7)
            x = x0 + (xf - x0) * s_lat
            y = y0 + (yf - y0) * s_lat
            z = _descent_profile(tau, h0, h1)
            return np.stack([x, y, z], axis=-1), yaw0 + dyaw * min_snap(tau)
        duration = D
    elif family == "spiral":
        turns = u(tr.spiral_turns)
        r_start = max(r0, 1.0)
        def path(t):  # noqa: E306
            tau = np.asarray(t, np.float64) / D
            s = min_snap(tau / 0.85)
            r = r_start * (1 - s)
            th = a0 + 2 * math.pi * turns * s
            x = r * np.cos(th) + xf * s
            y = r * np.sin(th) + yf * s
            z = _descent_profile(tau, h0, h1)
            return np.stack([x, y, z], axis=-1), yaw0 + dyaw * min_snap(tau) + 2 * math.pi * turns * s * 0.5
        duration = D
    elif family == "hover_correct":
        n = int(rng.integers(tr.hover_steps[0], tr.hover_steps[1] + 1))
        heights = h1 + (h0 - h1) * (1 - np.linspace(0, 1, n + 2) ** 0.6)
        keys = [(0.0, x0, y0, h0, yaw0)]
        t = 0.0
        seg = D / (n + 1)
        for i in range(1, n + 1):
            frac = 1 - i / (n + 1)
            err = rng.normal(0, 0.3 * frac * max(r0, 0.5), 2)
            t += seg * 0.75
            keys.append((t, xf + err[0], yf + err[1], heights[i], yaw0 + dyaw * i / (n + 1)))
            t += seg * 0.25  # hover, then correct
            keys.append((t, xf + err[0] * 0.2, yf + err[1] * 0.2, heights[i], yaw0 + dyaw * i / (n + 1)))
        t += seg
        keys.append((t, xf, yf, h1, yaw0 + dyaw))
        path = KeyframePath(keys)
        duration = path.duration
    elif family == "manoeuvres":
        hm = u(tr.manoeuvre_height_m) + body_above_cam
        hm = min(max(hm, h1 + 0.6), h0)
        d = u(tr.manoeuvre_step_m)
        keys = [(0.0, x0, y0, h0, yaw0), (D * 0.8, 0.0, 0.0, hm, yaw0 + dyaw)]
        t, yaw = D * 0.8, yaw0 + dyaw
        fwd = np.array([math.cos(yaw), math.sin(yaw)])
        left = np.array([-fwd[1], fwd[0]])
        moves = [(fwd * d, 0.0), (-fwd * d, 0.0), (left * d, 0.0), (-left * d, 0.0)]
        pos = np.zeros(2)
        z = hm
        for dxy, _ in moves:
            t += 2.0
            keys.append((t, pos[0] + dxy[0], pos[1] + dxy[1], z, yaw))
            t += 0.5
            keys.append((t, pos[0] + dxy[0], pos[1] + dxy[1], z, yaw))
            t += 2.0
            keys.append((t, pos[0], pos[1], z, yaw))
        for dz in (d, -d):  # up, down
            t += 2.0
            keys.append((t, 0.0, 0.0, z + dz, yaw))
        t += 5.0  # a full 360-degree spin
        yaw += 2 * math.pi
        keys.append((t, 0.0, 0.0, z, yaw))
        t += 0.2 * D + 2.0
        keys.append((t, xf, yf, h1, yaw))
        path = KeyframePath(keys)
        duration = path.duration
    else:
        raise ValueError(f"unknown trajectory family {family!r}")

    amp_max = u(tr.gust_accel_mps2)
    gusts = None
    if amp_max > 0:
        ncomp = 3
        amp = rng.uniform(0.3, 1.0, (ncomp, 3)) * amp_max / ncomp
        amp[:, 2] *= 0.3
        gusts = Gusts(amp, rng.uniform(0.6, 3.0, ncomp), rng.uniform(0, 2 * math.pi, (ncomp, 3)),
                      fade_in=2.0, fade_out_start=duration - 4.0, fade_out_end=duration - 0.5)
    aim = optical_axis_B if (spec.aim_camera and optical_axis_B is not None
                             and np.hypot(optical_axis_B[0], optical_axis_B[1]) > 1e-9) else None
    return Trajectory(path, duration, gusts, pad_height, pad_vel, family, aim, body_above_cam, deck)


def steepest_tilt(traj: Trajectory, dt: float = 0.01) -> tuple:
    """``(degrees, t)``: the body's largest tilt from level over the flight (sampled every ``dt``),
    and when.  A descent that has to accelerate downward faster than gravity turns the thrust axis
    over (180 degrees: the drone flies upside down), which no multirotor does."""
    ts = np.linspace(0.0, traj.duration, int(math.ceil(traj.duration / dt)) + 1)
    up = traj.state(ts).R_W_B[:, 2, 2]
    k = int(np.argmin(up))
    return float(np.degrees(np.arccos(np.clip(up[k], -1.0, 1.0)))), float(ts[k])


def angular_rate_check(traj: Trajectory, t0: float, t1: float, n: int = 2000) -> float:
    """Angle (rad) between integrating ``omega_B`` over [t0, t1] and the attitude change (a self-test)."""
    from hvloc.geometry import so3_exp

    ts = np.linspace(t0, t1, n + 1)
    s = traj.state(ts)
    R = s.R_W_B[0].copy()
    dt = ts[1] - ts[0]
    for k in range(n):
        R = R @ so3_exp(0.5 * (s.omega_B[k] + s.omega_B[k + 1]) * dt)
    return float(np.linalg.norm(so3_log(R.T @ s.R_W_B[-1])))
