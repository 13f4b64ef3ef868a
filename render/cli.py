"""``hvloc generate`` and ``hvloc dataset verify|show``."""
from __future__ import annotations

from pathlib import Path

from pad_design.errors import ArgumentParser, InputError, prepare_out_dir, validate_model, workers_arg


def generate_main(argv: list) -> int:
    p = ArgumentParser(prog="hvloc generate", description="Render labelled landing sequences.")
    p.add_argument("spec", help="dataset spec YAML (see data_specs/)")
    p.add_argument("--out", required=True, help="dataset folder (a second run resumes)")
    p.add_argument("--sequences", type=int, help="override the spec's number of sequences")
    p.add_argument("--seed", type=int, help="override the spec's dataset seed")
    p.add_argument("--workers", type=workers_arg, default=1, help="parallel render processes (one OSMesa context each)")
    p.add_argument("--overwrite", action="store_true", help="replace a dataset of another spec in --out")
    from .executor import EXECUTORS

    p.add_argument("--executor", choices=EXECUTORS, default="local",
                   help="where sequences are rendered: local processes, or a Ray cluster")
    p.add_argument("--ray-address", help="Ray cluster to join (default: start one on this machine); see README")
    p.add_quiet()
    a = p.parse_args(argv)
    from .generate import generate
    from .plan import check_flyable
    from .spec import DatasetSpec, load_dataset_spec

    spec = load_dataset_spec(a.spec)
    over = {}
    if a.sequences is not None:
        over["sequences"] = a.sequences
    if a.seed is not None:
        over["seed"] = a.seed
    if over:
        spec = validate_model(DatasetSpec, {**spec.model_dump(mode="json"), **over}, "command line")
    check_flyable(spec)  # a flight no multirotor flies is refused before --out is made
    prepare_out_dir(a.out)
    res = generate(spec, a.out, workers=a.workers, overwrite=a.overwrite, show_progress=not a.quiet,
                   executor=a.executor, ray_address=a.ray_address)
    fps = res.frames / res.seconds if res.seconds > 0 else float("nan")
    print(f"{res.root}: {len(res.rendered)} sequence(s) rendered ({res.frames} frames, {res.seconds:.1f} s, "
          f"{fps:.1f} frames/s), {len(res.skipped)} already complete")
    return 0


def dataset_main(argv: list) -> int:
    p = ArgumentParser(prog="hvloc dataset", description="Verify or look at a dataset.")
    sub = p.add_subparsers(dest="action", required=True)
    v = sub.add_parser("verify", help="checksums, completeness, label sanity (exit 1 if anything is wrong)")
    v.add_argument("dir", help="dataset folder")
    s = sub.add_parser("show", help="contact sheet of a sequence with the labels drawn on its frames")
    s.add_argument("dir", help="dataset folder")
    s.add_argument("seq", nargs="?", help="sequence id (default: the first)")
    s.add_argument("--frames", type=int, default=12, help="frames on the sheet")
    s.add_argument("--out", help="PNG path (default DIR/show/<seq>.png)")
    a = p.parse_args(argv)
    if a.action == "verify":
        from .dataset import verify_dataset

        if not Path(a.dir).is_dir():
            raise InputError(f"{a.dir}: no such folder")
        problems = verify_dataset(a.dir)
        if problems:
            print(f"{a.dir}: {len(problems)} problem(s):")
            for line in problems:
                print(f"  - {line}")
            return 1
        print(f"{a.dir}: ok")
        return 0
    from .show import contact_sheet

    path = contact_sheet(a.dir, a.seq, a.frames, a.out)
    print(path)
    return 0


def camera_main(argv: list) -> int:
    p = ArgumentParser(prog="hvloc camera", description="Cameras from the calibration files people have.")
    sub = p.add_subparsers(dest="action", required=True)
    i = sub.add_parser("import", help="a Kalibr camchain, ROS CameraInfo or OpenCV calibration as a spec's camera")
    i.add_argument("calibration", help="calibration file: Kalibr camchain YAML, ROS CameraInfo YAML, OpenCV "
                                       "FileStorage (YAML, XML, JSON)")
    i.add_argument("--name", help="the camera of a Kalibr camchain (default: the first, cam0)")
    i.add_argument("--model", choices=("pinhole", "fisheye"),
                   help="the lens model of an OpenCV file, which does not say it (fisheye: cv2.fisheye.calibrate's "
                        "K and D); Kalibr and ROS files say their own")
    i.add_argument("--spec", help="a dataset spec whose camera to replace (with --out): its other fields stay")
    i.add_argument("--out", help="where to write that spec (with --spec); without, the camera block is printed")
    a = p.parse_args(argv)
    import yaml

    from .calibration import read_calibration

    if (a.spec is None) != (a.out is None):
        raise InputError("--spec and --out go together (a spec to change, and where to write it)")
    cal = read_calibration(a.calibration, a.name, a.model)
    fields = cal.spec_fields()
    names = "k1 k2 p1 p2 k3" if cal.camera.model == "pinhole" else "fisheye k1 k2 k3 k4"
    header = (f"# {cal.source} from {a.calibration}: {cal.width}x{cal.height}, fx {cal.fx:.6g}, fy {cal.fy:.6g}, "
              f"cx {cal.cx:.6g}, cy {cal.cy:.6g}, {names} {list(cal.dist)}\n")
    if a.spec is None:
        print(header + yaml.safe_dump({"camera": fields}, sort_keys=False, default_flow_style=None), end="")
        return 0
    from pad_design.errors import yaml_load

    from .dataset import atomic_write_text
    from .spec import DatasetSpec

    try:
        doc = yaml_load(Path(a.spec).read_text(encoding="utf-8")) or {}
    except OSError as err:
        raise InputError(f"{a.spec}: cannot read ({err.strerror or err})") from None
    if not isinstance(doc, dict):
        raise InputError(f"{a.spec}: not a dataset spec (expected a mapping at the top)")
    doc["camera"] = {**(doc.get("camera") or {}), **fields}
    validate_model(DatasetSpec, doc, f"{a.spec} with the camera of {a.calibration}")  # refused before written
    if Path(a.out).exists():
        raise InputError(f"{a.out}: exists; choose a new file")
    atomic_write_text(Path(a.out), header + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None))
    print(f"{a.out}: {a.spec} with the camera of {a.calibration}")
    return 0


def import_main(argv: list) -> int:
    p = ArgumentParser(prog="hvloc import", description="A real flight (video or images, calibration, optional "
                       "IMU and ground truth) as an hvloc dataset: localize, bench score and export work on it.")
    p.add_argument("frames", help="a video file, or a folder of images (sorted by name)")
    p.add_argument("--calibration", required=True,
                   help="camera calibration: Kalibr camchain, ROS CameraInfo YAML or OpenCV FileStorage")
    p.add_argument("--camera-name", help="the camera of a Kalibr camchain (default: the first)")
    p.add_argument("--fps", type=float, help="frame rate (default: the video's; needed for an image folder)")
    p.add_argument("--timestamps", help="each frame's capture time (s), one per line in frame order (or 'frame t' "
                   "per line): times kept, frame numbers recovered from them (gaps where frames were dropped), "
                   "everything (frames, ground truth, IMU) re-zeroed to the first frame's time; --fps then "
                   "defaults to the median rate")
    p.add_argument("--groundtruth", help="TUM file (t tx ty tz qx qy qz qw) of the camera in the pad frame, T_P_C")
    p.add_argument("--gt-body", action="store_true",
                   help="the ground truth is the body's pose in the pad frame (T_P_B); the mount gives the camera")
    p.add_argument("--gt-time-offset", type=float, default=0.0,
                   help="seconds added to the ground truth's times to put them on the frames' clock (frame k at k/fps)")
    p.add_argument("--imu", help="imu.csv with hvloc's columns (t, gyro_*, accel_*, qx qy qz qw) on the frames' clock")
    p.add_argument("--mount-rpy", type=float, nargs=3, metavar=("ROLL", "PITCH", "YAW"),
                   help="camera mount T_B_C as roll pitch yaw in degrees (default: hvloc's downward camera)")
    p.add_argument("--pad-spec", help="pad spec YAML of the pad that was flown (default: the paper pad)")
    p.add_argument("--line-time-s", type=float, default=0.0,
                   help="rolling shutter: the time between the exposures of consecutive rows, in seconds (a sensor "
                   "read top to bottom in 20 ms over 1080 rows: 1.85e-5); 0, the default: a global shutter. "
                   "The localizer corrects for it (README, Rolling shutter)")
    p.add_argument("--ref-row", type=float,
                   help="with --line-time-s: the row whose exposure time a frame's time is (default: the middle row)")
    p.add_argument("--exposure-s", type=float,
                   help="how long each frame is exposed, in seconds (the camera's metadata says): the localizer "
                   "draws the pad smeared over it where a gust smears every feature (README); default: not known")
    p.add_argument("--response", type=float, nargs="+", metavar="V",
                   help="the camera's photometric calibration: GAMMA [SHARPEN [SIGMA_PX]], each channel written as "
                   "light ** (1 / GAMMA) and then sharpened by an unsharp mask of SHARPEN (Gaussian of SIGMA_PX, "
                   "default 1); the far pad's design fit draws the pad as the camera writes it (README); default: not known")
    p.add_argument("--name", default="imported", help="the dataset's name")
    p.add_argument("--out", required=True, help="new dataset folder")
    p.add_quiet()
    a = p.parse_args(argv)
    from .importer import import_recording

    if a.gt_body and not a.groundtruth:
        raise InputError("--gt-body: goes with --groundtruth")
    prepare_out_dir(a.out)
    res = import_recording(a.out, a.frames, a.calibration, calibration_name=a.camera_name, fps=a.fps,
                           timestamps=a.timestamps, groundtruth=a.groundtruth, gt_body=a.gt_body, gt_time_offset_s=a.gt_time_offset,
                           imu=a.imu, mount_rpy_deg=a.mount_rpy, pad_spec=a.pad_spec, name=a.name,
                           line_s=a.line_time_s, ref_row=a.ref_row, exposure_s=a.exposure_s, response=a.response,
                           show_progress=not a.quiet)
    print(f"{res['root']}: {res['frames']} frames, {res['with_ground_truth']} with ground truth, "
          f"{'with' if res['with_imu'] else 'no'} IMU")
    return 0
