"""Exports read back with the ecosystem's own readers: EuRoC/ASL as its loaders parse it (CSV with
a '#' header, Kalibr-style YAML), ROS 2 bags with ``rosbags``, COCO with ``pycocotools``; the
MAVLink stream with ``pymavlink``.  Values are checked against the dataset, frames composed."""
import json
import math

import numpy as np
import pytest
import yaml

from hvloc.geometry import invert, matrix_from_quat_xyzw, transform_from_tum
from render.dataset import Dataset
from render.export import DEFAULT_EPOCH_S, export_dataset
from render.generate import generate
from render.spec import DatasetSpec
from tests.conftest import assert_input_error, run_cli

SPEC = {"name": "extiny", "seed": 4, "sequences": 2, "pad_ppm": 800,
        "camera": {"width": 160, "height": 120, "fps": 5, "dist": [-0.12, 0.02, 0.0005, -0.0004, 0.003]},
        "trajectory": {"start_height_m": 4.0, "duration_s": [4.0, 4.0], "lateral_offset_m": [0.0, 0.3],
                       "families": ["straight"]}}


@pytest.fixture(scope="module")
def ds(tmp_path_factory):
    root = tmp_path_factory.mktemp("export") / "ds"
    generate(DatasetSpec.model_validate(SPEC), root, show_progress=False)
    return Dataset(root)


def _T(p7):
    return transform_from_tum(p7)


def test_euroc_layout_values_and_frames(ds, tmp_path):
    res = export_dataset("euroc", ds.root, tmp_path, epoch_s=1.6e9)
    assert [p.name for p in res["paths"]] == ds.sequence_ids and res["bytes"] > 0
    seq = ds[0]
    mav = tmp_path / seq.id / "mav0"
    cam = np.loadtxt(mav / "cam0" / "data.csv", delimiter=",", dtype=str, skiprows=1)
    stamps = cam[:, 0].astype(np.int64)
    assert len(stamps) == len(seq) and stamps[0] == 1_600_000_000 * 10**9 and np.all(np.diff(stamps) > 0)
    assert np.allclose((stamps - stamps[0]) * 1e-9, seq.t, atol=1e-9)
    for k in (0, len(seq) - 1):
        assert (mav / "cam0" / "data" / cam[k, 1]).read_bytes() == seq.image_path(k).read_bytes()
    sensor = yaml.safe_load((mav / "cam0" / "sensor.yaml").read_text())
    c = seq.camera
    assert sensor["intrinsics"] == [c.fx, c.fy, c.cx, c.cy] and sensor["resolution"] == [c.width, c.height]
    assert sensor["distortion_coefficients"] == list(c.dist[:4]) and sensor["k3"] == c.dist[4]
    T_BS = np.array(sensor["T_BS"]["data"]).reshape(4, 4)
    assert np.allclose(T_BS, seq.T_B_C)
    imu_yaml = yaml.safe_load((mav / "imu0" / "sensor.yaml").read_text())
    spec = ds.manifest["spec"].get("imu", {})
    rate = imu_yaml["rate_hz"]
    # a noise density times sqrt(rate) is the per-sample std the generator drew
    assert imu_yaml["gyroscope_noise_density"] * math.sqrt(rate) == pytest.approx(spec.get("gyro_noise_rad_s", 0.003))
    assert imu_yaml["accelerometer_random_walk"] == pytest.approx(spec.get("accel_bias_walk_mps3", 0.001))
    imu = np.loadtxt(mav / "imu0" / "data.csv", delimiter=",", comments="#")
    assert imu.shape == (len(seq.imu), 7) and np.allclose(imu[:, 1:], seq.imu[:, 1:7])
    gt = np.loadtxt(mav / "state_groundtruth_estimate0" / "data.csv", delimiter=",", comments="#")
    pad = np.loadtxt(mav / "pad_groundtruth0" / "data.csv", delimiter=",", comments="#")
    assert gt.shape == (len(seq), 17) and np.array_equal(gt[:, 0].astype(np.int64), stamps)
    for k in range(len(seq)):
        p, q_wxyz = gt[k, 1:4], gt[k, 4:8]
        T_W_B = np.eye(4)
        T_W_B[:3, :3], T_W_B[:3, 3] = matrix_from_quat_xyzw(np.r_[q_wxyz[1:], q_wxyz[0]]), p
        T_W_P = np.eye(4)
        T_W_P[:3, :3], T_W_P[:3, 3] = matrix_from_quat_xyzw(np.r_[pad[k, 5:8], pad[k, 4]]), pad[k, 1:4]
        # body pose (EuRoC ground truth) and camera mount give the labelled camera pose in the pad frame
        assert np.allclose(invert(T_W_P) @ T_W_B @ T_BS, seq.frame(k).cam2pad, atol=1e-9)
    # the biases are the true ones inside the IMU samples: gyro minus bias is near the true rate
    assert np.all(np.isfinite(gt[:, 11:17])) and np.abs(gt[:, 11:14]).max() < 0.05


def test_the_imu_noise_densities_count_the_airframes_vibration():
    """A filter tuned from sensor.yaml for a vibrating airframe must not trust each sample more than
    its vibration allows: the densities carry the vibration's rms with the sensor's white noise."""
    from render.export import imu_noise_model
    from render.spec import ImuSpec

    quiet = imu_noise_model(ImuSpec().model_dump())
    shaken = imu_noise_model(ImuSpec(vibration_accel_mps2=2.0, vibration_gyro_rad_s=0.1).model_dump())
    rate = math.sqrt(200.0)
    assert quiet["accelerometer_noise_density"] == pytest.approx(0.03 / rate)
    assert shaken["accelerometer_noise_density"] == pytest.approx(math.hypot(0.03, 2.0) / rate)
    assert shaken["gyroscope_noise_density"] == pytest.approx(math.hypot(0.003, 0.1) / rate)
    assert shaken["accelerometer_random_walk"] == quiet["accelerometer_random_walk"]


def test_rosbag2_reads_back_with_rosbags(ds, tmp_path):
    from rosbags.interfaces import QosDurability
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    export_dataset("rosbag2", ds.root, tmp_path, sequences=[ds.sequence_ids[1]])
    seq = ds[1]
    store = get_typestore(Stores.ROS2_HUMBLE)
    msgs: dict = {}
    with Reader(tmp_path / seq.id) as r:
        counts = {c.topic: c.msgcount for c in r.connections}
        qos = {c.topic: c.ext.offered_qos_profiles for c in r.connections}
        for conn, stamp, raw in r.messages():
            msgs.setdefault(conn.topic, []).append((stamp, store.deserialize_cdr(raw, conn.msgtype)))
    n, m = len(seq), len(seq.imu)
    assert counts == {"/camera/image_raw": n, "/camera/camera_info": n, "/imu/data": m, "/ground_truth/body_pose": n,
                      "/ground_truth/camera_in_pad": n, "/tf": n, "/tf_static": 1}
    assert qos["/tf_static"][0].durability == QosDurability.TRANSIENT_LOCAL
    epoch = DEFAULT_EPOCH_S * 10**9
    stamp, img = msgs["/camera/image_raw"][3]
    h = img.header.stamp
    assert stamp == h.sec * 10**9 + h.nanosec == epoch + round(seq.t[3] * 1e9) and h.sec > 10**9
    assert img.encoding == "rgb8" and np.array_equal(img.data.reshape(img.height, img.width, 3), seq.image(3))
    info = msgs["/camera/camera_info"][0][1]
    assert np.allclose(info.k.reshape(3, 3), seq.camera.K) and np.allclose(info.d, seq.camera.dist)
    assert info.distortion_model == "plumb_bob" and info.header.frame_id == "camera_optical"
    _, imu = msgs["/imu/data"][7]
    row = seq.imu[7]
    assert [imu.angular_velocity.x, imu.linear_acceleration.z] == pytest.approx([row[1], row[6]])
    assert [imu.orientation.x, imu.orientation.w] == pytest.approx([row[7], row[10]])
    assert imu.angular_velocity_covariance[0] > 0
    # tf: world->base_link, base_link->camera_optical (static) and world->pad compose to the label
    static = msgs["/tf_static"][0][1].transforms[0]
    assert (static.header.frame_id, static.child_frame_id) == ("base_link", "camera_optical")

    def T(tr):
        t, q = tr.transform.translation, tr.transform.rotation
        return _T([t.x, t.y, t.z, q.x, q.y, q.z, q.w])

    for k in (0, n // 2, n - 1):
        tfs = {tr.child_frame_id: tr for tr in msgs["/tf"][k][1].transforms}
        cam2pad = invert(T(tfs["pad"])) @ T(tfs["base_link"]) @ T(static)
        assert np.allclose(cam2pad, seq.frame(k).cam2pad, atol=1e-9)
        p = msgs["/ground_truth/camera_in_pad"][k][1].pose
        assert p.position.z == pytest.approx(seq.frame(k).height_above_pad)


def test_coco_keypoints_load_with_pycocotools(ds, tmp_path):
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    path = export_dataset("coco", ds.root, tmp_path)["paths"][0]
    coco = COCO(str(path))
    cat = coco.loadCats(1)[0]
    names = cat["keypoints"]
    geometry = ds[0].pad.geometry
    assert len(names) == 4 + sum(len(m.points) for m in geometry.markers)
    assert len(coco.getImgIds()) == sum(len(s) for s in ds)
    pads = coco.loadAnns(coco.getAnnIds(catIds=[1]))
    in_view = sum(int((s.columns["pad_visible_fraction"] > 0).sum()) for s in ds)
    assert len(pads) == in_view > 0.8 * len(coco.getImgIds())  # one pad annotation wherever the pad is seen
    checked = 0
    for a in pads:
        img = coco.loadImgs(a["image_id"])[0]
        seq = ds[img["sequence"]]
        f = seq.frame(img["frame"])
        kp = np.array(a["keypoints"]).reshape(-1, 3)
        for i in range(4):  # the outer corners exactly as labelled, their visibility from the labels
            if np.isfinite(f.corners_px[i]).all():
                assert kp[i, :2] == pytest.approx(f.corners_px[i], abs=1e-3)
                assert kp[i, 2] == (2 if f.corners_visible[i] else 1)
            else:
                assert kp[i, 2] == 0
        seen = kp[4:, 2] == 2
        if seen.any():  # marker corners: the labelled pose through the lens model
            P = np.concatenate([m.points for m in geometry.markers])
            px = seq.camera.project_from(f.cam2pad, P)
            assert np.abs(kp[4:][seen, :2] - px[seen]).max() < 1e-3
            checked += 1
        x, y, w, h = a["bbox"]
        assert -0.5 <= x and x + w <= img["width"] - 0.5 + 1e-6 and a["area"] <= w * h + 1e-6
        if f.pad_fully_visible:  # the box holds the projected outline
            assert x <= np.nanmin(f.corners_px[:, 0]) + 1e-3 and x + w >= np.nanmax(f.corners_px[:, 0]) - 1e-3
    assert checked > 5
    assert coco.getAnnIds(catIds=[2])  # finder marker boxes
    # the file is a valid detection ground truth: evaluated against itself it scores AP 1
    dets = coco.loadRes([{**a, "score": 1.0} for a in coco.loadAnns(coco.getAnnIds())])
    ev = COCOeval(coco, dets, "bbox")
    ev.evaluate()
    ev.accumulate()
    ev.summarize()
    assert ev.stats[0] == pytest.approx(1.0)


def test_export_cli_and_its_errors(ds, tmp_path):
    r = run_cli("export", "euroc", ds.root, "--out", tmp_path / "e", "--sequence", "seq_0000", "-q")
    assert r.returncode == 0 and r.stderr == "" and (tmp_path / "e" / "seq_0000" / "mav0").is_dir(), r.stderr
    assert not (tmp_path / "e" / "seq_0001").exists() and not list((tmp_path / "e").glob(".tmp-*"))
    assert_input_error(run_cli("export", "euroc", ds.root, "--out", tmp_path / "x", "--sequence", "seq_0042"),
                       "seq_0042")
    assert_input_error(run_cli("export", "coco", tmp_path / "nothing", "--out", tmp_path / "y"), "nothing")
    assert_input_error(run_cli("export", "rosbag2", ds.root, "--out", tmp_path / "z", "--epoch", "nan"), "--epoch")
    # a second export over the first replaces it whole
    r = run_cli("export", "euroc", ds.root, "--out", tmp_path / "e", "--sequence", "seq_0000", "-q")
    assert r.returncode == 0 and len(list((tmp_path / "e" / "seq_0000" / "mav0" / "cam0" / "data").iterdir())) == len(ds[0])
    assert json.loads(json.dumps({"ok": True}))


def _landing_target_expected(row_pose, T_B_C):
    """Independently: the pad centre and orientation in the body's FRD frame."""
    T_P_C = _T(row_pose)
    T_B_P = T_B_C @ invert(T_P_C)
    flip = np.diag([1.0, -1.0, -1.0])
    return flip @ T_B_P[:3, 3], flip @ T_B_P[:3, :3]


def test_mavlink_landing_target_file_and_udp_decode_with_pymavlink(ds, tmp_path):
    import socket

    from pymavlink import mavutil
    from pymavlink.dialects.v20 import common as mav

    from benchmarks.run import localize_dataset, read_estimates

    tlog = tmp_path / "lt.tlog"
    r = run_cli("localize", ds.root, "--out", tmp_path / "est", "--mavlink", tlog, "-q")
    assert r.returncode == 0 and "LANDING_TARGET" in r.stdout, r.stderr
    conn = mavutil.mavlink_connection(str(tlog))
    msgs = []
    while (m := conn.recv_match(type="LANDING_TARGET")) is not None:
        msgs.append(m)
    rows = []
    for seq in ds:
        c = read_estimates(tmp_path / "est" / seq.id / "estimates.csv")
        rows += [(seq, k, c) for k in range(len(c["t"])) if c["status"][k] == "ok"]
    assert len(msgs) == len(rows) > 10
    for m, (seq, k, c) in zip(msgs, rows):
        pose = [float(c[n][k]) for n in ("tx", "ty", "tz", "qx", "qy", "qz", "qw")]
        p, R = _landing_target_expected(pose, seq.T_B_C)
        assert m.frame == mav.MAV_FRAME_BODY_FRD and m.position_valid == 1
        assert m.type == mav.LANDING_TARGET_TYPE_VISION_FIDUCIAL
        assert [m.x, m.y, m.z] == pytest.approx(p, abs=1e-5) and m.distance == pytest.approx(np.linalg.norm(p), abs=1e-5)
        q = np.array(m.q)  # w x y z
        assert np.allclose(matrix_from_quat_xyzw(np.r_[q[1:], q[0]]), R, atol=1e-5)
        assert m.time_usec == round(float(c["t"][k]) * 1e6)
        # a downward camera over the pad: the pad is below (FRD z > 0)
        assert m.z > 0
    # the same stream over UDP, as a flight stack receives it
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(5.0)
    port = sock.getsockname()[1]
    res = localize_dataset(ds.root, tmp_path / "est2", show_progress=False, mavlink=f"udp:127.0.0.1:{port}",
                           mavlink_epoch_s=1.7e9)
    parser = mav.MAVLink(None)
    got = []
    for _ in range(res["mavlink_sent"]):
        got += [x for x in parser.parse_buffer(sock.recv(4096)) or [] if x.get_type() == "LANDING_TARGET"]
    sock.close()
    assert len(got) == res["mavlink_sent"] == len(msgs)
    assert got[0].time_usec == msgs[0].time_usec + 1_700_000_000_000_000 and got[-1].x == msgs[-1].x


def test_a_fisheye_exports_as_the_equidistant_model_its_readers_know(tmp_path):
    """EuRoC/Kalibr and ROS call OpenCV's fisheye 'equidistant', with four coefficients; the export
    says so (a radial-tangential line would make every reader undistort it wrongly)."""
    from rosbags.highlevel import AnyReader

    spec = {**SPEC, "name": "exfish", "sequences": 1,
            "camera": {"width": 160, "height": 120, "fps": 5, "model": "fisheye", "hfov_deg": 110,
                       "dist": [0.02, -0.01, 0.002, -0.0002]}}
    generate(DatasetSpec.model_validate(spec), tmp_path / "ds", show_progress=False)
    seq = Dataset(tmp_path / "ds")[0]
    export_dataset("euroc", tmp_path / "ds", tmp_path / "eu", epoch_s=1.6e9)
    sensor = yaml.safe_load((tmp_path / "eu" / seq.id / "mav0" / "cam0" / "sensor.yaml").read_text())
    assert sensor["distortion_model"] == "equidistant" and sensor["distortion_coefficients"] == list(seq.camera.dist)
    assert "k3" not in sensor
    export_dataset("rosbag2", tmp_path / "ds", tmp_path / "rb", epoch_s=1.6e9)
    (meta,) = (tmp_path / "rb").rglob("metadata.yaml")
    with AnyReader([meta.parent]) as r:
        infos = [r.deserialize(raw, c.msgtype) for c, _, raw in r.messages() if c.msgtype.endswith("CameraInfo")]
    assert infos and infos[0].distortion_model == "equidistant" and list(infos[0].d) == list(seq.camera.dist)


def test_a_mono_camera_exports_grey_images_as_its_readers_expect(tmp_path):
    """A monochrome camera (camera.mono) is stored as grey RGB (DESIGN.md's frames are RGB); what
    it exports is what such a camera gives: EuRoC's 8-bit grey PNGs, a ROS 2 bag's mono8, the same
    values."""
    import cv2
    from rosbags.highlevel import AnyReader

    spec = {**SPEC, "name": "exmono", "sequences": 1, "camera": {**SPEC.get("camera", {}), "mono": True}}
    generate(DatasetSpec.model_validate(spec), tmp_path / "ds", show_progress=False)
    seq = Dataset(tmp_path / "ds")[0]
    export_dataset("euroc", tmp_path / "ds", tmp_path / "eu", epoch_s=1.6e9)
    pngs = sorted((tmp_path / "eu" / seq.id / "mav0" / "cam0" / "data").glob("*.png"))
    assert len(pngs) == len(seq)
    grey = cv2.imread(str(pngs[2]), cv2.IMREAD_UNCHANGED)
    assert grey.ndim == 2 and grey.dtype == np.uint8 and np.array_equal(grey, seq.image(2)[..., 0])
    export_dataset("rosbag2", tmp_path / "ds", tmp_path / "rb", epoch_s=1.6e9)
    (meta,) = (tmp_path / "rb").rglob("metadata.yaml")
    with AnyReader([meta.parent]) as r:
        imgs = [r.deserialize(raw, c.msgtype) for c, _, raw in r.messages() if c.topic == "/camera/image_raw"]
    img = imgs[2]
    assert img.encoding == "mono8" and img.step == img.width
    assert np.array_equal(img.data.reshape(img.height, img.width), seq.image(2)[..., 0])
