"""The geometry leaf agrees with OpenCV, and its transforms go the way their names say."""
import math

import cv2
import numpy as np
import pytest

from hvloc import geometry as g


def random_rotation(rng):
    return g.so3_exp(rng.normal(size=3) * rng.uniform(0, math.pi) / math.sqrt(3))


DISTORTIONS = [(0, 0, 0, 0, 0), (-0.28, 0.09, 0.0012, -0.0008, -0.012), (0.12, -0.05, -0.002, 0.001, 0.01)]


@pytest.mark.parametrize("dist", DISTORTIONS)
def test_project_matches_opencv(dist):
    rng = np.random.default_rng(1)
    cam = g.Camera(1920, 1080, 1100.0, 1105.0, 955.3, 541.7, dist)
    for _ in range(20):
        R = random_rotation(rng)
        t = rng.uniform(-1, 1, 3) + [0, 0, 6]
        P = rng.uniform(-2, 2, (50, 3))
        P[:, 2] = 0.0
        cam2world = g.invert(g.make_transform(R, t))  # T_W_C, with T_C_W = (R, t)
        Pc = g.transform_points(g.invert(cam2world), P)
        keep = Pc[:, 2] > 0.5
        # keep points within the lens's sensible domain (|x/z|, |y/z| < 1)
        keep &= np.all(np.abs(Pc[:, :2] / Pc[:, 2:]) < 0.9, axis=1)
        if keep.sum() < 5:
            continue
        ours = cam.project_from(cam2world, P[keep])
        ref, _ = cv2.projectPoints(P[keep], cv2.Rodrigues(R)[0], t, cam.K, np.array(dist, float))
        np.testing.assert_allclose(ours, ref[:, 0, :], atol=1e-6)


@pytest.mark.parametrize("dist", DISTORTIONS)
def test_undistort_matches_opencv_and_inverts_project(dist):
    rng = np.random.default_rng(2)
    cam = g.Camera(1920, 1080, 1100.0, 1105.0, 955.3, 541.7, dist)
    xy = rng.uniform(-0.75, 0.75, (400, 2))
    px = cam.project(np.column_stack([xy, np.ones(len(xy))]))
    # ours inverts the forward model to numerical precision
    np.testing.assert_allclose(cam.normalized_from_pixels(px), xy, atol=1e-9)
    # OpenCV's iterative solver agrees (its default iteration count is looser, so ask for more)
    ref = cv2.undistortPoints(px.reshape(-1, 1, 2), cam.K, np.array(dist, float), None, None, None,
                                  (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12))[:, 0, :]
    np.testing.assert_allclose(cam.normalized_from_pixels(px), ref, atol=1e-6)
    # unproject at depth 3 then project returns the pixel
    P = cam.unproject(px, 3.0)
    np.testing.assert_allclose(P[:, 2], 3.0)
    np.testing.assert_allclose(cam.project(P), px, atol=1e-6)
    # the ideal pinhole's pixels and the lens's, both ways
    ideal = cam.undistort_pixels(px)
    np.testing.assert_allclose(ideal, xy * [cam.fx, cam.fy] + [cam.cx, cam.cy], atol=1e-6)
    np.testing.assert_allclose(cam.distort_pixels(ideal), px, atol=1e-6)


FISHEYES = [(0.0, 0.0, 0.0, 0.0), (-0.013, 0.021, -0.009, 0.0015), (0.08, -0.02, 0.004, -0.0003)]


@pytest.mark.parametrize("dist", FISHEYES)
def test_fisheye_matches_opencv_fisheye_out_to_80_degrees(dist):
    """The fisheye model is OpenCV's (Kannala-Brandt), forwards and backwards, for rays up to 80
    degrees off the axis; rays at 90 degrees or more have no normalised coordinates."""
    cam = g.Camera(1280, 960, 420.0, 421.5, 641.2, 478.9, dist, "fisheye")
    rng = np.random.default_rng(4)
    th, ph = rng.uniform(0, math.radians(80), 600), rng.uniform(-math.pi, math.pi, 600)
    P = np.column_stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)]) * rng.uniform(0.5, 9, (600, 1))
    ours = cam.project(P)
    ref, _ = cv2.fisheye.projectPoints(P.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, np.array(dist))
    np.testing.assert_allclose(ours, ref[:, 0, :], atol=1e-6)
    xy = cam.normalized_from_pixels(ours)
    np.testing.assert_allclose(xy, P[:, :2] / P[:, 2:], rtol=1e-9, atol=1e-9)
    ref = cv2.fisheye.undistortPoints(ours.reshape(-1, 1, 2), cam.K, np.array(dist))[:, 0, :]
    np.testing.assert_allclose(xy, ref, rtol=1e-6, atol=1e-6)
    # a point beyond the lens's 90 degrees (theta_d past pi/2 on the equidistant lens) has no ray
    if dist == FISHEYES[0]:
        assert np.isnan(cam.normalized_from_pixels([[cam.cx + cam.fx * 1.7, cam.cy]])).all()
    # a fisheye always distorts; it survives camera.json, scaling and cropping
    assert cam.has_distortion and g.Camera.from_dict(cam.to_dict()) == cam
    assert cam.scaled(2).model == "fisheye" and cam.shifted(5, 7).cx == cam.cx - 5
    with pytest.raises(ValueError, match="4 values for the fisheye"):
        g.Camera(10, 10, 5, 5, 4.5, 4.5, (0.1, 0, 0, 0, 0), "fisheye")
    with pytest.raises(ValueError, match="model"):
        g.Camera(10, 10, 5, 5, 4.5, 4.5, (0, 0, 0, 0), "omni")


def test_quaternion_conventions_hamilton_xyzw():
    # 90 degrees about z maps x to y (Hamilton, active); TUM order puts qw last
    R = g.so3_exp([0, 0, math.pi / 2])
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    q = g.quat_xyzw_from_matrix(R)
    np.testing.assert_allclose(q, [0, 0, math.sin(math.pi / 4), math.cos(math.pi / 4)], atol=1e-12)
    rng = np.random.default_rng(3)
    for _ in range(200):
        R = random_rotation(rng)
        q = g.quat_xyzw_from_matrix(R)
        assert q[3] >= 0 and abs(np.linalg.norm(q) - 1) < 1e-12
        np.testing.assert_allclose(g.matrix_from_quat_xyzw(q), R, atol=1e-12)
        np.testing.assert_allclose(g.so3_exp(g.so3_log(R)), R, atol=1e-9)
        # agree with OpenCV's Rodrigues on the rotation vector
        np.testing.assert_allclose(cv2.Rodrigues(R)[0].ravel(), g.so3_log(R), atol=1e-7)


def test_transform_direction_and_tum_roundtrip():
    # cam2pad = T_P_C: its translation is the camera position in the pad frame
    T_P_C = g.make_transform(g.so3_exp([math.pi, 0, 0]), [0.1, -0.2, 3.0])
    origin_C = np.zeros((1, 3))
    np.testing.assert_allclose(g.transform_points(T_P_C, origin_C)[0], [0.1, -0.2, 3.0])
    # the pad origin is 3 m in front of the camera looking down
    np.testing.assert_allclose(g.transform_points(g.invert(T_P_C), [[0.1, -0.2, 0.0]])[0], [0, 0, 3.0], atol=1e-12)
    row = g.tum_from_transform(T_P_C)
    np.testing.assert_allclose(g.transform_from_tum(row), T_P_C, atol=1e-12)
    np.testing.assert_allclose(g.compose(T_P_C, g.invert(T_P_C)), np.eye(4), atol=1e-12)


def test_camera_validation_and_scaling():
    with pytest.raises(ValueError, match="dist"):
        g.Camera(10, 10, 5, 5, 4.5, 4.5, (0, 0, 0))
    with pytest.raises(ValueError, match="fx"):
        g.Camera(10, 10, -5, 5, 4.5, 4.5)
    cam = g.Camera.from_hfov(800, 800, math.radians(60))
    assert abs(cam.fx - 400 / math.tan(math.radians(30))) < 1e-9 and cam.cx == 399.5
    # a point's pixel scales with the resolution under the pixel-centre convention
    P = np.array([[0.3, -0.2, 2.0]])
    np.testing.assert_allclose((cam.scaled(2).project(P) + 0.5), (cam.project(P) + 0.5) * 2, atol=1e-9)
    with pytest.raises(ValueError, match="shape"):
        cam.project(np.zeros((3, 2)))


def test_projection_sigma_is_the_spread_of_the_pose_covariance_in_the_image():
    """``projection_sigma_px``: how far a point's image may move under a pose's covariance, to first
    order; checked against poses drawn from that covariance (position, then the rotation vector
    about the camera's axes, as the covariance is parametrised)."""
    import dataclasses

    from hvloc.pose import projection_sigma_px
    from render.planar import nadir_cam2pad

    cam = dataclasses.replace(g.Camera.from_hfov(1280, 720, math.radians(100)), dist=(-0.2, 0.03, 0.0, 0.0, 0.0))
    T = nadir_cam2pad(0.3, -0.2, 4.0, 0.7)
    A = np.diag([0.02, 0.01, 0.03, 0.004, 0.006, 0.002]) + 0.002
    cov = A @ A.T
    pts = np.array([[0.5, 0.5, 0.0], [-0.5, 0.5, 0.0], [-0.5, -0.5, 0.0], [0.1, -0.3, 0.0]])
    predicted = projection_sigma_px(cam, T, cov, pts)
    rng = np.random.default_rng(3)
    draws = rng.multivariate_normal(np.zeros(6), cov, 4000)
    base = cam.project_from(T, pts)
    moved = []
    for d in draws:
        Td = T.copy()
        Td[:3, 3] += d[:3]
        Td[:3, :3] = T[:3, :3] @ g.so3_exp(d[3:])
        moved.append(cam.project_from(Td, pts) - base)
    spread = np.sqrt(np.mean(np.square(moved), axis=(0, 2)))
    assert np.all(predicted > 0.5)  # pixels, not a vanishing number
    np.testing.assert_allclose(predicted, spread, rtol=0.06)


def test_srgb_to_linear_is_the_srgb_curve_for_any_shape():
    """8-bit sRGB to linear light on the 0..255 scale, by the sRGB standard's piecewise curve, for
    colours, grey images, RGB and RGBA images, strided views and other shapes alike (OpenCV's LUT
    does most of them, numpy's indexing the rest: the same numbers)."""
    from hvloc.features import srgb_to_linear

    def srgb(v):
        c = np.asarray(v, np.float64) / 255.0
        return 255.0 * np.where(c <= 10 / 255.0, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)

    rng = np.random.default_rng(3)
    for shape in [(5,), (2, 3), (7, 9), (7, 9, 3), (7, 9, 4), (7, 9, 5), (2, 3, 4, 3)]:
        a = rng.integers(0, 256, shape).astype(np.uint8)
        for v in (a, a[::2]):
            out = srgb_to_linear(v)
            assert out.shape == v.shape and out.dtype == np.float32, shape
            np.testing.assert_allclose(out, srgb(v), rtol=1e-6, atol=1e-5)
    assert srgb_to_linear(np.arange(256, dtype=np.uint8)).max() == np.float32(255.0)
    np.testing.assert_allclose(srgb_to_linear([[198, 51, 176]]), srgb([[198, 51, 176]]), rtol=1e-6)


def test_rotvec_between_is_the_least_rotation_taking_one_direction_onto_another():
    """It takes ``a`` onto ``b`` (unnormalised in), about an axis normal to both, by their angle; zero
    for parallel or opposite directions (no axis is least for a half turn)."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        a, b = rng.normal(size=3) * rng.uniform(0.1, 10.0), rng.normal(size=3)
        r = g.rotvec_between(a, b)
        ua, ub = a / np.linalg.norm(a), b / np.linalg.norm(b)
        np.testing.assert_allclose(g.so3_exp(r) @ ua, ub, atol=1e-9)
        assert abs(r @ ua) < 1e-9 and abs(r @ ub) < 1e-9
        assert math.isclose(np.linalg.norm(r), math.acos(np.clip(ua @ ub, -1.0, 1.0)), abs_tol=1e-7)
    assert not g.rotvec_between([0, 0, 1], [0, 0, 3]).any() and not g.rotvec_between([0, 0, 1], [0, 0, -1]).any()
    # a pad tilted 5 degrees about world x: its normal's rotation vector from up is (5 deg, 0, 0)
    n = g.so3_exp([math.radians(5.0), 0.0, 0.0]) @ np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(g.rotvec_between([0, 0, 1], n), [math.radians(5.0), 0.0, 0.0], atol=1e-12)
