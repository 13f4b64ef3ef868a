"""The dataset on disk (DESIGN.md, "Dataset on disk"): writer and reader side by side.

Ownership: one process writes a dataset folder at a time (:class:`FolderLock`, an advisory lock
held for the whole run).  Atomicity: a sequence is written into ``.tmp-<id>/`` and renamed to
``<id>/`` only when every file is written and checksummed; ``manifest.json`` is replaced
atomically after each sequence.  An interrupted run leaves only ``.tmp-*`` folders, which no
reader or ``verify`` accepts and which the next run deletes and redoes.

Integrity: every file of the dataset is listed in the manifest with its SHA-256.  ``verify``
reports any file that is missing, differs or is not listed; readers asked to verify check the
checksums of what they read and refuse a dataset that differs.
"""
from __future__ import annotations

import csv
import hashlib
import json
import math
import os
import platform
import re
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from hvloc.geometry import Camera, transform_from_tum
from pad_design.errors import InputError

from .plan import sequence_seed  # noqa: F401  (re-exported: the seed rule belongs to the format)

FORMAT = "hvloc-dataset"
FORMAT_VERSION = 2
POSE = ("tx", "ty", "tz", "qx", "qy", "qz", "qw")
LOCK_NAME = ".hvloc.lock"
SEQUENCE_FILES = ("frames.csv", "groundtruth.tum", "imu.csv", "camera.json", "pad.json", "meta.json")
PAD_TEXTURE = "pad.png"  # at the dataset's root: one copy per dataset, named by every pad.json
AIRFRAME_MASK = "airframe_mask.png"  # per sequence, when the camera sees its airframe (legs, arms, propeller discs): 255 there

# frames.csv: every column and what it holds (the README's table is made from this)
COLUMN_DOCS = {
    "frame": "frame index k (0, 1, ...; gaps where the camera dropped frames)",
    "t": "time of the frame, s from the start of the sequence (k / fps, plus the camera's jitter if any)",
    "image": "image path relative to the sequence folder",
    **{c: f"camera pose in the pad frame T_P_C: {'translation (m)' if c[0] == 't' else 'rotation, Hamilton quaternion'} {c}"
       for c in POSE},
    "height_above_pad": "camera height above the pad plane (m): tz",
    "phase_gt": "ground-truth phase (approaching, adjustment, touchdown) by the rule of render/phase.py",
    "pad_fully_visible": "1 if the whole pad (outline and area) is in the image and hidden by nothing",
    "markers_visible": "how many of the three corner markers are wholly in the image and hidden by nothing",
    "module_px": "smallest module (px) of the visible corner markers (0 if none)",
    "blur_px": ("largest image motion over the exposure of the pad's points in view (px, through the lens: a 17 x 17 "
                "grid over the pad, corners included; NaN when none is in view). Datasets generated before commit "
                "54ed125 read it on the pad's four corners through an ideal pinhole, those out of view included (a "
                "fisheye close above a large pad: up to 10^5 px); their images and other labels are the same, so "
                "their spec identity is too. 0 where motion blur is not rendered (degradations.motion_blur false: each "
                "frame an instant, camera.json's exposure_s 0 too); datasets generated before 2026-12-06 gave the motion "
                "over the spec's exposure there, and camera.json that exposure, on sharp frames"),
    "blur_subframes": "samples over the exposure used for this frame's motion blur (1: none)",
    **{f"c{i}{a}": f"pixel {a} of the pad's outer corner {i} (TL, TR, BR, BL); NaN when outside the image"
       for i in range(4) for a in "uv"},
    **{f"c{i}_visible": f"1 if outer corner {i} is in the image and hidden by nothing" for i in range(4)},
    **{f"marker_{n}_visible": f"1 if the {n.capitalize()} corner marker is wholly in the image and hidden by nothing"
       for n in ("top", "right", "bottom")},
    "pad_visible_fraction": "share of the pad's area that is in the image and hidden by nothing",
    **{f"pad2world_{c}": f"pad pose in the world T_W_P (ENU): {c}" for c in POSE},
    **{f"body2world_{c}": f"body pose in the world T_W_B (FLU body, ENU world): {c}" for c in POSE},
    **{f"body_vel_{c}": f"body velocity in the world frame (m/s): {c}" for c in "xyz"},
    **{f"pad_vel_{c}": f"pad (platform) velocity in the world frame (m/s): {c}" for c in "xyz"},
}
FRAME_COLUMNS = list(COLUMN_DOCS)
TEXT_COLUMNS = ("image", "phase_gt")
PHASES = ("approaching", "adjustment", "touchdown")


# ----------------------------------------------------------------------------- small io helpers

def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def sha256_file(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def atomic_write_text(path, text: str) -> None:
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


def sequence_id(index: int) -> str:
    return f"seq_{index:04d}"


SEQUENCE_ID = re.compile(r"^seq_\d{4,}$")


def package_versions() -> dict:
    import importlib.metadata as md

    out = {"python": sys.version.split()[0], "platform": platform.platform()}
    for name in ("hvloc", "numpy", "opencv-python-headless", "pyrender-maintained", "PyOpenGL", "torch", "kornia",
                 "trimesh", "pydantic"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            out[name] = None
    return out


def _fmt(v) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "1" if v else "0"
    if isinstance(v, (float, np.floating)):
        return "nan" if not math.isfinite(v) else repr(float(v))
    return str(v)


def write_csv(path, columns, rows) -> None:
    """``rows``: sequences in ``columns`` order, or dicts keyed by column."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns)
        for r in rows:
            w.writerow([_fmt(r[c]) for c in columns] if isinstance(r, dict) else [_fmt(v) for v in r])


def read_csv_columns(path, text_columns=None) -> dict:
    """CSV -> {column: numpy array}.  With ``text_columns`` every other column must be numeric
    (float64; ``nan`` allowed) and a value that is not is an :class:`InputError` naming it; without,
    a column is numeric when every value parses."""
    try:
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as err:
        raise InputError(f"{path}: cannot read CSV ({err})") from None
    if not rows:
        raise InputError(f"{path}: empty CSV")
    head, body = rows[0], rows[1:]
    if len(set(head)) != len(head):
        raise InputError(f"{path}: repeated column names")
    for i, r in enumerate(body):
        if len(r) != len(head):
            raise InputError(f"{path}: row {i + 2} has {len(r)} values, the header {len(head)}")
    cols = {}
    for i, name in enumerate(head):
        vals = [r[i] for r in body]
        if text_columns is not None and name in text_columns:
            cols[name] = np.array(vals, dtype=object)
            continue
        try:
            cols[name] = np.array([float(v) for v in vals], np.float64)
        except ValueError:
            if text_columns is not None:
                bad = next(v for v in vals if not _is_float(v))
                raise InputError(f"{path}: column {name!r} holds {bad!r}, not a number") from None
            cols[name] = np.array(vals, dtype=object)
    return cols


def _is_float(v: str) -> bool:
    try:
        float(v)
        return True
    except ValueError:
        return False


def write_tum(path, t, poses7, header: str) -> None:
    with open(path, "w") as f:
        f.write(f"# {header}\n")
        for ti, p in zip(t, poses7):
            f.write(" ".join(_fmt(v) for v in (ti, *p)) + "\n")


def read_tum(path) -> np.ndarray:
    """``(N, 8)``: t tx ty tz qx qy qz qw."""
    try:
        lines = Path(path).read_text().splitlines()
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f"{path}: cannot read ({err})") from None
    rows = [ln.split() for ln in lines if ln.strip() and not ln.startswith("#")]
    if any(len(r) != 8 for r in rows):
        raise InputError(f"{path}: TUM rows need 8 values (t tx ty tz qx qy qz qw)")
    try:
        return np.array(rows, dtype=np.float64) if rows else np.zeros((0, 8))
    except ValueError:
        raise InputError(f"{path}: TUM rows must be numbers") from None


def encode_png(rgb: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, 1])
    if not ok:
        raise OSError("PNG encoding failed")
    return buf.tobytes()


def write_image(path, rgb: np.ndarray) -> str:
    """Write a PNG; returns the SHA-256 of the bytes written."""
    data = encode_png(rgb)
    Path(path).write_bytes(data)
    return sha256_bytes(data)


def decode_image(data: bytes, name) -> np.ndarray:
    bgr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR) if data else None
    if bgr is None:
        raise InputError(f"{name}: not a readable image")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def read_image(path) -> np.ndarray:
    try:
        data = Path(path).read_bytes()
    except OSError as err:
        raise InputError(f"{path}: cannot read ({err.strerror or err})") from None
    return decode_image(data, path)


# ----------------------------------------------------------------------------- one writer at a time

class FolderLock:
    """An advisory lock on a folder (``<folder>/.hvloc.lock``) held from ``__enter__`` to ``__exit__``
    (or the process's end, however it ends: the kernel drops it).  A second writer is refused
    with an :class:`InputError` naming the holder."""

    def __init__(self, folder, what: str = "writing"):
        self.folder = Path(folder)
        self.what = what
        self._fd = None

    def __enter__(self):
        import fcntl

        self.folder.mkdir(parents=True, exist_ok=True)
        path = self.folder / LOCK_NAME
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 64, 0).decode(errors="replace").strip() or "?"
            os.close(fd)
            raise InputError(f"{self.folder}: another hvloc process (pid {holder}) is {self.what} this folder; "
                             "wait for it or choose another --out") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._fd = fd
        return self

    def __exit__(self, *exc):
        import fcntl

        if self._fd is not None:
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None
        return False


# ----------------------------------------------------------------------------- manifest

def manifest_problems(m) -> list:
    """What is wrong with a manifest's structure (empty: it can be read)."""
    if not isinstance(m, dict):
        return ["manifest.json: not a JSON object"]
    out = []
    if m.get("format") != FORMAT:
        return ["manifest.json: not an hvloc dataset manifest (format)"]
    if m.get("version") != FORMAT_VERSION:
        return [f"manifest.json: format version {m.get('version')!r}; this hvloc reads version {FORMAT_VERSION} "
                "(regenerate the dataset from its spec)"]
    seqs = m.get("sequences")
    if not isinstance(seqs, list) or not all(isinstance(s, dict) and isinstance(s.get("id"), str)
                                             and SEQUENCE_ID.match(s["id"]) and isinstance(s.get("index"), int)
                                             for s in seqs):
        out.append("manifest.json: sequences must be a list of {id: seq_NNNN, index: int, ...}")
    elif len({s["id"] for s in seqs}) != len(seqs):
        out.append("manifest.json: a sequence is listed twice")
    files = m.get("files")
    if not isinstance(files, dict) or not all(isinstance(k, str) and isinstance(v, str) and re.fullmatch(r"[0-9a-f]{64}", v)
                                              for k, v in files.items()):
        out.append("manifest.json: files must map each path to its SHA-256")
    elif any(k.startswith("/") or ".." in Path(k).parts for k in files):
        out.append("manifest.json: files must be paths inside the dataset")
    planned = m.get("sequences_planned")
    if not isinstance(planned, int) or isinstance(planned, bool) or planned < 0:
        out.append("manifest.json: sequences_planned must be a non-negative integer")
    return out


def load_manifest(root) -> dict | None:
    """The manifest of ``root`` (``None`` if there is none); an :class:`InputError` if it cannot be used."""
    p = Path(root) / "manifest.json"
    if not p.exists():
        return None
    try:
        m = json.loads(p.read_text())
    except (ValueError, OSError, UnicodeDecodeError) as err:
        raise InputError(f"{p}: not valid JSON ({err})") from None
    problems = manifest_problems(m)
    if problems:
        raise InputError(f"{root}: {problems[0]}")
    return m


def new_manifest(spec, versions: dict | None = None) -> dict:
    return {"format": FORMAT, "version": FORMAT_VERSION, "name": spec.name, "seed": spec.seed,
            "sequences_planned": spec.sequences, "spec_sha256": spec.sha256(),
            "spec": json.loads(spec.canonical_json()), "versions": versions or package_versions(),
            "sequences": [], "files": {}}


def save_manifest(root, manifest: dict) -> None:
    manifest["sequences"].sort(key=lambda s: s["id"])
    manifest["files"] = dict(sorted(manifest["files"].items()))
    atomic_write_text(Path(root) / "manifest.json", json.dumps(manifest, indent=1, sort_keys=False) + "\n")


def sequence_files(manifest: dict, sid: str) -> dict:
    """``{path inside the sequence: sha256}`` of one listed sequence."""
    pre = sid + "/"
    return {k[len(pre):]: v for k, v in manifest["files"].items() if k.startswith(pre)}


def files_differing(root: Path, files: dict) -> list:
    """Paths (relative to ``root``) of ``files`` that are missing or whose checksum differs."""
    return [rel for rel, digest in files.items() if not (root / rel).is_file() or sha256_file(root / rel) != digest]


# ----------------------------------------------------------------------------- writer

class SequenceWriter:
    """Writes one sequence into a temporary folder; the renderer hands it named layers, and this
    alone decides what goes to disk (images are encoded on a background thread)."""

    def __init__(self, tmp_dir: Path):
        from concurrent.futures import ThreadPoolExecutor

        self.dir = Path(tmp_dir)
        if self.dir.exists():
            shutil.rmtree(self.dir)
        (self.dir / "images").mkdir(parents=True)
        self.rows: list = []
        self._pool = ThreadPoolExecutor(max_workers=1)  # PNG encoding overlaps rendering (OpenCV drops the GIL)
        self._writes: dict = {}

    def add(self, layers) -> None:
        row = layers.labels
        self.rows.append(row)
        self._writes[row["image"]] = self._pool.submit(write_image, self.dir / row["image"], layers.rgb)
        if layers.airframe_mask is not None and AIRFRAME_MASK not in self._writes:  # rigid with the camera: once
            mask = np.repeat((layers.airframe_mask.astype(np.uint8) * 255)[..., None], 3, axis=2)
            self._writes[AIRFRAME_MASK] = self._pool.submit(write_image, self.dir / AIRFRAME_MASK, mask)

    def close(self, *, camera_info: dict, pad_document: dict, imu_columns, imu_rows, meta: dict) -> dict:
        """Write the label files and meta.json; returns ``{path: sha256}`` of every file."""
        try:
            files = {rel: w.result() for rel, w in self._writes.items()}  # re-raises any write error
        finally:
            self._pool.shutdown(wait=True)
        rows = sorted(self.rows, key=lambda r: r["frame"])
        write_csv(self.dir / "frames.csv", FRAME_COLUMNS, rows)
        write_tum(self.dir / "groundtruth.tum", [r["t"] for r in rows], [[r[c] for c in POSE] for r in rows],
                  "t tx ty tz qx qy qz qw  (T_P_C: camera pose in the pad frame)")
        write_csv(self.dir / "imu.csv", imu_columns, imu_rows)
        (self.dir / "camera.json").write_text(json.dumps(camera_info, indent=1) + "\n")
        (self.dir / "pad.json").write_text(json.dumps(pad_document, indent=1) + "\n")
        for name in ("frames.csv", "groundtruth.tum", "imu.csv", "camera.json", "pad.json"):
            files[name] = sha256_file(self.dir / name)
        meta = dict(meta, files=dict(sorted(files.items())))
        (self.dir / "meta.json").write_text(json.dumps(meta, indent=1) + "\n")
        files["meta.json"] = sha256_file(self.dir / "meta.json")
        return dict(sorted(files.items()))


def finalize_sequence(tmp_dir: Path, final_dir: Path) -> None:
    """Move a completely written sequence into place (replacing any leftover of the same id)."""
    if final_dir.exists():
        shutil.rmtree(final_dir)
    os.replace(tmp_dir, final_dir)


# ----------------------------------------------------------------------------- reader

@dataclass
class Frame:
    index: int
    t: float
    image_path: Path
    cam2pad: np.ndarray
    phase_gt: str
    height_above_pad: float
    pad_fully_visible: bool
    markers_visible: int
    corners_px: np.ndarray       # (4, 2), NaN where out of view
    corners_visible: np.ndarray  # (4,) bool: in view and hidden by nothing

    @property
    def rgb(self) -> np.ndarray:
        return read_image(self.image_path)


def interpolate_pose(times: np.ndarray, pose_of_frame, t: float) -> np.ndarray:
    """The pose at ``t`` between the frames' ``pose_of_frame(k)`` at ``times``: position linearly,
    rotation along the shortest arc, held before the first frame and after the last."""
    from hvloc.geometry import make_transform, so3_exp, so3_log

    k = int(np.clip(np.searchsorted(times, t) - 1, 0, len(times) - 2))
    a = float(np.clip((t - times[k]) / (times[k + 1] - times[k]), 0.0, 1.0)) if len(times) > 1 else 0.0
    A, B = pose_of_frame(k), pose_of_frame(min(k + 1, len(times) - 1))
    R = A[:3, :3] @ so3_exp(a * so3_log(A[:3, :3].T @ B[:3, :3]))
    return make_transform(R, (1 - a) * A[:3, 3] + a * B[:3, 3])


def read_imu_csv(path) -> tuple:
    """``(rows (M, 11): t, gyro xyz, accel xyz, AHRS quaternion xyzw; all columns)`` of an
    ``imu.csv`` (a dataset's, or one ``hvloc import`` takes in), or an :class:`InputError` naming
    the columns it lacks or the first row whose time is not a number or goes back: every reader
    takes the rows in time order (the samples since a frame, the attitude at one).  (Shuffled, a
    dataset's were read without a word, and 22 of 107 frames rejected.)"""
    from .imu import IMU_COLUMNS

    cols = read_csv_columns(path, ())
    missing = [c for c in IMU_COLUMNS if c not in cols]
    if missing:
        raise InputError(f"{path}: lacks the columns {missing} (hvloc's imu.csv: {', '.join(IMU_COLUMNS)})")
    rows = np.column_stack([np.asarray(cols[k], np.float64) for k in IMU_COLUMNS])
    _check_imu_times(rows[:, 0], path)
    return rows, cols


def _check_imu_times(t: np.ndarray, where) -> None:
    bad = np.nonzero(~np.isfinite(t))[0]
    if len(bad):
        raise InputError(f"{where}: row {bad[0] + 1}'s t is {t[bad[0]]}, not a time")
    back = np.nonzero(np.diff(t) < 0)[0]
    if len(back):
        i = int(back[0]) + 1
        raise InputError(f"{where}: t goes back at row {i + 1} ({t[i]:.6g} s after {t[i - 1]:.6g} s): the IMU's rows "
                         "must be in time order")


def _check_camera_info(camera: Camera, fps: float, T_B_C: np.ndarray, info: dict, where) -> None:
    """An :class:`InputError` naming the field of a ``camera.json`` that no camera has: intrinsics
    (as a calibration read in: :func:`render.calibration.check_intrinsics`), a rate, a mount that
    is not a rigid transform, a shutter or clock offset that is not a number.  (A NaN in ``dist``
    or a ``T_B_C`` scaled by 2 was read without a word, and every frame of the sequence lost or
    rejected.)"""
    from .calibration import check_intrinsics

    check_intrinsics(camera, str(where))
    if not (math.isfinite(fps) and fps > 0):
        raise InputError(f"{where}: fps {fps} is not a frame rate")
    R = T_B_C[:3, :3]
    if not (np.isfinite(T_B_C).all() and np.abs(R @ R.T - np.eye(3)).max() < 1e-6 and np.linalg.det(R) > 0
            and np.abs(T_B_C[3] - [0.0, 0.0, 0.0, 1.0]).max() < 1e-9):
        raise InputError(f"{where}: T_B_C is not a rigid transform (a rotation and a translation): {T_B_C.tolist()}")
    for key in ("exposure_s", "rolling_shutter_line_s", "imu_time_offset_s", "rolling_shutter_ref_row"):
        v = info.get(key, 0.0)
        if v is None and key == "exposure_s":  # (an imported flight's: not known)
            continue
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)) or \
                (key != "imu_time_offset_s" and v < 0):
            raise InputError(f"{where}: {key} {v!r} is not a {'time' if key.endswith('_s') else 'row'}")
    if info.get("response") is not None:
        camera_response_of(info, where)


def camera_response_of(info: dict, where) -> tuple | None:
    """``camera.json``'s ``response`` (a photometric calibration: :func:`render.imaging.camera_response`)
    as ``(gamma, sharpen, sharpen_sigma_px)``, or ``None`` where the camera's response is not known;
    an :class:`InputError` naming the field that no camera's response has."""
    from hvloc.texfit import parse_response

    r = info.get("response")
    if r is None:
        return None
    if not isinstance(r, dict):  # (a tuple is the localizer's form, not camera.json's)
        raise InputError(f"{where}: response must be an object with gamma (and sharpen, sharpen_sigma_px), got {r!r}")
    try:
        return parse_response(r)
    except ValueError as err:
        raise InputError(f"{where}: {err}") from None


class Sequence:
    """One sequence folder: labels, camera, IMU and pad, with lazy image loading.

    ``expected``: ``{path: sha256}`` of its files (from the manifest).  With it, every file is
    checked against its checksum when it is read (labels on opening, each image when read), and
    a file that differs is an :class:`InputError`."""

    def __init__(self, root, expected: dict | None = None):
        self.root = Path(root)
        self.id = self.root.name
        self.expected = expected
        for name in SEQUENCE_FILES:
            if not (self.root / name).is_file():
                raise InputError(f"{self.root}: missing {name}")
        if expected is not None:
            bad = files_differing(self.root, {n: expected.get(n, "") for n in SEQUENCE_FILES})
            if bad:
                raise InputError(f"{self.root / bad[0]}: differs from the checksum in manifest.json "
                                 "(the dataset was changed or damaged; hvloc dataset verify lists everything)")
        self.columns = read_csv_columns(self.root / "frames.csv", TEXT_COLUMNS)
        missing = [c for c in FRAME_COLUMNS if c not in self.columns]
        if missing:
            raise InputError(f"{self.root / 'frames.csv'}: lacks columns {missing[:4]}")
        try:
            info = json.loads((self.root / "camera.json").read_text())
            self.camera = Camera.from_dict(info)
            self.fps = float(info["fps"])
            self.T_B_C = np.asarray(info["T_B_C"], np.float64).reshape(4, 4)
            self.meta = json.loads((self.root / "meta.json").read_text())
        except (ValueError, KeyError, TypeError) as err:
            raise InputError(f"{self.root}: camera.json or meta.json cannot be read ({err})") from None
        _check_camera_info(self.camera, self.fps, self.T_B_C, info, self.root / "camera.json")
        self.camera_info = info
        self._imu = None
        self._pad = None

    def __len__(self) -> int:
        return len(self.columns["frame"])

    @property
    def t(self) -> np.ndarray:
        return self.columns["t"]

    @property
    def cam2pad(self) -> np.ndarray:
        """``(N, 4, 4)`` labelled ``T_P_C``."""
        rows = np.column_stack([self.columns[k] for k in POSE])
        return np.stack([transform_from_tum(r) for r in rows])

    @property
    def phase_gt(self) -> np.ndarray:
        return self.columns["phase_gt"]

    @property
    def imu(self) -> np.ndarray:
        """``(M, 11)``: t, gyro xyz, accel xyz, AHRS quaternion xyzw."""
        if self._imu is None:
            from .imu import IMU_BIAS_COLUMNS

            self._imu, cols = read_imu_csv(self.root / "imu.csv")
            self._imu_bias = (np.column_stack([cols[k] for k in IMU_BIAS_COLUMNS])
                              if all(k in cols for k in IMU_BIAS_COLUMNS) else None)
        return self._imu

    @property
    def imu_bias(self) -> np.ndarray | None:
        """``(M, 6)`` true gyro and accelerometer biases per IMU row, or ``None`` (datasets made
        before imu.csv carried them)."""
        _ = self.imu
        return self._imu_bias

    @property
    def pad(self):
        """The pad, with its texture read from the dataset (never re-rasterised)."""
        if self._pad is None:
            from pad_design.pad import Pad

            self._pad = Pad.load(self.root / "pad.json")
        return self._pad

    @property
    def line_s(self) -> float:
        """Rolling shutter: time between consecutive rows (0: global shutter).  Row ``r`` of frame
        ``k`` is exposed at ``t_k + (r - ref_row) * line_s``; the labels are those of ``ref_row``."""
        return float(self.camera_info.get("rolling_shutter_line_s", 0.0))

    @property
    def exposure_s(self) -> float:
        """How long each frame is exposed (s; 0 where the camera does not say): how far motion smears it."""
        v = self.camera_info.get("exposure_s", 0.0)
        return float(v) if isinstance(v, (int, float)) and math.isfinite(v) and v > 0 else 0.0

    @property
    def response(self) -> tuple | None:
        """The camera's photometric response where ``camera.json`` gives it, ``(gamma, sharpen,
        sharpen_sigma_px)`` (:func:`camera_response_of`); ``None``: not known."""
        return camera_response_of(self.camera_info, self.root / "camera.json")

    @property
    def imu_time_offset_s(self) -> float:
        """The IMU's clock minus the camera's (imu.csv's t is on the IMU's clock)."""
        return float(self.camera_info.get("imu_time_offset_s", 0.0))

    @property
    def ref_row(self) -> float:
        return float(self.camera_info.get("rolling_shutter_ref_row", (self.camera.height - 1) / 2))

    def pose_at(self, t: float) -> np.ndarray:
        """``T_P_C`` at any time within the sequence, interpolated between the labelled frames
        (position linearly, rotation along the shortest arc; held beyond the first and last)."""
        return interpolate_pose(self.t, self.cam2pad_at, t)

    def pad2world_at(self, t: float) -> np.ndarray:
        """``T_W_P`` (the pad's pose in the world: a moving deck's) at any time, as :meth:`pose_at`."""
        return interpolate_pose(self.t, lambda k: transform_from_tum([self.columns[f"pad2world_{n}"][k] for n in POSE]), t)

    def cam2pad_at(self, k: int) -> np.ndarray:
        return transform_from_tum([self.columns[n][k] for n in POSE])

    def image_path(self, k: int) -> Path:
        return self.root / str(self.columns["image"][k])

    def image_bytes(self, k: int) -> bytes:
        """Frame ``k``'s PNG file as stored (checked against the manifest when opened with it)."""
        rel = str(self.columns["image"][k])
        path = self.root / rel
        try:
            data = path.read_bytes()
        except OSError as err:
            raise InputError(f"{path}: cannot read ({err.strerror or err})") from None
        if self.expected is not None and sha256_bytes(data) != self.expected.get(rel):
            raise InputError(f"{path}: differs from the checksum in manifest.json (the dataset was changed or damaged)")
        return data

    def image(self, k: int) -> np.ndarray:
        return decode_image(self.image_bytes(k), self.image_path(k))

    def frame(self, k: int) -> Frame:
        c = self.columns
        corners = np.array([[c[f"c{i}u"][k], c[f"c{i}v"][k]] for i in range(4)])
        vis = np.array([bool(c[f"c{i}_visible"][k]) for i in range(4)])
        return Frame(int(c["frame"][k]), float(c["t"][k]), self.image_path(k),
                     transform_from_tum([c[n][k] for n in POSE]),
                     str(c["phase_gt"][k]), float(c["height_above_pad"][k]), bool(c["pad_fully_visible"][k]),
                     int(c["markers_visible"][k]), corners, vis)

    def __iter__(self):
        for k in range(len(self)):
            yield self.frame(k)

    def imu_between(self, t0: float, t1: float) -> np.ndarray:
        imu = self.imu
        return imu[(imu[:, 0] > t0) & (imu[:, 0] <= t1)]


def _datasets_near(root: Path) -> str:
    """What a folder given for a dataset holds instead, to say in the error: a benchmark's results
    folder names its datasets, a sequence folder its dataset."""
    if (root / "frames.csv").is_file() and (root.parent / "manifest.json").is_file():
        return f"; it is a sequence of {root.parent}"
    inside = sorted(p for p in [*root.glob("*"), *root.glob("datasets/*")] if (p / "manifest.json").is_file())
    if inside:
        more = f" and {len(inside) - 2} more" if len(inside) > 2 else ""
        return "; it holds datasets: give one of " + ", ".join(str(p) for p in inside[:2]) + more
    return ""


class Dataset:
    """A generated dataset: its manifest and complete sequences (``.tmp-*`` folders are ignored).

    ``verify=True`` (what ``localize`` and ``bench run`` use): the dataset must be complete (every
    planned sequence listed, no unlisted sequence folder), the pad texture and every label file
    must match their checksums when opened, and each image when it is read."""

    def __init__(self, root, verify: bool = False):
        self.root = Path(root)
        m = load_manifest(self.root)
        if m is None:
            raise InputError(f"{self.root}: no manifest.json (not a generated dataset{_datasets_near(self.root)})")
        self.manifest = m
        self.verify = verify
        self.sequence_ids = [s["id"] for s in m["sequences"]]
        if verify:
            listed = set(self.sequence_ids)
            if len(listed) < m["sequences_planned"]:
                raise InputError(f"{self.root}: incomplete: {len(listed)} of {m['sequences_planned']} planned sequences "
                                 "(finish it with hvloc generate, or pass --no-verify)")
            extra = sorted(p.name for p in self.root.glob("seq_*") if p.is_dir() and p.name not in listed)
            if extra:
                raise InputError(f"{self.root}: sequence folder {extra[0]} is not in manifest.json "
                                 "(the dataset was changed or damaged; pass --no-verify to use it anyway)")
            tex = m["files"].get(PAD_TEXTURE)
            if tex is None or files_differing(self.root, {PAD_TEXTURE: tex}):
                raise InputError(f"{self.root / PAD_TEXTURE}: missing or differs from the checksum in manifest.json")

    def __len__(self) -> int:
        return len(self.sequence_ids)

    def _open(self, sid: str) -> Sequence:
        return Sequence(self.root / sid, sequence_files(self.manifest, sid) if self.verify else None)

    def __getitem__(self, key) -> Sequence:
        sid = self.sequence_ids[key] if isinstance(key, int) else key
        if sid not in self.sequence_ids:
            raise KeyError(sid)
        return self._open(sid)

    def __iter__(self):
        for sid in self.sequence_ids:
            yield self._open(sid)


class FrameDataset:
    """A ``torch.utils.data.Dataset`` over every frame of a dataset (a module-level class: it
    pickles under every DataLoader start method).

    Items are dicts: ``image`` (3, H, W) float32 in [0, 1]; ``cam2pad`` (4, 4) float64 ``T_P_C``;
    ``K`` (3, 3) and ``dist`` (5,) float64; ``corners_px`` (4, 2) float64 (NaN outside the image)
    and ``corners_visible`` (4,) bool; ``height_m``, ``t`` (float); ``phase_gt``, ``sequence``
    (str); ``frame`` (int).  ``transform(item) -> item`` is applied last when given."""

    def __init__(self, root, transform=None):
        self.root = Path(root)
        ds = Dataset(self.root)
        self.index = [(sid, k) for sid in ds.sequence_ids for k in range(len(ds[sid]))]
        self.transform = transform
        self._open: dict = {}

    def __len__(self) -> int:
        return len(self.index)

    def __getstate__(self):
        return {"root": self.root, "index": self.index, "transform": self.transform, "_open": {}}

    def __getitem__(self, i):
        import torch

        sid, k = self.index[i]
        if sid not in self._open:
            self._open[sid] = Sequence(self.root / sid)
        seq = self._open[sid]
        f = seq.frame(k)
        item = {"image": torch.from_numpy(seq.image(k)).permute(2, 0, 1).float() / 255.0,
                "cam2pad": torch.from_numpy(f.cam2pad), "K": torch.from_numpy(seq.camera.K),
                "dist": torch.tensor(seq.camera.dist, dtype=torch.float64), "camera_model": seq.camera.model,
                "corners_px": torch.from_numpy(f.corners_px), "corners_visible": torch.from_numpy(f.corners_visible),
                "height_m": f.height_above_pad, "t": f.t, "phase_gt": f.phase_gt, "sequence": sid, "frame": k}
        return self.transform(item) if self.transform is not None else item


def frame_dataset(root, transform=None) -> FrameDataset:
    """Every frame of the dataset at ``root`` as a torch Dataset (see :class:`FrameDataset`)."""
    return FrameDataset(root, transform)


# ----------------------------------------------------------------------------- verify

def verify_dataset(root, check_labels: bool = True, check_images: bool = True) -> list:
    """Everything wrong with a dataset folder, as readable lines (empty: it verifies).  Never
    raises on a damaged dataset: every problem, structural or not, is a line."""
    root = Path(root)
    try:
        m = json.loads((root / "manifest.json").read_text())
    except FileNotFoundError:
        return [f"{root}: no manifest.json"]
    except (ValueError, OSError, UnicodeDecodeError) as err:
        return [f"manifest.json: not valid JSON ({err})"]
    problems = manifest_problems(m)
    if problems:
        return problems
    ids = [s["id"] for s in m["sequences"]]
    planned = [sequence_id(i) for i in range(m["sequences_planned"])]
    problems += [f"{sid}: missing (planned in the spec, not complete)" for sid in planned if sid not in ids]
    files = m["files"]
    for rel, digest in files.items():
        p = root / rel
        if not p.is_file():
            problems.append(f"{rel}: listed in the manifest but missing")
        elif sha256_file(p) != digest:
            problems.append(f"{rel}: checksum differs from the manifest")
    if PAD_TEXTURE not in files:
        problems.append(f"{PAD_TEXTURE}: the pad texture is not listed in the manifest")
    leftovers = sorted(p.name for p in root.glob(".tmp-*"))
    if leftovers:
        problems.append(f"unfinished sequence folders: {', '.join(leftovers)}")
    for p in sorted(root.rglob("*")):
        rel = p.relative_to(root).as_posix()
        if p.is_file() and rel not in files and rel not in ("manifest.json", LOCK_NAME) \
                and not rel.startswith(".tmp-") and not rel.startswith("show/"):
            problems.append(f"{rel}: not in the manifest")
    for sid in ids:
        listed = sequence_files(m, sid)
        missing = [n for n in SEQUENCE_FILES if n not in listed]
        if missing:
            problems.append(f"{sid}: the manifest lists no {missing[0]}")
        if check_labels and (root / sid).is_dir():
            try:
                problems += [f"{sid}: {p}" for p in _label_problems(root / sid)]
            except InputError as err:
                problems.append(f"{sid}: {err}")
            except Exception as err:  # a damaged file must be reported, never crash verify
                problems.append(f"{sid}: cannot be read ({type(err).__name__}: {err})")
        if check_images and check_labels and (root / sid).is_dir() and not any(p.startswith(sid) for p in problems):
            from .checks import image_label_problems

            try:
                problems += [f"{sid}: {p}" for p in image_label_problems(Sequence(root / sid))]
            except InputError as err:
                problems.append(f"{sid}: {err}")
    return problems


def _label_problems(seq_dir: Path) -> list:
    from hvloc.geometry import transform_points

    out = []
    seq = Sequence(seq_dir)
    c = seq.columns
    n = len(seq)
    if n == 0:
        return ["frames.csv has no frames"]
    imgs = {p.name for p in (seq_dir / "images").glob("*.png")}
    named = {Path(str(v)).name for v in c["image"]}
    if imgs != named:
        out.append(f"{len(imgs)} images for {n} frames (or images not named in frames.csv)")
    t = c["t"]
    if not np.all(np.isfinite(t)) or (n > 1 and np.any(np.diff(t) <= 0)):
        out.append("frame times not finite and increasing")
    jitter = float(seq.camera_info.get("frame_time_jitter_s") or 0.0)
    if n > 1 and np.any(np.diff(c["frame"]) <= 0):
        out.append("frame indices do not increase")
    if np.any(np.abs(t - c["frame"] / seq.fps) > (0.4 / seq.fps + 1e-9 if jitter > 0 else 1e-6)):
        out.append("frame k is not at t = k / fps" + (" within its jitter" if jitter > 0 else ""))
    imported = seq.meta.get("imported")
    q = np.column_stack([c[k] for k in ("qx", "qy", "qz", "qw")])
    # an imported recording may lack ground truth on some frames: then the whole pose is NaN
    has = np.isfinite(q).all(axis=1) if imported else np.ones(n, bool)
    none = ~np.isfinite(np.column_stack([c[k] for k in POSE])).any(axis=1)
    qh = q[has]
    if np.any(~(has | none)) or np.any(~np.isfinite(qh)) or np.any(np.abs(np.linalg.norm(qh, axis=1) - 1) > 1e-6):
        out.append("non-unit quaternions")
    elif len(qh) > 1 and np.any(np.sum(qh[1:] * qh[:-1], axis=1) < 0):
        out.append("quaternions change hemisphere between rows")
    if np.any(np.abs(c["height_above_pad"][has] - c["tz"][has]) > 1e-9) or np.any(~(c["tz"][has] > 0)):
        out.append("height_above_pad is not tz > 0")
    bad_phase = set(c["phase_gt"][has]) - set(PHASES) | set(c["phase_gt"][~has]) - {""}
    if bad_phase:
        out.append(f"unknown phases {sorted(bad_phase)}")
    gt = read_tum(seq_dir / "groundtruth.tum")
    if gt.shape[0] != n or np.abs(gt[:, 0] - t).max(initial=0) > 1e-9 or \
            np.abs(gt[:, 1:] - np.column_stack([c[k] for k in POSE])).max(initial=0) > 1e-9:
        out.append("groundtruth.tum disagrees with frames.csv")
    corners = seq.pad.outer_corners_P
    worst, excess = 0.0, 0.0
    labels = np.stack([np.column_stack([c[f"c{i}u"], c[f"c{i}v"]]) for i in range(4)], axis=1)  # (n, 4, 2)
    # a rolling shutter's corners are where they appear (each at its row's time): the poses between
    # labelled frames are interpolated, so they agree to a fraction of a pixel plus the
    # interpolation's own error, which grows with how much the corners' motion bends from frame to
    # frame (a quarter of their second difference bounds it for the rows' offsets from the frame time)
    bend = np.zeros(n)
    if seq.line_s > 0 and n > 2:
        second = np.linalg.norm(labels[2:] - 2 * labels[1:-1] + labels[:-2], axis=2)
        b = np.nanmax(np.where(np.isfinite(second), second, 0.0), axis=1)
        bend[1:-1] = b
        bend[0], bend[-1] = b[0], b[-1]
    for k in np.nonzero(has)[0]:
        tolerance = 1e-3 if seq.line_s == 0 else 0.5 + 0.25 * bend[k]
        T = transform_from_tum([c[f][k] for f in POSE])
        px = seq.camera.project(transform_points(np.linalg.inv(T), corners))
        for _ in range(3 if seq.line_s > 0 else 0):
            rows = np.clip(np.nan_to_num(px[:, 1], nan=seq.ref_row), 0, seq.camera.height - 1)
            px = np.stack([seq.camera.project(transform_points(np.linalg.inv(seq.pose_at(c["t"][k] + (r - seq.ref_row)
                                                                                          * seq.line_s)), corners[i:i + 1]))[0]
                           for i, r in enumerate(rows)])
        lab = labels[k]
        # within the tolerance of the image's edge a corner may fall either way
        near = seq.camera.in_image(px, -tolerance) & ~seq.camera.in_image(px, tolerance)
        inside = seq.camera.in_image(px)
        px[~inside] = np.nan
        if not np.array_equal(np.isnan(px), np.isnan(lab)):
            if seq.line_s == 0 or np.any((np.isnan(px).any(axis=1) != np.isnan(lab).any(axis=1)) & ~near):
                out.append(f"frame {k}: corner in-view flags disagree with the pose")
                break
        vis = np.array([c[f"c{i}_visible"][k] for i in range(4)]) > 0.5
        if np.any(vis & ~(np.isfinite(lab).all(axis=1) & seq.camera.in_image(lab))):
            out.append(f"frame {k}: a corner outside the image is labelled visible")
            break
        d = np.linalg.norm(px - lab, axis=1)
        if np.isfinite(d).any():
            worst = max(worst, float(np.nanmax(d)))
            excess = max(excess, float(np.nanmax(d)) - tolerance)
    if excess > 0:
        out.append(f"projected corners disagree with the pose by {worst:.4f} px")
    imu = seq.imu
    if imported and not imported.get("imu"):
        if len(imu):
            out.append("imu.csv has rows, yet the import says it had no IMU")
    elif len(imu) < 2 or not np.all(np.isfinite(imu)) or imu[0, 0] > t[0] + seq.imu_time_offset_s + 1e-9 \
            or imu[-1, 0] < t[-1] + seq.imu_time_offset_s - 0.01:
        out.append("imu.csv does not cover the frames with finite values")
    return out
