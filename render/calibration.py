"""Camera calibrations from the files people have, as the ``camera:`` fields of a dataset spec.

Read: Kalibr camchain YAML (``cam0: {camera_model, intrinsics, distortion_model, distortion_coeffs,
resolution}``), ROS ``CameraInfo`` YAML (``camera_calibration``'s ``ost.yaml``: ``image_width``,
``camera_matrix``, ``distortion_coefficients``), and OpenCV ``FileStorage`` files (YAML, XML or
JSON, as ``cv::calibrateCamera`` users write them: ``camera_matrix``, ``distortion_coefficients``,
``image_width``/``image_height``).  All three put the centre of the top-left pixel at (0, 0), as
hvloc does (DESIGN.md), so ``cx, cy`` carry over unchanged.

hvloc renders a pinhole with OpenCV's radial-tangential distortion (k1 k2 p1 p2 k3) and a fisheye
with OpenCV's Kannala-Brandt model (k1 k2 k3 k4: Kalibr's ``equidistant``, ROS's ``equidistant``);
an omnidirectional or rational model, or a skewed camera matrix, is refused with the field named.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hvloc.geometry import Camera
from pad_design.errors import InputError, read_user_text


@dataclass(frozen=True)
class Calibration:
    """A calibrated camera (:class:`hvloc.geometry.Camera`: pinhole, radial-tangential, OpenCV's
    pixels) and what it was read from."""

    camera: Camera
    source: str

    def __getattr__(self, name):  # cal.fx, cal.width, ...: the camera's
        return getattr(self.__dict__["camera"], name)

    def spec_fields(self) -> dict:
        """The ``camera:`` fields of a dataset spec that give exactly this camera
        (``render.plan.camera_from_spec`` reads them back to the same fx, fy, cx, cy)."""
        c = self.camera
        half = (c.width / 2.0) / c.fx
        return {"width": c.width, "height": c.height, "model": c.model,
                "hfov_deg": math.degrees(2.0 * (math.atan(half) if c.model == "pinhole" else half)),
                "fy_over_fx": c.fy / c.fx,
                "principal_offset_px": [c.cx - (c.width - 1) / 2.0, c.cy - (c.height - 1) / 2.0],
                "dist": [float(d) for d in c.dist]}


def _radtan(coeffs, where: str) -> tuple:
    d = [float(c) for c in np.asarray(coeffs, np.float64).ravel()]
    if len(d) in (4, 5):
        return tuple(d + [0.0] * (5 - len(d)))
    if len(d) in (8, 12, 14) and not any(d[5:]):
        return tuple(d[:5])
    raise InputError(f"{where}: {len(d)} distortion coefficients {d}; hvloc's lens is radial-tangential "
                     "(k1 k2 p1 p2 [k3]); a rational or thin-prism model is not supported")


def _equidistant(coeffs, where: str) -> tuple:
    d = [float(c) for c in np.asarray(coeffs, np.float64).ravel()]
    if len(d) != 4:
        raise InputError(f"{where}: {len(d)} distortion coefficients {d}; the equidistant (fisheye) model has 4 "
                         "(k1 k2 k3 k4)")
    return tuple(d)


def _camera_matrix(K, where: str) -> tuple:
    K = np.asarray(K, np.float64).reshape(-1)
    if K.size != 9:
        raise InputError(f"{where}: a camera matrix has 9 numbers, this one {K.size}")
    K = K.reshape(3, 3)
    if abs(K[0, 1]) > 1e-9 * abs(K[0, 0]) or abs(K[1, 0]) > 0 or abs(K[2, 0]) > 0 or abs(K[2, 1]) > 0 \
            or abs(K[2, 2] - 1.0) > 1e-9:
        raise InputError(f"{where}: not of the form [[fx 0 cx] [0 fy cy] [0 0 1]] (skew is not supported): {K.tolist()}")
    return float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])


def check_intrinsics(camera: Camera, where: str) -> Camera:
    """``camera``, or an :class:`InputError` naming ``where`` for a size, focal length or
    coefficient no camera has: a calibration read in, or a dataset's ``camera.json``."""
    w, h, fx, fy = camera.width, camera.height, camera.fx, camera.fy
    if w < 16 or h < 16:
        raise InputError(f"{where}: image size {w}x{h} is too small")
    if not (fx > 0 and fy > 0 and math.isfinite(fx) and math.isfinite(fy)):
        raise InputError(f"{where}: focal lengths must be positive (fx {fx}, fy {fy})")
    bad = [n for n, v in (("cx", camera.cx), ("cy", camera.cy), *((f"dist[{i}]", d) for i, d in enumerate(camera.dist)))
           if not math.isfinite(v)]
    if bad:
        raise InputError(f"{where}: {', '.join(bad)} of the calibration not finite")
    return camera


def _checked(w: int, h: int, fx: float, fy: float, cx: float, cy: float, dist: tuple, source: str,
             where: str, model: str = "pinhole") -> Calibration:
    return Calibration(check_intrinsics(Camera(w, h, fx, fy, cx, cy, dist, model), where), source)


def _kalibr(doc: dict, name: str | None, path: str) -> Calibration:
    cams = [k for k, v in doc.items() if isinstance(v, dict) and "intrinsics" in v]
    if name is None:
        name = sorted(cams)[0]
    if name not in cams:
        raise InputError(f"{path}: no camera {name!r} (it has {', '.join(sorted(cams))})")
    c = doc[name]
    where = f"{path}: {name}"
    model, dmodel = c.get("camera_model", "pinhole"), c.get("distortion_model", "radtan")
    if model != "pinhole":
        raise InputError(f"{where}.camera_model: {model!r}; hvloc renders a pinhole camera")
    if dmodel not in ("radtan", "none", "equidistant"):
        raise InputError(f"{where}.distortion_model: {dmodel!r}; hvloc's lenses are radial-tangential (radtan) "
                         "and equidistant (Kannala-Brandt fisheye)")
    try:
        fx, fy, cx, cy = (float(v) for v in c["intrinsics"])
        w, h = (int(v) for v in c["resolution"])
    except (KeyError, TypeError, ValueError):
        raise InputError(f"{where}: needs intrinsics [fu, fv, pu, pv] and resolution [width, height]") from None
    if dmodel == "equidistant":
        dist = _equidistant(c.get("distortion_coeffs", [0, 0, 0, 0]), f"{where}.distortion_coeffs")
        return _checked(w, h, fx, fy, cx, cy, dist, f"Kalibr {name}", where, "fisheye")
    dist = _radtan(c.get("distortion_coeffs", [0, 0, 0, 0]) if dmodel == "radtan" else [0, 0, 0, 0],
                   f"{where}.distortion_coeffs")
    return _checked(w, h, fx, fy, cx, cy, dist, f"Kalibr {name}", where)


def _ros(doc: dict, path: str) -> Calibration:
    model = doc.get("distortion_model", "plumb_bob")
    if model not in ("plumb_bob", "rational_polynomial", "equidistant"):
        raise InputError(f"{path}: distortion_model: {model!r}; hvloc's lenses are plumb_bob (radial-tangential) "
                         "and equidistant (Kannala-Brandt fisheye)")
    try:
        K = doc["camera_matrix"]["data"]
        D = (doc.get("distortion_coefficients") or {}).get("data", [])
        w, h = int(doc["image_width"]), int(doc["image_height"])
    except (KeyError, TypeError, ValueError):
        raise InputError(f"{path}: a ROS CameraInfo YAML needs image_width, image_height and camera_matrix.data") from None
    fx, fy, cx, cy = _camera_matrix(K, f"{path}: camera_matrix")
    name = f"ROS CameraInfo {doc.get('camera_name', '')}".strip()
    if model == "equidistant":
        return _checked(w, h, fx, fy, cx, cy, _equidistant(D or [0, 0, 0, 0], f"{path}: distortion_coefficients"),
                        name, path, "fisheye")
    dist = _radtan(D or [0, 0, 0, 0], f"{path}: distortion_coefficients")
    return _checked(w, h, fx, fy, cx, cy, dist, name, path)


def _opencv(path: str, model: str | None = None) -> Calibration:
    """``model``: ``fisheye`` for a file of ``cv2.fisheye.calibrate`` (it writes K and D as
    ``cv2.calibrateCamera`` does, so the file alone cannot say), unless a ``distortion_model``
    string in the file says it."""
    import cv2

    try:
        fs = cv2.FileStorage(path, cv2.FILE_STORAGE_READ)
    except cv2.error as err:
        raise InputError(f"{path}: not an OpenCV FileStorage file ({str(err).strip().splitlines()[-1]})") from None
    try:
        def node(*names):
            for n in names:
                nd = fs.getNode(n)
                if not nd.empty():
                    return n, nd
            return None, None

        kname, k = node("camera_matrix", "cameraMatrix", "K", "intrinsic_matrix")
        if k is None:
            raise InputError(f"{path}: no camera_matrix (or cameraMatrix, K) in this OpenCV file")
        fx, fy, cx, cy = _camera_matrix(k.mat(), f"{path}: {kname}")
        dname, d = node("distortion_coefficients", "dist_coeffs", "distCoeffs", "D", "distortion")
        _, dm = node("distortion_model", "camera_model")
        said = dm.string().strip().lower() if dm is not None and dm.isString() else ""
        if said in ("fisheye", "equidistant", "kannala_brandt", "kb4"):
            said = "fisheye"
        elif said in ("", "plumb_bob", "radtan", "radial-tangential", "pinhole"):
            said = "pinhole" if said else ""
        else:
            raise InputError(f"{path}: distortion_model: {said!r}; hvloc's lenses are plumb_bob (radial-tangential) "
                             "and fisheye (equidistant)")
        if model and said and model != said:
            raise InputError(f"{path}: distortion_model says {said}, --model says {model}")
        model = model or said or "pinhole"
        coeffs = d.mat() if d is not None else [0, 0, 0, 0]
        dist = _equidistant(coeffs, f"{path}: {dname}") if model == "fisheye" else _radtan(coeffs, f"{path}: {dname}")
        _, w = node("image_width", "width")
        _, h = node("image_height", "height")
        if w is not None and h is not None:
            size = (int(w.real()), int(h.real()))
        else:
            sname, s = node("image_size", "imageSize")
            if s is None:
                raise InputError(f"{path}: no image size (image_width and image_height, or image_size)")
            v = [s.at(i).real() for i in range(s.size())] if s.isSeq() else s.mat().ravel()
            size = (int(v[0]), int(v[1]))
    finally:
        fs.release()
    return _checked(size[0], size[1], fx, fy, cx, cy, dist, "OpenCV FileStorage", path, model)


def read_calibration(path, name: str | None = None, model: str | None = None) -> Calibration:
    """The calibration in ``path`` (format told by its content); ``name``: the camera of a Kalibr
    camchain (default: the first, ``cam0``); ``model``: the lens model of an OpenCV file, which does
    not say it (``fisheye`` for ``cv2.fisheye.calibrate``'s K and D).  Any problem is an
    :class:`InputError` naming the field."""
    cal = _read_calibration(Path(path), name, model)
    if model and cal.camera.model != model:
        raise InputError(f"{path}: the file says its lens is {cal.camera.model}, --model says {model}")
    return cal


def _read_calibration(p: Path, name: str | None, model: str | None) -> Calibration:
    path = p
    text = read_user_text(p, "a calibration")
    head = text.lstrip()[:200]
    if head.startswith("%YAML") or head.startswith("<?xml") or "opencv-matrix" in text or p.suffix.lower() == ".xml":
        return _opencv(str(p), model)
    from pad_design.errors import yaml_load

    try:
        doc = yaml_load(text)
    except Exception as err:  # noqa: BLE001 - any parser complaint is the user's file
        if p.suffix.lower() == ".json":
            return _opencv(str(p), model)
        raise InputError(f"{path}: not valid YAML ({str(err).splitlines()[0]})") from None
    if not isinstance(doc, dict):
        raise InputError(f"{path}: not a calibration (expected a mapping at the top)")
    if any(isinstance(v, dict) and "intrinsics" in v for v in doc.values()):
        return _kalibr(doc, name, str(path))
    if "camera_matrix" in doc and isinstance(doc["camera_matrix"], dict) and "data" in doc["camera_matrix"]:
        return _ros(doc, str(path))
    if p.suffix.lower() == ".json":
        return _opencv(str(p), model)
    raise InputError(f"{path}: not a Kalibr camchain, a ROS CameraInfo YAML or an OpenCV FileStorage file")
