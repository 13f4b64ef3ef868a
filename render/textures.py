"""Procedural ground textures made in code (tileable: FFT-filtered noise wraps around)."""
from __future__ import annotations

import cv2
import numpy as np

GROUND_KINDS = ("grass", "dry_grass", "gravel", "soil", "asphalt", "sand", "concrete", "snow")


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


# mean colour (sRGB) and colour variation of each ground kind
GROUND_COLOURS = {"grass": ((70, 104, 44), (26, 30, 14)), "dry_grass": ((150, 132, 86), (30, 26, 18)),
                  "gravel": ((128, 122, 112), (18, 18, 18)), "soil": ((112, 84, 60), (26, 20, 14)),
                  "asphalt": ((118, 118, 122), (10, 10, 10)), "sand": ((196, 172, 132), (16, 14, 10)),
                  "concrete": ((162, 160, 152), (12, 12, 11)), "snow": ((228, 232, 240), (8, 8, 6))}


GROUND_TILE_M = 32.0   # the rasterised ground texture repeats every this many metres
GROUND_TILE_PX = 2048  # 15.6 mm per texel; render/ground.py adds the finer octaves


def ground_texture(kind: str, rng: np.random.Generator, size: int = GROUND_TILE_PX) -> np.ndarray:
    """``(size, size, 3)`` uint8 RGB, tileable over ``GROUND_TILE_M``, for one ground kind: its
    colour, large patches, and the coarse octaves of the kind's detail (32, 16 and 8 m per detail
    tile: features from ~20 cm down to the texel); :mod:`render.ground` adds the finer ones."""
    from .ground import AMPLITUDE, COARSE, TILE_PX, detail_tile

    if kind not in GROUND_COLOURS:
        raise ValueError(f"unknown ground kind {kind!r} (one of {', '.join(GROUND_KINDS)})")
    base, var = GROUND_COLOURS[kind]
    log_albedo = np.zeros((size, size), np.float32)
    for repeats in (1, 2, 4):  # octaves of 32, 16 and 8 m: a different tile each, repeated to the period
        tile_seed = int(rng.integers(2**31))  # drawn either way: the draws after it stay
        if AMPLITUDE[kind] * COARSE[kind] == 0:  # asphalt since render revision 8
            continue
        tile = detail_tile(kind, tile_seed)
        px = size // repeats
        octave = cv2.resize(tile, (px, px), interpolation=cv2.INTER_CUBIC if px > TILE_PX else cv2.INTER_AREA)
        log_albedo += AMPLITUDE[kind] * COARSE[kind] * np.tile(octave, (repeats, repeats))
    log_albedo += 0.5 * (fbm(size, rng, 2.4) - 0.5)  # field-scale patches
    hue = fbm(size, rng, 2.0) - 0.5
    lin = (np.asarray(base, np.float32) / 255.0) ** 2.2
    img = lin[None, None, :] * np.exp(log_albedo)[..., None]
    img *= 1.0 + (np.asarray(var, np.float32) / np.asarray(base, np.float32))[None, None, :] * 2.0 * hue[..., None]
    out = np.clip(img, 0, 1) ** (1 / 2.2) * 255.0
    if kind == "concrete":  # slab joints every 2 m
        step = size // 16
        for k in range(0, size, step):
            out[k:k + 2, :] *= 0.6
            out[:, k:k + 2] *= 0.6
    if kind == "asphalt":  # a painted line
        w = max(2, size // 320)
        out[size // 3:size // 3 + w, :] = out[size // 3:size // 3 + w, :] * 0.3 + np.array([235, 235, 225]) * 0.7
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


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


def dirty_texture(rgb: np.ndarray, share: float, seed: int) -> np.ndarray:
    """The pad's texture with stains and wear over about ``share`` of its area: brownish-grey
    blotches of varying opacity (mud, scuffs), fine specks, and a lightening of the black
    (wear).  A new image; the design stays as it is."""
    if share <= 0:
        return rgb
    rng = np.random.default_rng(seed)
    n = rgb.shape[0]
    small = 256
    field = cv2.resize(fbm(small, rng, 2.4), (n, n), interpolation=cv2.INTER_CUBIC)
    thresh = np.quantile(field, 1.0 - share)
    alpha = np.clip((field - thresh) / 0.08, 0.0, 1.0) * rng.uniform(0.35, 0.7)
    specks = cv2.resize((rng.random((small, small)) < 0.02 * share).astype(np.float32), (n, n),
                        interpolation=cv2.INTER_LINEAR) * 0.8
    a = np.clip(alpha + specks, 0.0, 0.85)[..., None]
    stain = np.array([118, 100, 78], np.float32)
    out = rgb.astype(np.float32) * (1 - a) + stain * a
    out = out + (255 - out) * (0.15 * share)  # wear: the dark ink fades a little
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)
