"""IMU from the trajectory's derivatives: gyro and accelerometer in the body frame (FLU) with
bias, bias random walk and white noise; an AHRS attitude with slow, correlated drift and noise."""
from __future__ import annotations

import math

import numpy as np

from hvloc.geometry import matrix_from_quat_xyzw, quat_xyzw_from_matrix, so3_exp

from .trajectory import GRAVITY, Trajectory

IMU_COLUMNS = ["t", "gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z",
               "ahrs_qx", "ahrs_qy", "ahrs_qz", "ahrs_qw"]
# the true biases inside each sample (what a filter estimates; EuRoC-style ground truth carries them)
IMU_BIAS_COLUMNS = ["gyro_bias_x", "gyro_bias_y", "gyro_bias_z", "accel_bias_x", "accel_bias_y", "accel_bias_z"]
IMU_FILE_COLUMNS = IMU_COLUMNS + IMU_BIAS_COLUMNS


def _random_walk(rng, n, dt, sigma0, walk):
    x = np.empty((n, 3))
    x[0] = rng.normal(0, sigma0, 3)
    if n > 1:
        x[1:] = x[0] + np.cumsum(rng.normal(0, walk * math.sqrt(dt), (n - 1, 3)), axis=0)
    return x


def _ou(rng, n, dt, sigma, tau):
    """Ornstein-Uhlenbeck process, stationary std ``sigma`` (per axis), correlation time ``tau``."""
    a = math.exp(-dt / tau)
    x = np.empty((n, len(sigma)))
    x[0] = rng.normal(0, sigma)
    s = np.asarray(sigma) * math.sqrt(1 - a * a)
    for k in range(1, n):
        x[k] = a * x[k - 1] + rng.normal(0, s)
    return x


def synthesize_imu(traj: Trajectory, spec, rng: np.random.Generator, duration: float) -> np.ndarray:
    """``(N, 17)`` rows in :data:`IMU_FILE_COLUMNS` order at ``spec.rate_hz`` over ``[0, duration]``."""
    dt = 1.0 / spec.rate_hz
    t = np.arange(0.0, duration + 1e-9, dt)
    n = len(t)
    s = traj.state(t)
    gyro_bias = _random_walk(rng, n, dt, spec.gyro_bias_rad_s, spec.gyro_bias_walk_rad_s2)
    gyro = s.omega_B + gyro_bias + rng.normal(0, spec.gyro_noise_rad_s, (n, 3))
    f_W = s.acc_W + np.array([0.0, 0.0, GRAVITY])
    f_B = np.einsum("nji,nj->ni", s.R_W_B, f_W)  # R_W_B^T f_W
    accel_bias = _random_walk(rng, n, dt, spec.accel_bias_mps2, spec.accel_bias_walk_mps3)
    accel = f_B + accel_bias + rng.normal(0, spec.accel_noise_mps2, (n, 3))
    # AHRS error: a slow drift (most of the variance) plus a little white noise, in the body frame
    sig = np.radians([spec.ahrs_roll_pitch_deg, spec.ahrs_roll_pitch_deg, spec.ahrs_yaw_deg])
    err = _ou(rng, n, dt, sig * 0.95, spec.ahrs_drift_time_s) + rng.normal(0, sig * 0.3, (n, 3))
    q = np.stack([quat_xyzw_from_matrix(R @ so3_exp(e)) for R, e in zip(s.R_W_B, err)])
    if spec.vibration_accel_mps2 > 0 or spec.vibration_gyro_rad_s > 0:  # drawn last: a spec without it is unchanged
        vib = vibration(rng, t, spec.vibration_hz)
        gyro = gyro + spec.vibration_gyro_rad_s * vib[:, :3]
        accel = accel + spec.vibration_accel_mps2 * vib[:, 3:]
    return np.column_stack([t, gyro, accel, q, gyro_bias, accel_bias])


VIBRATION_TONE_SHARE = 0.7  # of the vibration's variance in the rotors' tone; the rest is broadband


def vibration(rng: np.random.Generator, t: np.ndarray, hz_range) -> np.ndarray:
    """``(N, 6)``: an airframe's vibration at the sample times ``t``, unit rms per column (gyro xyz,
    accelerometer xyz).  Most of it is the rotors' tone, at a frequency drawn from ``hz_range`` for
    the sequence that wanders 5 % with the thrust (1 s correlation), each column at its own phase;
    the rest is broadband.  The tone is read at the sample times as an IMU without an anti-alias
    filter reads it, so above half the rate it aliases to a lower frequency, as on a real
    airframe.  The AHRS's attitude does not see it (its own filter takes it out)."""
    n = len(t)
    f0 = rng.uniform(*hz_range)
    dt = np.diff(t, prepend=t[0] - (t[1] - t[0] if n > 1 else 0.0))
    f = f0 * (1.0 + _ou(rng, n, float(np.median(dt)) if n > 1 else 1.0, [0.05], 1.0)[:, 0])
    phase = 2.0 * math.pi * np.cumsum(f * dt)
    offsets = rng.uniform(0.0, 2.0 * math.pi, 6)
    tone = math.sqrt(2.0 * VIBRATION_TONE_SHARE) * np.sin(phase[:, None] + offsets)
    return tone + rng.normal(0.0, math.sqrt(1.0 - VIBRATION_TONE_SHARE), (n, 6))


def ahrs_rotation(row) -> np.ndarray:
    return matrix_from_quat_xyzw(np.asarray(row)[7:11])
