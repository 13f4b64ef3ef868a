"""Calibrations from the files people have (Kalibr, ROS CameraInfo, OpenCV FileStorage) become a
spec's camera that renders exactly that camera."""
import json
import math

import cv2
import numpy as np
import pytest

from render.calibration import read_calibration
from render.plan import camera_from_spec
from render.spec import CameraSpec, DatasetSpec, load_dataset_spec
from tests.conftest import assert_input_error, run_cli

# EuRoC MAV's cam0 (its sensor.yaml), as Kalibr writes a camchain
KALIBR = """cam0:
  camera_model: pinhole
  intrinsics: [458.654, 457.296, 367.215, 248.375]
  distortion_model: radtan
  distortion_coeffs: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
  resolution: [752, 480]
  rostopic: /cam0/image_raw
cam1:
  camera_model: pinhole
  intrinsics: [457.587, 456.134, 379.999, 255.238]
  distortion_model: radtan
  distortion_coeffs: [-0.28368365, 0.07451284, -0.00010473, -3.55590700e-05]
  resolution: [752, 480]
"""

ROS = """image_width: 160
image_height: 120
camera_name: downward
camera_matrix:
  rows: 3
  cols: 3
  data: [131.5, 0, 80.75, 0, 130.25, 58.5, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.12, 0.015, 0.0004, -0.0003, 0.0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [131.5, 0, 80.75, 0, 0, 130.25, 58.5, 0, 0, 0, 1, 0]
"""


def _same_camera(cal, fields):
    cam = camera_from_spec(CameraSpec.model_validate(fields))
    assert (cam.width, cam.height) == (cal.width, cal.height)
    np.testing.assert_allclose([cam.fx, cam.fy, cam.cx, cam.cy], [cal.fx, cal.fy, cal.cx, cal.cy], rtol=0, atol=1e-9)
    assert tuple(cam.dist) == tuple(cal.dist) and cam.model == cal.camera.model


def test_kalibr_camchain_gives_exactly_its_camera(tmp_path):
    p = tmp_path / "camchain.yaml"
    p.write_text(KALIBR)
    cal = read_calibration(p)
    assert (cal.fx, cal.cy, cal.dist[3], cal.dist[4]) == (458.654, 248.375, 1.76187114e-05, 0.0)
    _same_camera(cal, cal.spec_fields())
    assert read_calibration(p, "cam1").cx == 379.999


def test_ros_camera_info_gives_exactly_its_camera(tmp_path):
    p = tmp_path / "ost.yaml"
    p.write_text(ROS)
    cal = read_calibration(p)
    assert (cal.width, cal.fx, cal.fy, cal.cx, cal.cy) == (160, 131.5, 130.25, 80.75, 58.5)
    _same_camera(cal, cal.spec_fields())


@pytest.mark.parametrize("suffix", ["yaml", "xml", "json"])
def test_opencv_filestorage_gives_exactly_its_camera(tmp_path, suffix):
    p = tmp_path / f"calib.{suffix}"
    K = np.array([[612.25, 0, 319.5], [0, 611.75, 241.125], [0, 0, 1]])
    D = np.array([[0.05, -0.1, 0.001, 0.002, 0.03]])
    fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 640)
    fs.write("image_height", 480)
    fs.write("camera_matrix", K)
    fs.write("distortion_coefficients", D)
    fs.release()
    cal = read_calibration(p)
    assert (cal.width, cal.height, cal.fx, cal.cy) == (640, 480, 612.25, 241.125)
    assert cal.dist == tuple(D.ravel())
    _same_camera(cal, cal.spec_fields())


def test_fisheye_calibrations_become_the_same_fisheye_camera(tmp_path):
    """Kalibr's and ROS's equidistant model is OpenCV's fisheye (Kannala-Brandt): read as such, and
    the spec fields it gives render exactly that camera."""
    p = tmp_path / "fish.yaml"
    p.write_text(KALIBR.replace("distortion_model: radtan", "distortion_model: equidistant", 1))
    cal = read_calibration(p)
    assert cal.camera.model == "fisheye" and cal.dist == (-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05)
    fields = cal.spec_fields()
    assert fields["model"] == "fisheye"
    _same_camera(cal, fields)
    assert camera_from_spec(CameraSpec.model_validate(fields)).model == "fisheye"
    p.write_text(ROS.replace("plumb_bob", "equidistant").replace("data: [-0.12, 0.015, 0.0004, -0.0003, 0.0]",
                                                                   "data: [0.01, -0.002, 0.0005, 0.0]"))
    cal = read_calibration(p)
    assert cal.camera.model == "fisheye" and cal.dist == (0.01, -0.002, 0.0005, 0.0)
    _same_camera(cal, cal.spec_fields())
    p.write_text(ROS.replace("plumb_bob", "equidistant"))  # five coefficients: not the equidistant model
    assert_input_error(run_cli("camera", "import", p), "distortion_coefficients")
    # an OpenCV file of cv2.fisheye.calibrate (K and D, as calibrateCamera writes them): --model says it,
    # or a distortion_model string in the file does
    o = tmp_path / "fish_cv.yaml"
    fs = cv2.FileStorage(str(o), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 1280)
    fs.write("image_height", 960)
    fs.write("K", np.array([[600.5, 0, 641.0], [0, 601.0, 479.5], [0, 0, 1]]))
    fs.write("D", np.array([[0.03], [-0.01], [0.002], [-0.0003]]))
    fs.release()
    assert read_calibration(o).camera.model == "pinhole"  # four radial-tangential coefficients, as far as it can tell
    cal = read_calibration(o, model="fisheye")
    assert cal.camera.model == "fisheye" and cal.dist == (0.03, -0.01, 0.002, -0.0003)
    _same_camera(cal, cal.spec_fields())
    r = run_cli("camera", "import", o, "--model", "fisheye")
    assert r.returncode == 0 and "model: fisheye" in r.stdout and "fisheye k1 k2 k3 k4" in r.stdout, r.stderr
    fs = cv2.FileStorage(str(o), cv2.FILE_STORAGE_APPEND)
    fs.write("distortion_model", "equidistant")
    fs.release()
    assert read_calibration(o).camera.model == "fisheye"
    assert_input_error(run_cli("camera", "import", o, "--model", "pinhole"), "--model says pinhole")


def test_models_hvloc_cannot_render_are_refused_with_the_field_named(tmp_path):
    p = tmp_path / "omni.yaml"
    p.write_text(KALIBR.replace("camera_model: pinhole", "camera_model: omni", 1))
    assert_input_error(run_cli("camera", "import", p), "cam0.camera_model")
    p.write_text(KALIBR.replace("distortion_model: radtan", "distortion_model: fov", 1))
    assert_input_error(run_cli("camera", "import", p), "cam0.distortion_model")
    p.write_text(ROS.replace("data: [131.5, 0, 80.75", "data: [131.5, 2.0, 80.75"))
    assert_input_error(run_cli("camera", "import", p), "skew")
    p.write_text("just: a mapping\n")
    assert_input_error(run_cli("camera", "import", p), "not a Kalibr camchain")
    assert_input_error(run_cli("camera", "import", tmp_path / "nope.yaml"), "cannot read")


def test_imported_camera_renders_labels_that_agree_with_its_images(tmp_path):
    """A ROS calibration into the tiny spec (its other fields kept) renders a dataset that verifies,
    whose camera.json is the calibration."""
    from render.dataset import Dataset, verify_dataset
    from render.generate import generate

    cal_p = tmp_path / "ost.yaml"
    cal_p.write_text(ROS)
    out = tmp_path / "mine.yaml"
    r = run_cli("camera", "import", cal_p, "--spec", "data_specs/tiny.yaml", "--out", out)
    assert r.returncode == 0, r.stderr
    spec = load_dataset_spec(out)
    assert spec.camera.fps == 10 and spec.camera.exposure_s == 0.01 and spec.name == "tiny"  # the rest kept
    short = DatasetSpec.model_validate({**json.loads(spec.canonical_json()), "sequences": 1,
                                        "trajectory": {**json.loads(spec.canonical_json())["trajectory"],
                                                       "start_height_m": 2.5, "duration_s": [2.0, 2.0],
                                                       "lateral_offset_m": [0.0, 0.3]}})
    generate(short, tmp_path / "ds", show_progress=False)
    assert verify_dataset(tmp_path / "ds") == []
    cam = json.loads((tmp_path / "ds" / "seq_0000" / "camera.json").read_text())
    assert [cam[k] for k in ("width", "height")] == [160, 120]
    assert all(math.isclose(cam[k], v, abs_tol=1e-9) for k, v in (("fx", 131.5), ("fy", 130.25), ("cx", 80.75),
                                                                  ("cy", 58.5)))
    assert Dataset(tmp_path / "ds")["seq_0000"].camera.dist == (-0.12, 0.015, 0.0004, -0.0003, 0.0)
    # printed without --spec: a camera block that validates
    r = run_cli("camera", "import", cal_p)
    assert r.returncode == 0 and r.stdout.startswith("# ROS CameraInfo downward") and "camera:" in r.stdout
