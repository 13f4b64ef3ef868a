"""Planar views of the pad by homography warping: the fast floor for rendering a planar scene.

Used by tests (synthetic views with exact labels, no OpenGL) and by the render-speed benchmark
as the reference a real renderer is compared with.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from hvloc.geometry import Camera, invert, pad_plane_homography  # noqa: F401  (re-exported)
from pad_design.texture import texture_to_pad


_LIGHT_LEVELS: dict = {}  # id(texture) -> (texture, its light pyramid): the views of one pad share it


def warp_pad_view(pad, camera: Camera, cam2pad: np.ndarray, background=(90, 110, 70),
                  levels: list | None = None, supersample: int = 3, in_light: bool = True,
                  blur_sigma_px: float = 0.0) -> np.ndarray:
    """RGB ``(H, W, 3)`` uint8 view of the pad (on a flat background colour) from pose ``cam2pad``.

    Pixels integrate over their area like a camera's: the view is warped at ``supersample``
    times the resolution (from a texture pyramid level with >= 4 texels per sample, so nothing
    aliases) and box-averaged down.  ``in_light`` (the default): texels and samples are averaged
    in light, as a camera's pixel sums it and the renderer mixes it (``camera.mix_in_light``;
    ``levels``, a pyramid of the texture in light, may be passed to share it), then blurred by a
    Gaussian of ``blur_sigma_px`` (a lens's) and written through the renderer's tone curve
    (:func:`render.imaging.display_bytes`).  ``in_light=False``: averaged in the texture's own
    values (8-bit display values, as the renderer's revisions up to 11 mixed them; or whatever
    ``levels`` and a float ``pad.texture_rgb`` hold, for a caller that mixes light itself), no
    blur.  Lens distortion is applied exactly by remapping the ideal pinhole view.
    """
    if in_light:
        from .imaging import SRGB_TO_LINEAR, display_bytes

        if levels is None:
            tex = pad.texture_rgb
            cached = _LIGHT_LEVELS.get(id(tex))
            if cached is None or cached[0] is not tex:
                if len(_LIGHT_LEVELS) >= 8:
                    _LIGHT_LEVELS.clear()
                cached = _LIGHT_LEVELS[id(tex)] = (tex, [cv2.LUT(tex, SRGB_TO_LINEAR)])
            levels = cached[1]
        bg = tuple(float(SRGB_TO_LINEAR[int(c)]) for c in background)
        lin = _warp_levels(pad, camera, cam2pad, bg, levels, supersample)
        if blur_sigma_px > 0:
            lin = cv2.GaussianBlur(lin, (0, 0), blur_sigma_px, borderType=cv2.BORDER_REPLICATE)
        return display_bytes(lin)
    if blur_sigma_px > 0:
        raise ValueError("warp_pad_view: blur_sigma_px blurs light: it needs in_light=True")
    return _warp_levels(pad, camera, cam2pad, tuple(int(c) for c in background), levels, supersample)


def _warp_levels(pad, camera: Camera, cam2pad: np.ndarray, background, levels: list | None, supersample: int):
    """:func:`warp_pad_view`'s warp of ``levels`` (the texture's pyramid, made as needed: uint8
    display values or float32 light), whatever their values are."""
    ss = max(1, int(supersample))
    cam = camera.without_distortion()
    cam_ss = cam.scaled(ss) if ss > 1 else cam
    tex = pad.texture_rgb
    H = pad_plane_homography(cam_ss, cam2pad)
    T = invert(cam2pad)
    depth = max(float(T[2, 3]), 1e-3)
    img_ppm = cam_ss.fx / depth  # samples per pad metre at the pad centre
    if levels is None:
        levels = [tex]
    level = 0
    # the coarsest level that still has >= 4 texels per sample: bilinear interpolation of a
    # coarser (sharper per sample) level biases axis-aligned edges by a phase-dependent ~0.1 px
    while pad.ppm / (2 ** (level + 1)) >= 4 * img_ppm and tex.shape[0] // (2 ** (level + 1)) > 8:
        level += 1
        if level >= len(levels):
            # exact 2x2 box average (an odd last row/column is dropped, not stretched over)
            prev = levels[-1]
            h2, w2 = prev.shape[0] // 2, prev.shape[1] // 2
            levels.append(cv2.resize(prev[:2 * h2, :2 * w2], (w2, h2), interpolation=cv2.INTER_AREA))
    src = levels[level]
    ppm = pad.ppm / (2 ** level)  # level texel i is centred on level-0 texels [i 2^l, (i+1) 2^l)
    Htot = H @ texture_to_pad(pad.side_m, ppm)
    img = cv2.warpPerspective(src, Htot, (cam_ss.width, cam_ss.height), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT,
                              borderValue=background)
    if ss > 1:
        img = cv2.resize(img, (camera.width, camera.height), interpolation=cv2.INTER_AREA)
    if camera.has_distortion:
        img = apply_distortion(img, camera)
    return img


def distortion_maps(camera: Camera):
    """``cv2.remap`` maps that turn an ideal pinhole image (same K) into the distorted image."""
    u, v = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
    px = np.column_stack([u.ravel(), v.ravel()])
    und = camera.undistort_pixels(px)
    mapx = und[:, 0].reshape(camera.height, camera.width).astype(np.float32)
    mapy = und[:, 1].reshape(camera.height, camera.width).astype(np.float32)
    return mapx, mapy


def apply_distortion(img: np.ndarray, camera: Camera, maps=None) -> np.ndarray:
    mapx, mapy = maps if maps is not None else distortion_maps(camera)
    return cv2.remap(img, mapx, mapy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def nadir_cam2pad(x: float, y: float, height: float, yaw: float = 0.0) -> np.ndarray:
    """Camera looking straight down at height ``height`` above pad point (x, y), image top toward
    pad +y when ``yaw`` = 0 (yaw rotates the camera about the pad's z axis)."""
    c, s = math.cos(yaw), math.sin(yaw)
    # camera axes in the pad frame: x_C = pad +x, y_C = pad -y, z_C = pad -z (looking down)
    R0 = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    T = np.eye(4)
    T[:3, :3] = Rz @ R0
    T[:3, 3] = (x, y, height)
    return T
