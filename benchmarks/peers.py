"""Peer localizers for the leaderboard, behind the same interface as hvloc's:
``Localizer(pad, camera, config, T_B_C).process(image, t, imu=None) -> Estimate``.

``ArucoLocalizer`` is what a practitioner would reach for instead of hvloc: OpenCV's ArUco
detector (``cv2.aruco.ArucoDetector``, sub-pixel corner refinement) on the ``aruco`` pad variant,
whose three markers have the finder markers' outer size and place, and one ``cv2.solvePnP``
(IPPE, the planar solver, on every detected corner, with the lens model) refined by
``cv2.solvePnPRefineLM``.  Left as OpenCV ships it: no phases, no IMU, no tracking; the only
gate is the reprojection RMS (``max_reprojection_px`` of the config), which any user of solvePnP
would add.  Markers with ids the pad does not carry are ignored.
"""
from __future__ import annotations


import cv2
import numpy as np

from hvloc.config import LocalizerConfig
from hvloc.geometry import Camera, invert, make_transform
from hvloc.localizer import Estimate, check_image, guarded_process
from hvloc.pose import pose_covariance

PHASE = "adjustment"  # it is a marker method: reported in the markers' phase


class ArucoLocalizer:
    def __init__(self, pad, camera: Camera, config: LocalizerConfig | None = None, T_B_C=None):
        geometry = pad.geometry if hasattr(pad, "geometry") else pad
        markers = geometry.markers_in(kind="aruco")
        if not markers:
            raise ValueError(f"the ArUco peer needs the 'aruco' pad variant; this pad is {geometry.variant!r}")
        self.camera = camera
        self.config = config or LocalizerConfig()
        self.corners_P = {m.aruco_id: m.outer_corners for m in markers}
        name = geometry.spec["aruco_dictionary"]
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        self.detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name)), params)
        self.K = camera.K
        self.dist = np.asarray(camera.dist, np.float64)

    def reset(self) -> None:
        pass

    def process(self, image, t: float, imu=None) -> Estimate:
        return guarded_process(self._process, image, t, imu, PHASE)

    def _process(self, image, t: float, imu=None) -> Estimate:
        _, gray, why = check_image(image)
        if gray is None:
            return Estimate(t, PHASE, "lost", None, reason=why)
        if gray.shape != (self.camera.height, self.camera.width):
            return Estimate(t, PHASE, "lost", None, reason=f"image is {gray.shape[1]}x{gray.shape[0]}, "
                            f"camera is {self.camera.width}x{self.camera.height}")
        corners, ids, _ = self.detector.detectMarkers(gray)
        if ids is None:
            return Estimate(t, PHASE, "lost", None, reason="aruco: no marker")
        obj, img = [], []
        for c, i in zip(corners, ids.ravel()):
            if int(i) in self.corners_P:
                obj.append(self.corners_P[int(i)])
                img.append(c.reshape(4, 2))
        if not obj:
            return Estimate(t, PHASE, "lost", None, reason="aruco: no marker of this pad")
        obj = np.concatenate(obj)
        img = np.concatenate(img).astype(np.float64)
        ok, rvec, tvec = cv2.solvePnP(obj, img, self.K, self.dist, flags=cv2.SOLVEPNP_IPPE)
        if not ok:
            return Estimate(t, PHASE, "lost", None, reason="aruco: solvePnP failed")
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, self.K, self.dist, rvec, tvec)
        proj, _ = cv2.projectPoints(obj, rvec, tvec, self.K, self.dist)
        rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))
        cam2pad = invert(make_transform(cv2.Rodrigues(rvec)[0], tvec.ravel()))
        cov = pose_covariance(self.camera, cam2pad, obj, img, min_sigma_px=0.3)  # the same model as hvloc's
        est = Estimate(t, PHASE, "ok", cam2pad, len(obj), rms, cov, method="aruco",
                       extras={"markers": len(obj) // 4})
        if not np.isfinite(rms) or rms > self.config.max_reprojection_px:
            est.status, est.reason = "rejected", f"reprojection RMS {rms:.2f} px > {self.config.max_reprojection_px}"
        return est


LOCALIZERS = {"aruco": ArucoLocalizer}
