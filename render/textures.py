"""Procedural ground textures made in code (tileable: FFT-filtered noise wraps around)."""
from __future__ import annotations

import cv2
import numpy as np

GROUND_KINDS = ("grass", "soil", "asphalt", "sand", "concrete")


def fbm(size: int, rng: np.random.Generator, beta: float = 1.8, lo_cut: float = 1.0) -> np.ndarray:
    """Tileable fractal noise in [0, 1], power spectrum ~ 1/f^beta, ``(size, size)`` float32."""
    white = rng.standard_normal((size, size))
    f = np.fft.fftfreq(size) * size
    fx, fy = np.meshgrid(f, f)
    r = np.sqrt(fx * fx + fy * fy)
    r[0, 0] = 1.0
    amp = 1.0 / np.maximum(r, lo_cut) ** (beta / 2.0)
    amp[0, 0] = 0.0
    n = np.real(np.fft.ifft2(np.fft.fft2(white) * amp))
    n = (n - n.min()) / max(n.max() - n.min(), 1e-12)
    return n.astype(np.float32)


def _mix(base, var, n, extra=None):
    img = np.asarray(base, np.float32)[None, None, :] + (n[..., None] - 0.5) * np.asarray(var, np.float32)
    if extra is not None:
        img += extra
    return np.clip(img, 0, 255).astype(np.uint8)


def ground_texture(kind: str, rng: np.random.Generator, size: int = 1024) -> np.ndarray:
    """``(size, size, 3)`` uint8 RGB, tileable, for one ground kind."""
    if kind == "grass":
        n = 0.6 * fbm(size, rng, 1.6) + 0.4 * fbm(size, rng, 0.6)
        blades = fbm(size, rng, 0.2)
        blades = sum(np.roll(blades, k, axis=0) for k in range(-3, 4)) / 7.0  # streaks, still tileable
        return _mix((62, 104, 40), (60, 80, 40), n, ((blades - 0.5) * 40)[..., None])
    if kind == "soil":
        n = 0.7 * fbm(size, rng, 1.9) + 0.3 * fbm(size, rng, 0.4)
        return _mix((112, 84, 60), (70, 55, 40), n)
    if kind == "asphalt":
        n = 0.5 * fbm(size, rng, 1.5) + 0.5 * fbm(size, rng, 0.1)
        img = _mix((72, 72, 75), (40, 40, 40), n)
        specks = rng.random((size, size)) > 0.985
        img[specks] = np.clip(img[specks].astype(int) + 60, 0, 255).astype(np.uint8)
        return img
    if kind == "sand":
        n = fbm(size, rng, 2.2)
        y = np.arange(size, dtype=np.float32)[:, None]
        warp = fbm(size, rng, 2.5) * 40
        ripples = np.sin(2 * np.pi * (y * 24 / size + warp / 8)) * 10
        return _mix((196, 172, 132), (50, 45, 35), n, ripples[..., None])
    if kind == "concrete":
        n = 0.5 * fbm(size, rng, 1.7) + 0.5 * fbm(size, rng, 0.3)
        img = _mix((160, 158, 150), (45, 45, 42), n)
        step = size // 4
        for k in range(0, size, step):
            img[k:k + 3, :] = (img[k:k + 3, :] * 0.55).astype(np.uint8)
            img[:, k:k + 3] = (img[:, k:k + 3] * 0.55).astype(np.uint8)
        return img
    raise ValueError(f"unknown ground kind {kind!r} (one of {', '.join(GROUND_KINDS)})")


def finder_marker_image(modules_px: int = 16, quiet_modules: int = 1) -> np.ndarray:
    """A lone QR-style finder marker with its quiet zone, RGB uint8 (a decoy)."""
    n = 7 + 2 * quiet_modules
    m = np.full((n, n), 255, np.uint8)
    q = quiet_modules
    m[q:q + 7, q:q + 7] = 0
    m[q + 1:q + 6, q + 1:q + 6] = 255
    m[q + 2:q + 5, q + 2:q + 5] = 0
    img = cv2.resize(m, (n * modules_px, n * modules_px), interpolation=cv2.INTER_NEAREST)
    return np.repeat(img[..., None], 3, axis=2)


def aruco_image(marker_id: int, modules_px: int = 16) -> np.ndarray:
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    img = cv2.aruco.generateImageMarker(d, int(marker_id) % 50, 6 * modules_px, borderBits=1)
    img = cv2.copyMakeBorder(img, modules_px, modules_px, modules_px, modules_px, cv2.BORDER_CONSTANT, value=255)
    return np.repeat(img[..., None], 3, axis=2)
