"""Image formation after rasterisation, on batches with torch/kornia.

Input: sub-frame renders (sRGB uint8, FLAT-shaded albedo of a fully sunlit horizontal surface
= 1, at the render camera's resolution: supersampled, and widened when the lens distorts).
Steps: per sub-frame, in display space, the lens distortion (remap at the supersampled
resolution) and the box-average of the supersampling; the sub-frames averaged in linear light
(motion blur over the exposure); then in linear light exposure gain, defocus (Gaussian), shot +
read noise; tone curve, 8-bit quantisation, optional JPEG.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import torch

import kornia

from hvloc.geometry import Camera

SRGB_GAMMA = 2.2
WHITE_LEVEL = 0.85
SRGB_TO_LINEAR = ((np.arange(256, dtype=np.float32) / 255.0) ** SRGB_GAMMA).astype(np.float32)  # auto-exposure: a sunlit white horizontal surface lands here (linear)


@dataclass
class ImagingParams:
    """Degradations drawn for one sequence (written to meta.json)."""

    exposure_gain: float
    gamma: float
    defocus_sigma_px: float
    shot_noise: float
    read_noise: float
    jpeg_quality: int | None

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def render_camera_for(camera: Camera, supersample: int) -> tuple:
    """The pinhole camera to rasterise with, and the remap grid (or None) to the final camera.

    Images are rasterised at ``supersample`` times the resolution.  With distortion, the pinhole
    image must cover every ray the distorted image sees, so it is widened (same focal length,
    shifted principal point), and ``grid_xy`` ``(H*ss, W*ss, 2)`` float32 holds, for each pixel
    of the *supersampled distorted* image, its position in the pinhole render (OpenCV pixel
    convention).  Remapping at the supersampled resolution and box-averaging afterwards keeps
    the resampling blur a fraction of a final pixel.
    """
    target = camera.scaled(supersample) if supersample > 1 else camera
    if not camera.has_distortion:
        return target, None
    u, v = np.meshgrid(np.arange(target.width, dtype=np.float64), np.arange(target.height, dtype=np.float64))
    und = target.undistort_pixels(np.column_stack([u.ravel(), v.ravel()]))
    lo = np.floor(und.min(axis=0)) - 2
    hi = np.ceil(und.max(axis=0)) + 2
    w, h = int(hi[0] - lo[0]) + 1, int(hi[1] - lo[1]) + 1
    if w * h > 80e6:
        raise ValueError("the lens's distortion needs an impractically wide pinhole render")
    pin = Camera(w, h, target.fx, target.fy, target.cx - lo[0], target.cy - lo[1])
    grid = (und - lo).reshape(target.height, target.width, 2).astype(np.float32)
    return pin, grid


class ImageFormation:
    """Turns sub-frame renders into the camera's final 8-bit images.

    Per sub-frame (OpenCV, uint8, display space): lens remap at the supersampled resolution,
    then the exact box average of the supersampling; then a lookup into linear light, where
    sub-frames are averaged (motion blur).  Per batch of frames (torch/kornia): exposure,
    defocus, noise, tone curve, quantisation.
    """

    def __init__(self, camera: Camera, supersample: int, params: ImagingParams, irradiance_rel: float,
                 seed: int):
        self.camera = camera
        self.ss = supersample
        self.params = params
        self.render_camera, grid = render_camera_for(camera, supersample)
        self.map_x = None if grid is None else np.ascontiguousarray(grid[..., 0])
        self.map_y = None if grid is None else np.ascontiguousarray(grid[..., 1])
        self.gen = torch.Generator().manual_seed(int(seed) % (2**63))
        self.gain = params.exposure_gain * WHITE_LEVEL * irradiance_rel

    def to_pixels(self, render: np.ndarray) -> np.ndarray:
        """One render (uint8 sRGB, render camera) -> uint8 sRGB at the camera's pixel grid.

        Resampling happens in display space, like OpenGL's own texture filtering and edge
        blending: every filter a sharp frame sees treats an edge alike, and a 50 % crossing stays
        where the label says (the projection test).  Optical blur is applied in linear light."""
        img = render
        if self.map_x is not None:
            img = cv2.remap(img, self.map_x, self.map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        if self.ss > 1:
            img = cv2.resize(img, (self.camera.width, self.camera.height), interpolation=cv2.INTER_AREA)
        return img

    def linear_average(self, subframes: list) -> np.ndarray:
        """Sub-frame renders -> their average in linear light, ``(H, W, 3)`` float32."""
        if len(subframes) == 1:
            return cv2.LUT(self.to_pixels(subframes[0]), SRGB_TO_LINEAR)
        acc = np.zeros((self.camera.height, self.camera.width, 3), np.float32)
        for img in subframes:
            acc += cv2.LUT(self.to_pixels(img), SRGB_TO_LINEAR)
        acc *= 1.0 / len(subframes)
        return acc

    def finish(self, linear_frames: list) -> list:
        """Linear frames at the camera's resolution -> final uint8 RGB images."""
        if not linear_frames:
            return []
        x = torch.from_numpy(np.stack(linear_frames)).permute(0, 3, 1, 2)
        x = x * self.gain
        p = self.params
        if p.defocus_sigma_px > 0.05:
            k = int(2 * round(3 * p.defocus_sigma_px) + 1)
            x = kornia.filters.gaussian_blur2d(x, (k, k), (p.defocus_sigma_px, p.defocus_sigma_px), border_type="replicate")
        if p.shot_noise > 0 or p.read_noise > 0:
            noise = torch.randn(x.shape, generator=self.gen)
            x = x + noise * torch.sqrt(p.shot_noise**2 * x.clamp(min=0) + p.read_noise**2)
        x = x.clamp(0, 1) ** (1.0 / (SRGB_GAMMA * p.gamma))
        out = (x * 255.0 + 0.5).clamp(0, 255).to(torch.uint8).permute(0, 2, 3, 1).contiguous().numpy()
        frames = list(out)
        if p.jpeg_quality:
            q = [cv2.IMWRITE_JPEG_QUALITY, int(p.jpeg_quality)]
            frames = [cv2.cvtColor(cv2.imdecode(cv2.imencode(".jpg", cv2.cvtColor(f, cv2.COLOR_RGB2BGR), q)[1],
                                                cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB) for f in frames]
        return frames
