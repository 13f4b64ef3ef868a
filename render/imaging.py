"""Image formation after rasterisation.

Input: renders (sRGB uint8, FLAT-shaded albedo of a fully sunlit horizontal surface = 1, at the
render camera's resolution: supersampled, and widened when the lens distorts).  Steps: in display
space, the lens distortion (remap at the supersampled resolution) and the box-average of the
supersampling; in linear light, motion blur over the exposure (:mod:`render.motion`, or
sub-frames averaged), exposure gain, defocus (Gaussian), shot + read noise; tone curve, 8-bit
quantisation, optional JPEG.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from hvloc.geometry import Camera

SRGB_GAMMA = 2.2
WHITE_LEVEL = 0.85  # auto-exposure: a sunlit white horizontal surface lands here (linear)
SHARPEN_SIGMA_PX = 1.0  # the camera's own sharpening subtracts a Gaussian blur this wide (px) of the written values
MONO_RESPONSE = np.array([0.2126, 0.7152, 0.0722], np.float32)  # a mono sensor's weights of linear R, G, B
SRGB_TO_LINEAR = ((np.arange(256, dtype=np.float32) / 255.0) ** SRGB_GAMMA).astype(np.float32)


@dataclass
class ImagingParams:
    """Degradations drawn for one sequence (written to meta.json)."""

    exposure_gain: float
    gamma: float
    defocus_sigma_px: float
    shot_noise: float
    read_noise: float
    jpeg_quality: int | None
    sharpen: float = 0.0
    vignetting: float = 0.0
    chromatic_aberration_px: float = 0.0
    mono: bool = False  # a monochrome sensor: one channel (written as grey RGB, R = G = B)

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def camera_response(params: ImagingParams) -> dict:
    """``camera.json``'s ``response`` (``camera.response_known``): what a photometric calibration says
    of how the camera writes light.  ``gamma``: each channel is written as ``(gain * light) ** (1 /
    gamma)``; ``sharpen``: then sharpened, ``(1 + sharpen) v - sharpen G(v)`` with ``G`` a Gaussian of
    ``sharpen_sigma_px``, before its 8 bits (and JPEG)."""
    return {"gamma": SRGB_GAMMA * float(params.gamma), "sharpen": float(params.sharpen),
            "sharpen_sigma_px": SHARPEN_SIGMA_PX}


def display_bytes(render: np.ndarray) -> np.ndarray:
    """A scene render as 8-bit display values: a uint8 render as it is, a float32 one (light:
    ``camera.mix_in_light``) through the renderer's tone convention (``light ** (1 / 2.2)``)."""
    if render.dtype == np.uint8:
        return render
    return cv2.convertScaleAbs(cv2.pow(np.clip(render, 0.0, 1.0).astype(np.float32), 1.0 / SRGB_GAMMA), alpha=255.0)


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
    """Turns renders into the camera's final 8-bit images.

    ``to_pixels``: one render (OpenCV, uint8 display values or float32 light) -> the camera's pixel grid: lens
    remap at the supersampled resolution, then the exact box average of the supersampling.
    ``depth_to_pixels``: the render's depth at each final pixel centre.  ``finish``: linear
    light -> exposure gain, defocus, shot and read noise (seeded per frame), tone curve, 8 bits,
    optional JPEG.  OpenCV throughout (one thread per process is the parallelism).
    """

    def __init__(self, camera: Camera, supersample: int, params: ImagingParams, irradiance_rel: float,
                 seed: int):
        self.camera = camera
        self.ss = supersample
        self.params = params
        self.seed = int(seed)
        self.render_camera, grid = render_camera_for(camera, supersample)
        self.maps = None
        if grid is not None:  # fixed-point maps: the same bilinear weights at 1/32 px, 2-3x faster
            self.maps = cv2.convertMaps(np.ascontiguousarray(grid[..., 0]), np.ascontiguousarray(grid[..., 1]),
                                        cv2.CV_16SC2)
        # each final pixel centre in the render (for depth): undistorted, then into the render's grid
        u, v = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
        und = camera.undistort_pixels(np.column_stack([u.ravel(), v.ravel()]))
        rc, ss = self.render_camera, supersample
        pin_x = (und[:, 0] - camera.cx) * ss + (rc.cx)
        pin_y = (und[:, 1] - camera.cy) * ss + (rc.cy)
        self.centre_x = pin_x.reshape(camera.height, camera.width).astype(np.float32)
        self.centre_y = pin_y.reshape(camera.height, camera.width).astype(np.float32)
        self.gain = params.exposure_gain * WHITE_LEVEL * irradiance_rel
        self.tone_exponent = 1.0 / (SRGB_GAMMA * params.gamma)
        # optics: light falloff toward the corners, and red/blue magnified/shrunk about the principal point
        H, W = camera.height, camera.width
        corner = max(math.hypot(x - camera.cx, y - camera.cy) for x in (0, W - 1) for y in (0, H - 1))
        self.vignette = None
        if params.vignetting > 0:
            yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
            rho2 = ((xx - camera.cx) ** 2 + (yy - camera.cy) ** 2) / corner**2
            # three channels, once: a same-shape multiply is 2x faster than numpy's broadcast of one
            self.vignette = np.repeat((1.0 - params.vignetting * rho2).astype(np.float32)[..., None], 3, axis=2)
        self.ca_scale = params.chromatic_aberration_px / corner if params.chromatic_aberration_px > 0 else 0.0

    def to_pixels(self, render: np.ndarray) -> np.ndarray:
        """One render (uint8 sRGB, render camera) -> uint8 sRGB at the camera's pixel grid; a float32
        render (light: ``camera.mix_in_light``) -> float32 light.

        Resampling happens in the render's own values, like OpenGL's texture filtering and edge
        blending before it: every filter a sharp frame sees treats an edge alike, and a 50 % crossing
        (of display values, or of light) stays where the label says (the projection test).  Optical
        blur is applied in linear light."""
        img = render
        if self.maps is not None:
            img = cv2.remap(img, self.maps[0], self.maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        if self.ss > 1:
            img = cv2.resize(img, (self.camera.width, self.camera.height), interpolation=cv2.INTER_AREA)
        return img

    def depth_to_pixels(self, z_render: np.ndarray) -> np.ndarray:
        """``(H, W)`` float32 depth (metres, ``inf`` for nothing) at every final pixel centre."""
        return cv2.remap(z_render, self.centre_x, self.centre_y, cv2.INTER_NEAREST, borderMode=cv2.BORDER_REPLICATE)

    def linear(self, render: np.ndarray) -> np.ndarray:
        """One render -> linear light ``(H, W, 3)`` float32 at the camera's pixel grid."""
        if render.dtype == np.float32:  # light already (camera.mix_in_light): resampled as light
            return np.ascontiguousarray(self.to_pixels(render))
        return cv2.LUT(self.to_pixels(render), SRGB_TO_LINEAR)

    def linear_average(self, subframes: list) -> np.ndarray:
        """Sub-frame renders -> their average in linear light, ``(H, W, 3)`` float32."""
        acc = self.linear(subframes[0])
        for img in subframes[1:]:
            acc += self.linear(img)
        if len(subframes) > 1:
            acc *= 1.0 / len(subframes)
        return acc

    def optics(self, linear: np.ndarray) -> np.ndarray:
        """Vignetting and lateral chromatic aberration (``linear`` is consumed)."""
        if self.ca_scale:
            c = self.camera
            planes = list(cv2.split(linear))  # (whole planes: numpy's strided channel copies cost twice as much)
            for ch, k in ((0, 1.0 + self.ca_scale), (2, 1.0 - self.ca_scale)):  # red outward, blue inward
                M = np.array([[1 / k, 0, c.cx * (1 - 1 / k)], [0, 1 / k, c.cy * (1 - 1 / k)]], np.float64)
                planes[ch] = cv2.warpAffine(planes[ch], M, linear.shape[1::-1], flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                            borderMode=cv2.BORDER_REPLICATE)
            linear = cv2.merge(planes)
        if self.vignette is not None:
            cv2.multiply(linear, self.vignette, dst=linear)
        return linear

    def finish(self, linear: np.ndarray, frame_index: int, exposure: float = 1.0) -> np.ndarray:
        """Linear light ``(H, W, 3)`` float32 -> the final uint8 RGB image of frame ``frame_index``
        (its noise is seeded by the sequence seed and the index: any frame renders alone alike).
        ``exposure`` scales the sequence's gain (auto exposure).  ``linear`` is consumed."""
        p = self.params
        x = self.optics(linear)
        if p.mono:  # no colour filter: the sensor sums the light (its response taken as the eye's, Rec. 709),
            # one noise draw per pixel, a grey tone curve and a grey JPEG (no chroma to subsample)
            x = cv2.transform(x, MONO_RESPONSE[None])
        x *= np.float32(self.gain * exposure)
        if p.defocus_sigma_px > 0.05:
            k = int(2 * round(3 * p.defocus_sigma_px) + 1)
            x = cv2.GaussianBlur(x, (k, k), p.defocus_sigma_px, borderType=cv2.BORDER_REPLICATE)
        np.clip(x, 0.0, None, out=x)  # bicubic blur samples can overshoot below black
        if p.shot_noise > 0 or p.read_noise > 0:
            sigma = x * np.float32(p.shot_noise**2)
            sigma += np.float32(p.read_noise**2)
            cv2.sqrt(sigma, sigma)
            noise = np.empty_like(x)
            cv2.setRNGSeed(int(np.random.SeedSequence([self.seed, 7, int(frame_index)]).generate_state(1)[0] % 2**31))
            cv2.randn(noise, 0.0, 1.0)
            cv2.multiply(noise, sigma, dst=noise)
            x += noise
        np.clip(x, 0.0, 1.0, out=x)
        disp = cv2.pow(x, self.tone_exponent)
        if p.sharpen > 0:  # the camera's own sharpening, in display space (a symmetric kernel keeps edges put)
            disp = cv2.addWeighted(disp, 1.0 + p.sharpen, cv2.GaussianBlur(disp, (0, 0), SHARPEN_SIGMA_PX), -p.sharpen, 0.0)
            # its undershoot beside a bright edge is black, as a camera clips it: written as it was
            # (convertScaleAbs takes the absolute value), a black pixel beside white read 38 of 255
            # under a 0.5 unsharp mask, a grey halo on the dark side of every strong edge (revision 13)
            np.maximum(disp, 0.0, out=disp)
        out = cv2.convertScaleAbs(disp, alpha=255.0)  # rounds to the nearest level, saturates at 255 (>= 0 here)
        if p.jpeg_quality:
            q = [cv2.IMWRITE_JPEG_QUALITY, int(p.jpeg_quality)]
            if p.mono:
                out = cv2.imdecode(cv2.imencode(".jpg", out, q)[1], cv2.IMREAD_GRAYSCALE)
            else:
                out = cv2.cvtColor(cv2.imdecode(cv2.imencode(".jpg", cv2.cvtColor(out, cv2.COLOR_RGB2BGR), q)[1],
                                                cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        if p.mono:  # DESIGN.md's frames are RGB: a grey frame is written with R = G = B
            out = cv2.cvtColor(out, cv2.COLOR_GRAY2RGB)
        return out
