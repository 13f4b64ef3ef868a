"""A printed pad that is not flat: wrinkles and a gentle sag, as a height field over the pad.

The labels stay on the pad's ideal plane (z = 0 of the pad frame, as DESIGN.md defines it): a
localizer is asked for the pose of that plane.  What the relief does to the image is reported per
sequence (``meta.json``'s ``pad_relief``): how far, in pixels, each labelled feature's image on the
real surface lies from its image on the ideal plane.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PadRelief:
    """``z(x, y)`` in metres over the pad (pad frame), between 0 (where it rests) and
    ``amplitude_m``: a few plane waves of random direction, wavelength and phase (wrinkles) plus a
    bowl of random sign (sag or curl), scaled so that the highest point is ``amplitude_m``."""

    amplitude_m: float
    waves: np.ndarray   # (K, 4): kx, ky (rad/m), phase, weight
    bowl: float         # weight of ((x^2 + y^2) / half^2)
    half_m: float
    lo: float
    hi: float

    @classmethod
    def draw(cls, amplitude_m: float, wavelength_m: tuple, side_m: float, rng: np.random.Generator,
             waves: int = 5) -> "PadRelief":
        lam = rng.uniform(wavelength_m[0], wavelength_m[1], waves) if wavelength_m[1] > wavelength_m[0] \
            else np.full(waves, float(wavelength_m[0]))
        ang = rng.uniform(0.0, math.pi, waves)
        k = 2 * math.pi / lam
        w = np.column_stack([k * np.cos(ang), k * np.sin(ang), rng.uniform(0, 2 * math.pi, waves),
                             rng.uniform(0.5, 1.0, waves)])
        bowl = float(rng.uniform(-1.0, 1.0))
        half = side_m / 2
        raw = cls(amplitude_m, w, bowl, half, 0.0, 1.0)
        g = np.linspace(-half, half, 129)
        s = raw._raw(np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2))
        return cls(amplitude_m, w, bowl, half, float(s.min()), float(s.max()))

    @property
    def shortest_m(self) -> float:
        """The shortest wrinkle's wavelength."""
        return float(2 * math.pi / np.max(np.linalg.norm(self.waves[:, :2], axis=1)))

    def _raw(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        arg = xy @ self.waves[:, :2].T + self.waves[:, 2]
        return np.sin(arg) @ self.waves[:, 3] + self.bowl * (xy**2).sum(axis=1) / self.half_m**2

    def height(self, xy: np.ndarray) -> np.ndarray:
        """(N,) metres above the ideal plane at pad-frame points ``xy`` (clamped to the pad)."""
        xy = np.clip(np.asarray(xy, np.float64).reshape(-1, 2), -self.half_m, self.half_m)
        return self.amplitude_m * (self._raw(xy) - self.lo) / max(self.hi - self.lo, 1e-12)

    def normal(self, xy: np.ndarray) -> np.ndarray:
        """(N, 3) unit normals of the surface (pad frame)."""
        xy = np.clip(np.asarray(xy, np.float64).reshape(-1, 2), -self.half_m, self.half_m)
        arg = xy @ self.waves[:, :2].T + self.waves[:, 2]
        grad = (np.cos(arg) * self.waves[:, 3]) @ self.waves[:, :2] + 2 * self.bowl * xy / self.half_m**2
        grad *= self.amplitude_m / max(self.hi - self.lo, 1e-12)
        n = np.column_stack([-grad, np.ones(len(xy))])
        return n / np.linalg.norm(n, axis=1, keepdims=True)

    def on_surface(self, pts_P: np.ndarray) -> np.ndarray:
        """Pad-plane points (N, 3) moved up onto the surface."""
        p = np.array(pts_P, np.float64).reshape(-1, 3)
        p[:, 2] = p[:, 2] + self.height(p[:, :2])
        return p

    def to_dict(self) -> dict:
        return {"amplitude_m": self.amplitude_m, "waves": self.waves.round(6).tolist(), "bowl": round(self.bowl, 6)}
