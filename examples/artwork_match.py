"""An example localizer for a pad made from your own artwork (``pad: {variant: artwork}``), scored
by hvloc's benchmark through a suite:

    localizers:
      - {name: artwork_match, kind: "examples.artwork_match:ArtworkMatch"}

It knows nothing of hvloc's border, cue or markers: it matches SIFT features (OpenCV's) of the
camera image against the pad's own texture (``pad.texture_rgb``, what the dataset was rendered
with), keeps the matches a RANSAC homography agrees with, and solves the planar pose on them with
hvloc's solver (lens undistortion included; the IMU's gravity, when given, chooses between the
two poses a plane allows).  Any pad texture works, hvloc's own variants too;
a plain one (few corners) gives few matches, and a pad smaller than ~40 px gives none.  The
protocol is the one of ``examples/colour_quad.py`` (README, "Bring your own localizer").
"""
from __future__ import annotations

import cv2
import numpy as np

from hvloc.localizer import DEFAULT_T_B_C, Estimate, imu_check, up_in_camera
from hvloc.pose import solve_planar_pose

MIN_INLIERS = 12


class ArtworkMatch:
    PAD_VARIANTS = ("artwork",)

    def __init__(self, pad, camera, config=None, T_B_C=None, template_px: int = 800):
        self.camera = camera
        self.max_rms_px = float(getattr(config, "max_reprojection_px", 2.0))
        self.T_B_C = DEFAULT_T_B_C if T_B_C is None else np.asarray(T_B_C, np.float64)
        tex = np.asarray(pad.texture_rgb)
        scale = min(1.0, template_px / tex.shape[1])
        small = cv2.resize(tex, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA) if scale < 1 else tex
        self.sift = cv2.SIFT_create(nfeatures=1500)
        kp, self.desc = self.sift.detectAndCompute(cv2.cvtColor(small, cv2.COLOR_RGB2GRAY), None)
        # template pixel (j, i) centre -> pad frame (x right, y up, metres), as pad.json's texture says
        ppm = pad.ppm * scale
        uv = np.array([k.pt for k in kp], np.float64).reshape(-1, 2)
        side = float(pad.geometry.side_m)
        self.pts_P = np.column_stack([(uv[:, 0] + 0.5) / ppm - side / 2, side / 2 - (uv[:, 1] + 0.5) / ppm,
                                      np.zeros(len(uv))])
        self.matcher = cv2.BFMatcher(cv2.NORM_L2)

    def process(self, image, t, imu=None) -> Estimate:
        if self.desc is None or len(self.pts_P) < MIN_INLIERS:
            return Estimate(t, "approaching", "lost", None, reason="the pad's texture has too few features")
        gray = cv2.cvtColor(np.asarray(image), cv2.COLOR_RGB2GRAY)
        kp, desc = self.sift.detectAndCompute(gray, None)
        if desc is None or len(kp) < MIN_INLIERS:
            return Estimate(t, "approaching", "lost", None, reason="too few image features")
        pairs = self.matcher.knnMatch(self.desc, desc, k=2)
        good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < 0.75 * p[1].distance]
        if len(good) < MIN_INLIERS:
            return Estimate(t, "approaching", "lost", None, reason=f"{len(good)} matches")
        P = self.pts_P[[m.queryIdx for m in good]]
        px = np.array([kp[m.trainIdx].pt for m in good], np.float64)
        und = self.camera.undistort_pixels(px) if self.camera.has_distortion else px
        H, inl = cv2.findHomography(P[:, :2], und, cv2.RANSAC, 3.0)
        if H is None or int(inl.sum()) < MIN_INLIERS:
            return Estimate(t, "approaching", "lost", None, reason="no homography")
        keep = inl.ravel().astype(bool)
        # the IMU's gravity picks the right one of a plane's two poses (a small pad's are close)
        res = solve_planar_pose(self.camera, P[keep], px[keep], up_C=up_in_camera(imu_check(imu)[0], self.T_B_C))
        if res is None:
            return Estimate(t, "approaching", "lost", None, reason="pose failed")
        h = float(res.cam2pad[2, 3])
        phase = "touchdown" if h < 0.5 else "adjustment" if h < 3.0 else "approaching"
        est = Estimate(t, phase, "ok", res.cam2pad, int(keep.sum()), res.rms_px, res.cov, method="artwork_match")
        if not np.isfinite(res.rms_px) or res.rms_px > self.max_rms_px:  # matches RANSAC let through by chance
            est.status, est.reason = "rejected", f"reprojection RMS {res.rms_px:.2f} px > {self.max_rms_px}"
        return est
