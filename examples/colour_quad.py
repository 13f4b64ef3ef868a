"""An example of a localizer written outside hvloc, scored by hvloc's benchmark through a suite:

    localizers:
      - {name: colour_quad, kind: "examples.colour_quad:ColourQuad"}

It finds the pad's magenta border by colour, fits a quadrilateral to the largest region and
solves a planar PnP on its four corners, assuming the image's top edge is nearest the pad's top
edge (it has no yaw cue: rotate the drone by more than 45 degrees and its yaw is wrong by 90).
It implements the whole protocol (README, "Bring your own localizer"):

- ``__init__(pad, camera, config, T_B_C=None)``: the pad (``.geometry.outer_corners``: TL, TR,
  BR, BL in the pad frame), the camera (``K``, ``dist``, ``width``, ``height``), hvloc's
  ``LocalizerConfig`` (ignore what you do not use) and the camera mount;
- ``process(image, t, imu=None) -> hvloc.localizer.Estimate`` (``status`` ok/rejected/lost,
  ``cam2pad`` = T_P_C); exceptions become ``lost`` frames, never a crash;
- optional ``PAD_VARIANTS`` (the pad variants it runs on by default) and ``reset()``.
"""
from __future__ import annotations

import cv2
import numpy as np

from hvloc.geometry import invert, make_transform
from hvloc.localizer import Estimate


class ColourQuad:
    PAD_VARIANTS = ("paper", "nested")

    def __init__(self, pad, camera, config=None, T_B_C=None):
        geometry = pad.geometry if hasattr(pad, "geometry") else pad
        self.corners_P = np.asarray(geometry.outer_corners, np.float64)
        self.K, self.dist = camera.K, np.asarray(camera.dist, np.float64)

    def process(self, image, t, imu=None) -> Estimate:
        rgb = np.asarray(image)
        r, g, b = (rgb[..., i].astype(np.int16) for i in range(3))
        mask = ((r - g > 60) & (b - g > 40)).astype(np.uint8)  # magenta: red and blue well above green
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        if not contours:
            return Estimate(t, "approaching", "lost", None, reason="no magenta")
        c = max(contours, key=cv2.contourArea)
        quad = cv2.approxPolyDP(cv2.convexHull(c), 0.04 * cv2.arcLength(c, True), True).reshape(-1, 2)
        if len(quad) != 4 or cv2.contourArea(quad) < 64:
            return Estimate(t, "approaching", "lost", None, reason="no quadrilateral")
        # TL, TR, BR, BL as in the image: the corner nearest the image's top-left first
        centre = quad.mean(axis=0)
        ang = np.arctan2(quad[:, 1] - centre[1], quad[:, 0] - centre[0])
        quad = quad[np.argsort(ang)]  # clockwise in the image, starting near the left
        start = int(np.argmin(quad[:, 0] + quad[:, 1]))
        px = np.roll(quad, -start, axis=0).astype(np.float64)
        ok, rvec, tvec = cv2.solvePnP(self.corners_P, px, self.K, self.dist, flags=cv2.SOLVEPNP_IPPE)
        if not ok:
            return Estimate(t, "approaching", "lost", None, reason="solvePnP failed")
        proj, _ = cv2.projectPoints(self.corners_P, rvec, tvec, self.K, self.dist)
        rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - px) ** 2, axis=1))))
        cam2pad = invert(make_transform(cv2.Rodrigues(rvec)[0], tvec.ravel()))
        return Estimate(t, "approaching", "ok", cam2pad, 4, rms, method="colour_quad")
