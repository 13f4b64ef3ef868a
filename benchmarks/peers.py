"""Peer localizers for the leaderboard, behind the same interface as hvloc's:
``Localizer(pad, camera, config, T_B_C).process(image, t, imu=None) -> Estimate``.

What a practitioner would reach for instead of hvloc, left as its library ships it: a fiducial
detector, then one ``cv2.solvePnP`` (IPPE, the planar solver) over every corner of every marker of
the pad it found, with the lens model, refined by ``cv2.solvePnPRefineLM``.  No phases, no IMU, no
tracking; the only gate is the reprojection RMS (``max_reprojection_px`` of the config), which any
user of solvePnP would add.  Markers with ids the pad does not carry are ignored.  A suite entry
with ``gates: true`` gives the peer what hvloc has besides its pad: the IMU's gravity as a prior in
the pose solve (``gravity_prior``: hvloc's ``solve_planar_pose``, which also breaks IPPE's flip by
gravity) and hvloc's false-pose gates in front (``hvloc.localizer.GatedLocalizer``).

* ``ArucoLocalizer``: OpenCV's ArUco detector (``cv2.aruco.ArucoDetector``, sub-pixel corner
  refinement) on the ``aruco`` pad variant, three markers with the finder markers' size and place.
* ``AprilTagLocalizer``: AprilTag 3 (``pupil_apriltags``, the AprilTag library's binding, at its
  defaults) on the ``apriltag`` variant: the recursive pad of precision-landing projects, a large
  ``tagCustom48h12`` tag with a small one nested in its centre; the pose from every tag in view.
"""
from __future__ import annotations


import cv2
import numpy as np

from hvloc.config import LocalizerConfig
from hvloc.geometry import Camera, invert, make_transform
from hvloc.localizer import DEFAULT_T_B_C, Estimate, check_image, guarded_process, imu_check, up_in_camera
from hvloc.pose import pose_covariance, solve_planar_pose

PHASE = "adjustment"  # a marker method: reported in the markers' phase


class _FiducialPeer:
    """Detector in, one solvePnP over every detected corner out.  Subclasses give ``_detect(gray)
    -> ([(corners_P (4, 3), corners_px (4, 2)), ...], reason)`` and ``METHOD``."""

    METHOD = ""
    PEER = ""  # its name in messages
    IMU_BLOCK = True  # it reads the attitude of a block's last row (imu_check)

    gravity_prior = False  # with an IMU: its gravity as a prior in the pose solve (hvloc's, see the module doc)

    def __init__(self, pad, camera: Camera, config: LocalizerConfig | None, T_B_C=None):
        """Sets ``self.markers``: the pad's markers of kind ``METHOD`` (refused when it has none)."""
        self.geometry = pad.geometry if hasattr(pad, "geometry") else pad
        self.markers = self.geometry.markers_in(kind=self.METHOD)
        if not self.markers:
            raise ValueError(f"the {self.PEER} peer needs the '{self.METHOD}' pad variant; this pad is "
                             f"{self.geometry.variant!r}")
        self.camera = camera
        self.config = config or LocalizerConfig()
        self.K = camera.K
        self.dist = np.asarray(camera.dist, np.float64)
        self.T_B_C = DEFAULT_T_B_C if T_B_C is None else np.asarray(T_B_C, np.float64)

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
        found, why = self._detect(gray)
        if not found:
            return Estimate(t, PHASE, "lost", None, reason=f"{self.METHOD}: {why}")
        obj = np.concatenate([o for o, _ in found])
        img = np.concatenate([i for _, i in found]).astype(np.float64)
        up_C = up_in_camera(imu_check(imu)[0], self.T_B_C) if self.gravity_prior else None
        if up_C is not None:
            res = solve_planar_pose(self.camera, obj, img, up_C=up_C, gravity_sigma_deg=self.config.up_sigma_deg())
            if res is None:
                return Estimate(t, PHASE, "lost", None, reason=f"{self.METHOD}: pose failed")
            cam2pad, rms, cov = res.cam2pad, res.rms_px, res.cov
        else:
            # cv2.solvePnP knows the pinhole's lens; a fisheye's points are undistorted first
            fisheye = self.camera.model != "pinhole"
            img_s, dist = (self.camera.undistort_pixels(img), None) if fisheye else (img, self.dist)
            ok, rvec, tvec = cv2.solvePnP(obj, img_s, self.K, dist, flags=cv2.SOLVEPNP_IPPE)
            if not ok or not np.isfinite(img_s).all():
                return Estimate(t, PHASE, "lost", None, reason=f"{self.METHOD}: solvePnP failed")
            rvec, tvec = cv2.solvePnPRefineLM(obj, img_s, self.K, dist, rvec, tvec)
            cam2pad = invert(make_transform(cv2.Rodrigues(rvec)[0], tvec.ravel()))
            if fisheye:
                proj = self.camera.project_from(cam2pad, obj)
            else:
                proj, _ = cv2.projectPoints(obj, rvec, tvec, self.K, self.dist)
            rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))
            cov = pose_covariance(self.camera, cam2pad, obj, img, min_sigma_px=0.3)  # the same model as hvloc's
        est = Estimate(t, PHASE, "ok", cam2pad, len(obj), rms, cov, method=self.METHOD,
                       extras={"markers": len(found)})
        if not np.isfinite(rms) or rms > self.config.max_reprojection_px:
            est.status, est.reason = "rejected", f"reprojection RMS {rms:.2f} px > {self.config.max_reprojection_px}"
        return est


class ArucoLocalizer(_FiducialPeer):
    METHOD, PEER = "aruco", "ArUco"

    def __init__(self, pad, camera: Camera, config: LocalizerConfig | None = None, T_B_C=None):
        from pad_design.layout import aruco_dictionary_of

        super().__init__(pad, camera, config, T_B_C)
        # one detector per dictionary the pad uses (a nested pad's small marker is of another: one
        # detector drops a marker candidate that holds another, so practitioners nest dictionaries)
        self.corners_P = {}
        for m in self.markers:
            self.corners_P.setdefault(aruco_dictionary_of(self.geometry.spec, m), {})[m.aruco_id] = m.outer_corners
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        self.detectors = [(cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name)), params),
                           self.corners_P[name]) for name in sorted(self.corners_P)]

    def _detect(self, gray) -> tuple:
        found, seen = [], False
        for detector, corners_P in self.detectors:
            corners, ids, _ = detector.detectMarkers(gray)
            if ids is None:
                continue
            seen = True
            found += [(corners_P[int(i)], c.reshape(4, 2)) for c, i in zip(corners, ids.ravel()) if int(i) in corners_P]
        return found, "no marker of this pad" if seen else "no marker"


_DETECTOR_CLASS = None


def _apriltag_detector(family: str):
    """A ``pupil_apriltags.Detector`` that is freed in the right order.  pupil-apriltags 1.0.4 frees
    the tag families before the detector, whose destructor still reads them (AprilTag's
    ``apriltag_detector_destroy`` uninitialises each family's decode table): a use-after-free that
    crashed a test run, and crashes every time under ``MALLOC_PERTURB_``.  Here the detector goes first."""
    global _DETECTOR_CLASS
    if _DETECTOR_CLASS is None:
        from pupil_apriltags import Detector

        class _Detector(Detector):
            def __del__(self):
                ptr = getattr(self, "tag_detector_ptr", None)
                if ptr is None:
                    return
                self.libc.apriltag_detector_destroy.restype = None
                self.libc.apriltag_detector_destroy(ptr)
                self.tag_detector_ptr = None
                for fam, tf in self.tag_families.items():
                    destroy = getattr(self.libc, f"{fam}_destroy")
                    destroy.restype = None
                    destroy(tf)
                self.tag_families = {}

        _DETECTOR_CLASS = _Detector
    return _DETECTOR_CLASS(families=family, nthreads=1)


class AprilTagLocalizer(_FiducialPeer):
    METHOD, PEER = "apriltag", "AprilTag"

    def __init__(self, pad, camera: Camera, config: LocalizerConfig | None = None, T_B_C=None):
        from pad_design.apriltag import DETECTOR_TO_PAD_CORNERS, FAMILY

        super().__init__(pad, camera, config, T_B_C)
        order = list(DETECTOR_TO_PAD_CORNERS)
        self.corners_P = {m.aruco_id: m.outer_corners[order] for m in self.markers}  # in the detector's order
        self.detector = _apriltag_detector(FAMILY)

    def _detect(self, gray) -> tuple:
        tags = self.detector.detect(np.ascontiguousarray(gray))
        # the AprilTag library puts the centre of the top-left pixel at (0.5, 0.5), OpenCV (and hvloc) at (0, 0)
        found = [(self.corners_P[d.tag_id], np.asarray(d.corners, np.float64) - 0.5) for d in tags
                 if d.tag_id in self.corners_P and d.hamming == 0]
        return found, "no tag of this pad" if tags else "no tag"


LOCALIZERS = {"aruco": ArucoLocalizer, "apriltag": AprilTagLocalizer}
