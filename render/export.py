"""``hvloc export euroc|rosbag2|coco DATASET --out DIR``: a dataset in the formats other tools read.

Each writer is a thin layer over the dataset reader (:class:`render.dataset.Dataset`): it reads the
labels and images as stored and writes them in another layout, converting nothing but units,
frames and time.  Conventions kept from DESIGN.md: body frame FLU, world ENU, camera OpenCV,
``T_A_B`` maps B coordinates to A.

- **EuRoC/ASL** (``DIR/<seq>/mav0/``): ``cam0`` (images named by their nanosecond stamp, 8-bit grey
  PNGs for a monochrome camera as EuRoC's own,
  ``data.csv``, ``sensor.yaml`` with intrinsics, radial-tangential distortion and ``T_BS`` = the
  camera's mount ``T_B_C``), ``imu0`` (``data.csv``; ``sensor.yaml`` with noise densities and
  random walks from the spec, the IMU frame being the body frame), ``state_groundtruth_estimate0``
  (the body's world pose, velocity and true IMU biases at every frame time) and, an hvloc
  addition, ``pad_groundtruth0`` (the pad's world pose, for moving decks).
- **ROS 2 bag** (``DIR/<seq>/``, written with ``rosbags``, pure Python): ``/camera/image_raw``
  (rgb8; mono8 for a monochrome camera), ``/camera/camera_info`` (plumb_bob), ``/imu/data`` (with covariances), ground-truth
  ``PoseStamped`` of the body in ``world`` and of the camera in ``pad``, and ``/tf`` (world to
  base_link, world to pad) with ``/tf_static`` (base_link to camera_optical, latched).
- **COCO keypoints** (``DIR/coco_keypoints.json``): per image one ``landing_pad`` annotation whose
  keypoints are the pad's four outer corners and every corner of every marker square, with COCO
  visibility, its box, area and outline polygon; one box annotation per marker in view.

Times: stamps are ``epoch + t`` in integer nanoseconds (``--epoch``, default 1 700 000 000 s, so
that no stamp is 0, which ROS reads as "unset").
"""
from __future__ import annotations

import json
import math
import os
import shutil
import time
from pathlib import Path

import cv2
import numpy as np

from hvloc.geometry import quat_xyzw_from_matrix, transform_from_tum
from pad_design.errors import ArgumentParser, InputError, prepare_out_dir, progress_bar

from .dataset import POSE, Dataset, FolderLock, finalize_sequence, write_csv

DEFAULT_EPOCH_S = 1_700_000_000  # 2023-11-14T22:13:20Z
FORMATS = ("euroc", "rosbag2", "coco")


def stamps_ns(t, epoch_s: float = DEFAULT_EPOCH_S) -> np.ndarray:
    """Integer nanoseconds of sequence times ``t`` (s) after ``epoch_s`` (exact for whole-ns times)."""
    return np.int64(round(epoch_s * 1e9)) + np.round(np.asarray(t, np.float64) * 1e9).astype(np.int64)


def _poses(seq, prefix: str = "") -> np.ndarray:
    """``(N, 7)`` poses ``tx ty tz qx qy qz qw`` of a frames.csv pose group (``""``: T_P_C)."""
    return np.column_stack([seq.columns[prefix + c].astype(np.float64) for c in POSE])


def _fresh(path: Path) -> Path:
    if path.exists():
        shutil.rmtree(path)
    return path


# ----------------------------------------------------------------------------- EuRoC / ASL

def imu_noise_model(imu_spec: dict) -> dict:
    """Continuous-time noise densities and random walks (Kalibr / EuRoC ``sensor.yaml`` units)
    from the spec's per-sample white noise and per-sqrt(s) bias walks.  The airframe's vibration
    (``vibration_*``) is counted in the densities as white noise of its rms, as a filter's tuning
    for a flying airframe counts it (its rotors' tone is not white: see :func:`render.imu.vibration`)."""
    rate = float(imu_spec["rate_hz"])
    gyro = math.hypot(imu_spec["gyro_noise_rad_s"], imu_spec.get("vibration_gyro_rad_s", 0.0))
    accel = math.hypot(imu_spec["accel_noise_mps2"], imu_spec.get("vibration_accel_mps2", 0.0))
    return {"rate_hz": rate,
            "gyroscope_noise_density": gyro / math.sqrt(rate),                               # rad/s/sqrt(Hz)
            "gyroscope_random_walk": imu_spec["gyro_bias_walk_rad_s2"],                      # rad/s^2/sqrt(Hz)
            "accelerometer_noise_density": accel / math.sqrt(rate),                         # m/s^2/sqrt(Hz)
            "accelerometer_random_walk": imu_spec["accel_bias_walk_mps3"]}                   # m/s^3/sqrt(Hz)


def _imu_spec(ds: Dataset) -> dict:
    from .spec import ImuSpec

    return ImuSpec.model_validate(ds.manifest["spec"].get("imu", {})).model_dump()


def _matrix_yaml(T) -> str:
    rows = ",\n         ".join(", ".join(f"{v:.12g}" for v in r) for r in np.asarray(T))
    return f"  cols: 4\n  rows: 4\n  data: [{rows}]\n"


def is_mono(seq) -> bool:
    """Whether a sequence's camera is monochrome (camera.json's ``mono``; its frames are grey RGB)."""
    return bool(seq.camera_info.get("mono", False))


def _write_csv(path: Path, header: str, rows) -> None:
    """EuRoC's CSV: its header line as the spec writes it, then the rows (``write_csv``'s numbers)."""
    write_csv(path, header.split(","), rows)


def export_euroc_sequence(seq, out: Path, imu_spec: dict, epoch_s: float) -> None:
    mav = out / "mav0"
    cam_dir = mav / "cam0" / "data"
    cam_dir.mkdir(parents=True)
    ts = stamps_ns(seq.t, epoch_s)
    mono = is_mono(seq)
    for k, stamp in enumerate(ts):
        if mono:  # a grey camera's EuRoC images are 8-bit grey PNGs (the same values: R = G = B in the dataset)
            cv2.imwrite(str(cam_dir / f"{stamp}.png"), seq.image(k)[..., 0])
        else:
            (cam_dir / f"{stamp}.png").write_bytes(seq.image_bytes(k))
    _write_csv(mav / "cam0" / "data.csv", "#timestamp [ns],filename", ([s, f"{s}.png"] for s in ts))
    cam = seq.camera
    if cam.model == "fisheye":  # EuRoC/Kalibr's equidistant model is OpenCV's fisheye
        lens = f"distortion_model: equidistant\ndistortion_coefficients: [{', '.join(repr(v) for v in cam.dist)}]\n"
        note, kind = "", "OpenCV fisheye"
    else:
        k1, k2, p1, p2, k3 = cam.dist
        note = "" if k3 == 0 else f"\n# k3 = {k3!r}: radial-tangential here has four coefficients; k3 is given apart"
        lens = (f"distortion_model: radial-tangential\ndistortion_coefficients: [{k1!r}, {k2!r}, {p1!r}, {p2!r}]\n"
                + (f"k3: {k3!r}\n" if k3 != 0 else ""))
        kind = "OpenCV pinhole"
    (mav / "cam0" / "sensor.yaml").write_text(
        f"# hvloc export: camera ({kind}, pixel centres at integers), T_BS = T_B_C (camera to body FLU)"
        f"{note}\nsensor_type: camera\ncomment: hvloc {seq.id}\nT_BS:\n{_matrix_yaml(seq.T_B_C)}"
        f"rate_hz: {seq.fps:g}\nresolution: [{cam.width}, {cam.height}]\ncamera_model: pinhole\n"
        f"intrinsics: [{cam.fx!r}, {cam.fy!r}, {cam.cx!r}, {cam.cy!r}]\n"
        + lens
        + f"exposure_s: {seq.camera_info.get('exposure_s', 0.0)!r}\n"
        f"rolling_shutter_line_s: {seq.camera_info.get('rolling_shutter_line_s', 0.0)!r}\n")
    imu = seq.imu
    (mav / "imu0").mkdir()
    its = stamps_ns(imu[:, 0], epoch_s)
    _write_csv(mav / "imu0" / "data.csv",
               "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
               "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]",
               ([s, *r[1:7]] for s, r in zip(its, imu)))
    n = imu_noise_model(imu_spec)
    (mav / "imu0" / "sensor.yaml").write_text(
        "# hvloc export: the IMU frame is the body frame (FLU)\nsensor_type: imu\n"
        f"comment: hvloc {seq.id}, AHRS attitude not included (see the ROS 2 export)\nT_BS:\n{_matrix_yaml(np.eye(4))}"
        f"rate_hz: {n['rate_hz']:g}\n"
        f"gyroscope_noise_density: {n['gyroscope_noise_density']!r}     # [ rad / s / sqrt(Hz) ]\n"
        f"gyroscope_random_walk: {n['gyroscope_random_walk']!r}       # [ rad / s^2 / sqrt(Hz) ]\n"
        f"accelerometer_noise_density: {n['accelerometer_noise_density']!r}  # [ m / s^2 / sqrt(Hz) ]\n"
        f"accelerometer_random_walk: {n['accelerometer_random_walk']!r}    # [ m / s^3 / sqrt(Hz) ]\n")
    body = _poses(seq, "body2world_")
    vel = np.column_stack([seq.columns[f"body_vel_{a}"].astype(np.float64) for a in "xyz"])
    bias = seq.imu_bias
    if bias is None:
        b = np.full((len(ts), 6), np.nan)
    else:  # the bias inside the latest IMU sample at or before each frame
        j = np.clip(np.searchsorted(imu[:, 0], np.asarray(seq.t, np.float64) + 1e-9) - 1, 0, len(imu) - 1)
        b = bias[j]
    gt = mav / "state_groundtruth_estimate0"
    gt.mkdir()
    _write_csv(gt / "data.csv",
               "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], "
               "v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad s^-1], "
               "b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]",
               ([s, *p[:3], p[6], *p[3:6], *v, *bb] for s, p, v, bb in zip(ts, body, vel, b)))
    pad = mav / "pad_groundtruth0"
    pad.mkdir()
    _write_csv(pad / "data.csv", "#timestamp, p_RP_x [m], p_RP_y [m], p_RP_z [m], q_RP_w [], q_RP_x [], q_RP_y [], q_RP_z []",
               ([s, *p[:3], p[6], *p[3:6]] for s, p in zip(ts, _poses(seq, "pad2world_"))))


# ----------------------------------------------------------------------------- ROS 2 bag

def _ros_time(typestore, ns: int):
    Time = typestore.types["builtin_interfaces/msg/Time"]
    return Time(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))


def export_rosbag2_sequence(seq, out: Path, imu_spec: dict, epoch_s: float) -> None:
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts_store = get_typestore(Stores.ROS2_HUMBLE)
    T = ts_store.types
    Header, Pose, Point, Quat, Vec3 = (T["std_msgs/msg/Header"], T["geometry_msgs/msg/Pose"], T["geometry_msgs/msg/Point"],
                                       T["geometry_msgs/msg/Quaternion"], T["geometry_msgs/msg/Vector3"])
    Transform, TransformStamped = T["geometry_msgs/msg/Transform"], T["geometry_msgs/msg/TransformStamped"]

    def header(ns, frame):
        return Header(stamp=_ros_time(ts_store, ns), frame_id=frame)

    def quat(q):
        return Quat(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))

    def tf(ns, parent, child, p7):
        return TransformStamped(header=header(ns, parent), child_frame_id=child,
                                transform=Transform(translation=Vec3(x=float(p7[0]), y=float(p7[1]), z=float(p7[2])),
                                                    rotation=quat(p7[3:])))

    def pose_stamped(ns, frame, p7):
        return T["geometry_msgs/msg/PoseStamped"](header=header(ns, frame), pose=Pose(
            position=Point(x=float(p7[0]), y=float(p7[1]), z=float(p7[2])), orientation=quat(p7[3:])))

    never = QosTime(sec=2147483647, nsec=4294967295)
    # /tf_static as tf2's static broadcaster offers it (transient local): a late subscriber still gets it
    latched = (Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL, never, never,
                   QosLiveliness.AUTOMATIC, never, False),)
    cam = seq.camera
    ts = stamps_ns(seq.t, epoch_s)
    cam_frame, body_frame = "camera_optical", "base_link"
    mono = is_mono(seq)
    with Writer(out, version=9) as w:
        def conn(topic, msgtype, qos=()):
            return w.add_connection(topic, msgtype, typestore=ts_store, offered_qos_profiles=qos)

        c_img = conn("/camera/image_raw", "sensor_msgs/msg/Image")
        c_info = conn("/camera/camera_info", "sensor_msgs/msg/CameraInfo")
        c_imu = conn("/imu/data", "sensor_msgs/msg/Imu")
        c_body = conn("/ground_truth/body_pose", "geometry_msgs/msg/PoseStamped")
        c_cam = conn("/ground_truth/camera_in_pad", "geometry_msgs/msg/PoseStamped")
        c_tf = conn("/tf", "tf2_msgs/msg/TFMessage")
        c_tfs = conn("/tf_static", "tf2_msgs/msg/TFMessage", latched)

        def put(c, ns, msg):
            w.write(c, int(ns), ts_store.serialize_cdr(msg, msg.__msgtype__))

        TF = T["tf2_msgs/msg/TFMessage"]
        mount = np.concatenate([seq.T_B_C[:3, 3], quat_xyzw_from_matrix(seq.T_B_C[:3, :3])])
        put(c_tfs, min(ts[0], stamps_ns(seq.imu[:1, 0], epoch_s)[0]), TF(transforms=[tf(ts[0], body_frame, cam_frame, mount)]))
        info = T["sensor_msgs/msg/CameraInfo"](
            header=header(0, cam_frame), height=cam.height, width=cam.width, distortion_model="plumb_bob" if cam.model == "pinhole" else "equidistant",
            d=np.array(cam.dist, np.float64), k=cam.K.ravel().astype(np.float64), r=np.eye(3).ravel(),
            p=np.column_stack([cam.K, np.zeros(3)]).ravel().astype(np.float64), binning_x=0, binning_y=0,
            roi=T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))
        imu = seq.imu
        its = stamps_ns(imu[:, 0], epoch_s)
        g2, a2 = imu_spec["gyro_noise_rad_s"] ** 2, imu_spec["accel_noise_mps2"] ** 2
        rp, yaw = np.radians(imu_spec["ahrs_roll_pitch_deg"]) ** 2, np.radians(imu_spec["ahrs_yaw_deg"]) ** 2
        Imu = T["sensor_msgs/msg/Imu"]
        frames = list(zip(ts, range(len(ts))))
        events = sorted([(int(s), 0, i) for i, s in enumerate(its)] + [(int(s), 1, k) for s, k in frames])
        body, padw, campad = _poses(seq, "body2world_"), _poses(seq, "pad2world_"), _poses(seq)
        for ns, kind, i in events:
            if kind == 0:
                r = imu[i]
                put(c_imu, ns, Imu(header=header(ns, body_frame), orientation=quat(r[7:11]),
                                   orientation_covariance=np.diag([rp, rp, yaw]).ravel(),
                                   angular_velocity=Vec3(x=float(r[1]), y=float(r[2]), z=float(r[3])),
                                   angular_velocity_covariance=(np.eye(3) * g2).ravel(),
                                   linear_acceleration=Vec3(x=float(r[4]), y=float(r[5]), z=float(r[6])),
                                   linear_acceleration_covariance=(np.eye(3) * a2).ravel()))
                continue
            k = i
            rgb = seq.image(k)
            px = rgb[..., 0] if mono else rgb  # a grey camera's driver publishes mono8
            put(c_img, ns, T["sensor_msgs/msg/Image"](header=header(ns, cam_frame), height=rgb.shape[0], width=rgb.shape[1],
                                                      encoding="mono8" if mono else "rgb8", is_bigendian=0,
                                                      step=rgb.shape[1] * (1 if mono else 3),
                                                      data=np.ascontiguousarray(px).reshape(-1)))
            info.header = header(ns, cam_frame)
            put(c_info, ns, info)
            put(c_body, ns, pose_stamped(ns, "world", body[k]))
            put(c_cam, ns, pose_stamped(ns, "pad", campad[k]))
            put(c_tf, ns, TF(transforms=[tf(ns, "world", body_frame, body[k]), tf(ns, "world", "pad", padw[k])]))


# ----------------------------------------------------------------------------- COCO keypoints

def pad_keypoint_names(geometry) -> list:
    """The ``landing_pad`` keypoints: the outer corners, then every marker square's corners."""
    names = [f"pad_{c}" for c in ("tl", "tr", "br", "bl")]
    for m in geometry.markers:
        for s in range(len(m.squares)):
            names += [f"{m.set}_{m.name.lower()}_sq{s}_{c}" for c in ("tl", "tr", "br", "bl")]
    return names


def _pad_points(geometry) -> np.ndarray:
    return np.concatenate([geometry.outer_corners] + [m.points for m in geometry.markers])


def _clip_polygon(poly: np.ndarray, w: int, h: int) -> np.ndarray:
    """Sutherland-Hodgman: ``poly`` clipped to the image's area ``[-0.5, w - 0.5] x [-0.5, h - 0.5]``."""
    lo, hi = (-0.5, -0.5), (w - 0.5, h - 0.5)
    pts = [tuple(p) for p in poly]
    for axis in (0, 1):
        for bound, keep in ((lo[axis], lambda v, b: v >= b), (hi[axis], lambda v, b: v <= b)):
            out = []
            for i, cur in enumerate(pts):
                prev = pts[i - 1]
                cin, pin = keep(cur[axis], bound), keep(prev[axis], bound)
                if cin != pin:
                    s = (bound - prev[axis]) / (cur[axis] - prev[axis])
                    out.append(tuple(prev[j] + s * (cur[j] - prev[j]) for j in (0, 1)))
                if cin:
                    out.append(cur)
            pts = out
            if not pts:
                return np.zeros((0, 2))
    return np.array(pts)


def _rolling_correction(labels: np.ndarray, ideal: np.ndarray, pts_P: np.ndarray, half: float):
    """Per-point pixel offsets that carry the frame-time projection to the rolling-shutter labels:
    the four outer corners' offsets, interpolated bilinearly over the pad (an approximation for
    points inside; exact at the corners, zero for a global shutter)."""
    d = labels - ideal
    if not np.isfinite(d).all():
        return np.zeros((len(pts_P), 2))
    u = (pts_P[:, 0] + half) / (2 * half)          # 0 at the left edge
    v = (half - pts_P[:, 1]) / (2 * half)          # 0 at the top edge (TL, TR, BR, BL)
    return ((1 - u) * (1 - v))[:, None] * d[0] + (u * (1 - v))[:, None] * d[1] \
        + (u * v)[:, None] * d[2] + ((1 - u) * v)[:, None] * d[3]


def coco_annotations(seq, geometry, image_id0: int, ann_id0: int, rel: str) -> tuple:
    """``(images, annotations)`` of one sequence (ids from ``image_id0`` / ``ann_id0``)."""
    cam = seq.camera
    c = seq.columns
    pts = _pad_points(geometry)
    n_outer = 4
    edge = np.linspace(0.0, 1.0, 17)[:-1]
    oc = geometry.outer_corners
    outline_P = np.concatenate([oc[i] + edge[:, None] * (oc[(i + 1) % 4] - oc[i]) for i in range(4)])
    line_s = float(seq.camera_info.get("rolling_shutter_line_s", 0.0) or 0.0)
    marker_vis_col = {m.name: f"marker_{m.name.lower()}_visible" for m in geometry.markers if m.set == "corner"}
    images, anns = [], []
    for k in range(len(seq)):
        image_id = image_id0 + k
        images.append({"id": image_id, "file_name": f"{rel}/{c['image'][k]}", "width": cam.width, "height": cam.height,
                       "sequence": seq.id, "frame": int(k), "t": float(c["t"][k])})
        T = transform_from_tum([c[n][k] for n in POSE])
        px = cam.project_from(T, pts)
        outline = cam.project_from(T, outline_P)
        labels = np.array([[c[f"c{i}u"][k], c[f"c{i}v"][k]] for i in range(4)], np.float64)
        if line_s > 0:
            px = px + _rolling_correction(labels, px[:4], pts, geometry.half_side_m)
            outline = outline + _rolling_correction(labels, cam.project_from(T, oc), outline_P, geometry.half_side_m)
        px[:4] = np.where(np.isfinite(labels), labels, px[:4])  # the corners exactly as labelled
        inside = cam.in_image(px) & np.isfinite(px).all(axis=1)
        vis = np.where(inside, 1, 0)
        vis[:4] = np.where([bool(c[f"c{i}_visible"][k]) for i in range(4)], 2, vis[:4])
        fully = bool(c["pad_fully_visible"][k])
        start = n_outer
        boxes = []
        for m in geometry.markers:
            n = len(m.points)
            col = marker_vis_col.get(m.name) if m.set == "corner" else None
            seen = bool(c[col][k]) if col else fully
            sl = slice(start, start + n)
            vis[sl] = np.where(inside[sl] & seen, 2, vis[sl])
            if seen:
                q = px[start:start + 4]
                boxes.append((m, q))
            start += n
        kp = np.column_stack([np.where(vis[:, None] > 0, px, 0.0), vis]).ravel()
        poly = _clip_polygon(outline[np.isfinite(outline).all(axis=1)], cam.width, cam.height)
        if len(poly) < 3:
            continue
        x0, y0 = poly.min(axis=0)
        x1, y1 = poly.max(axis=0)
        area = 0.5 * abs(float(np.dot(poly[:, 0], np.roll(poly[:, 1], 1)) - np.dot(poly[:, 1], np.roll(poly[:, 0], 1))))
        anns.append({"id": ann_id0 + len(anns), "image_id": image_id, "category_id": 1, "iscrowd": 0,
                     "keypoints": [round(float(v), 4) for v in kp], "num_keypoints": int((vis > 0).sum()),
                     "bbox": [round(float(v), 4) for v in (x0, y0, x1 - x0, y1 - y0)], "area": round(area, 4),
                     "segmentation": [[round(float(v), 4) for v in poly.ravel()]]})
        for m, q in boxes:
            (bx0, by0), (bx1, by1) = q.min(axis=0), q.max(axis=0)
            anns.append({"id": ann_id0 + len(anns), "image_id": image_id, "category_id": MARKER_CATEGORY[m.kind],
                         "iscrowd": 0, "bbox": [round(float(v), 4) for v in (bx0, by0, bx1 - bx0, by1 - by0)],
                         "area": round(float((bx1 - bx0) * (by1 - by0)), 4), "marker": f"{m.set}/{m.name}",
                         "keypoints": [], "num_keypoints": 0})
    return images, anns


MARKER_CATEGORY = {"finder": 2, "aruco": 3, "apriltag": 4}


def export_coco(ds: Dataset, out: Path, sequence_ids: list) -> Path:
    geometry = ds[sequence_ids[0]].pad.geometry
    names = pad_keypoint_names(geometry)
    doc = {"info": {"description": f"hvloc dataset {ds.manifest['name']} (spec {ds.manifest['spec_sha256'][:12]})",
                    "image_root": str(ds.root.resolve()),
                    "note": "file_name is relative to image_root; keypoint visibility 2: seen, 1: in the image but "
                            "maybe hidden, 0: outside (x = y = 0); marker corners under a rolling shutter are "
                            "interpolated from the labelled outer corners"},
           "images": [], "annotations": [],
           "categories": [{"id": 1, "name": "landing_pad", "supercategory": "pad", "keypoints": names,
                           "skeleton": [[1, 2], [2, 3], [3, 4], [4, 1]]},
                          {"id": 2, "name": "finder_marker", "supercategory": "pad"},
                          {"id": 3, "name": "aruco_marker", "supercategory": "pad"},
                          {"id": 4, "name": "apriltag", "supercategory": "pad"}]}
    for sid in sequence_ids:
        seq = ds[sid]
        if pad_keypoint_names(seq.pad.geometry) != names:
            raise InputError(f"{sid}: its pad differs from {sequence_ids[0]}'s; COCO needs one keypoint list")
        imgs, anns = coco_annotations(seq, seq.pad.geometry, len(doc["images"]) + 1, len(doc["annotations"]) + 1, sid)
        doc["images"] += imgs
        doc["annotations"] += anns
    path = out / "coco_keypoints.json"
    tmp = out / ".coco_keypoints.json.tmp"
    tmp.write_text(json.dumps(doc) + "\n")
    os.replace(tmp, path)
    return path


# ----------------------------------------------------------------------------- front door

def export_dataset(fmt: str, root, out, epoch_s: float = DEFAULT_EPOCH_S, sequences: list | None = None,
                   verify: bool = True, show_progress: bool = False) -> dict:
    """Write dataset ``root`` in format ``fmt`` under ``out``; returns what was written
    (``{"paths": [...], "bytes": n, "seconds": s}``).  Each sequence is written into a temporary
    folder and moved into place whole: an interrupted export leaves nothing half-written."""
    if fmt not in FORMATS:
        raise InputError(f"format {fmt!r}: one of {', '.join(FORMATS)}")
    if not math.isfinite(epoch_s) or epoch_s < 0:
        raise InputError(f"--epoch {epoch_s}: must be a finite number of seconds >= 0")
    ds = Dataset(root, verify=verify)
    ids = sequences or ds.sequence_ids
    unknown = [s for s in ids if s not in ds.sequence_ids]
    if unknown:
        raise InputError(f"sequence {unknown[0]}: not in {root} (it has {', '.join(ds.sequence_ids)})")
    out = prepare_out_dir(out)
    t0 = time.perf_counter()
    paths = []
    with FolderLock(out, "exporting into"):
        if fmt == "coco":
            paths.append(export_coco(ds, out, ids))
        else:
            imu_spec = _imu_spec(ds)
            write = export_euroc_sequence if fmt == "euroc" else export_rosbag2_sequence
            bar = progress_bar(show_progress, len(ids), f"export {fmt}")
            for sid in ids:
                tmp = _fresh(out / f".tmp-{sid}")
                if fmt == "euroc":
                    tmp.mkdir()
                try:
                    write(ds[sid], tmp, imu_spec, epoch_s)
                except BaseException:
                    shutil.rmtree(tmp, ignore_errors=True)
                    raise
                finalize_sequence(tmp, out / sid)
                paths.append(out / sid)
                if bar:
                    bar.update(1)
            if bar:
                bar.close()
    size = sum(f.stat().st_size for p in paths for f in ([p] if p.is_file() else p.rglob("*")) if f.is_file())
    return {"paths": paths, "bytes": size, "seconds": time.perf_counter() - t0}


def export_main(argv: list) -> int:
    p = ArgumentParser(prog="hvloc export", description=__doc__.split("\n\n")[0])
    p.add_argument("format", choices=FORMATS, help="euroc (EuRoC/ASL folders), rosbag2 (ROS 2 bags), coco (keypoints JSON)")
    p.add_argument("dataset", help="dataset folder (made by hvloc generate)")
    p.add_argument("--out", required=True, help="output folder: one folder per sequence (coco: coco_keypoints.json)")
    p.add_argument("--epoch", type=float, default=DEFAULT_EPOCH_S,
                   help=f"seconds since 1970 of the sequence's t = 0 (default {DEFAULT_EPOCH_S}; ROS reads 0 as unset)")
    p.add_argument("--sequence", action="append", help="export only this sequence id (repeatable)")
    p.add_argument("--no-verify", action="store_true",
                   help="use a dataset even if its files differ from the checksums in its manifest")
    p.add_quiet()
    a = p.parse_args(argv)
    if not Path(a.dataset).is_dir():
        raise InputError(f"{a.dataset}: no such dataset folder")
    res = export_dataset(a.format, a.dataset, a.out, a.epoch, a.sequence, verify=not a.no_verify,
                         show_progress=not a.quiet)
    for path in res["paths"]:
        print(path)
    print(f"{a.format}: {len(res['paths'])} item(s), {res['bytes'] / 1e6:.1f} MB in {res['seconds']:.1f} s")
    return 0
