"""The dataset on disk (DESIGN.md, "Dataset on disk"): writer and reader side by side.

Atomicity: a sequence is rendered into ``.tmp-<id>/`` and renamed to ``<id>/`` only when every
file is written and checksummed; ``manifest.json`` is replaced atomically after each sequence.
An interrupted run therefore leaves only ``.tmp-*`` folders, which no reader or ``verify``
accepts and which the next run deletes and redoes.
"""
from __future__ import annotations

import csv
import hashlib
import json
import math
import os
import platform
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from hvloc.geometry import Camera, transform_from_tum
from pad_design.errors import InputError

FORMAT = "hvloc-dataset"
FORMAT_VERSION = 1
FRAME_COLUMNS = ["frame", "t", "image", "tx", "ty", "tz", "qx", "qy", "qz", "qw", "height_above_pad", "phase_gt",
                 "pad_fully_visible", "markers_visible", "module_px", "blur_px",
                 "c0u", "c0v", "c1u", "c1v", "c2u", "c2v", "c3u", "c3v"]
SEQUENCE_FILES = ("frames.csv", "groundtruth.tum", "imu.csv", "camera.json", "pad.json", "meta.json")


# ----------------------------------------------------------------------------- small io helpers

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


def sequence_seed(dataset_seed: int, index: int) -> int:
    """Per-sequence seed derived from the dataset seed and the index alone (regenerable alone)."""
    return int(np.random.SeedSequence([int(dataset_seed), int(index)]).generate_state(1, np.uint64)[0] % (2**63))


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
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns)
        for r in rows:
            w.writerow([_fmt(v) for v in r])


def read_csv_columns(path) -> dict:
    """CSV -> {column: numpy array} (numbers as float64, others as str)."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        raise InputError(f"{path}: empty CSV")
    head, body = rows[0], rows[1:]
    cols = {}
    for i, name in enumerate(head):
        vals = [r[i] if i < len(r) else "" for r in body]
        try:
            cols[name] = np.array([float(v) for v in vals], np.float64)
        except ValueError:
            cols[name] = np.array(vals, dtype=object)
    return cols


def write_tum(path, t, poses7, header: str) -> None:
    with open(path, "w") as f:
        f.write(f"# {header}\n")
        for ti, p in zip(t, poses7):
            f.write(" ".join(_fmt(v) for v in (ti, *p)) + "\n")


def read_tum(path) -> np.ndarray:
    """``(N, 8)``: t tx ty tz qx qy qz qw."""
    rows = [ln.split() for ln in Path(path).read_text().splitlines() if ln.strip() and not ln.startswith("#")]
    arr = np.array(rows, dtype=np.float64) if rows else np.zeros((0, 8))
    if arr.ndim != 2 or arr.shape[1] != 8:
        raise InputError(f"{path}: TUM rows need 8 values (t tx ty tz qx qy qz qw)")
    return arr


def write_image(path, rgb: np.ndarray) -> None:
    if not cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, 1]):
        raise OSError(f"could not write {path}")


def read_image(path) -> np.ndarray:
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise InputError(f"{path}: not a readable image")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


# ----------------------------------------------------------------------------- manifest

def load_manifest(root) -> dict | None:
    p = Path(root) / "manifest.json"
    if not p.exists():
        return None
    try:
        m = json.loads(p.read_text())
    except ValueError as err:
        raise InputError(f"{p}: not valid JSON ({err})") from None
    if m.get("format") != FORMAT:
        raise InputError(f"{p}: not an hvloc dataset manifest")
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


def finalize_sequence(tmp_dir: Path, final_dir: Path, meta: dict) -> dict:
    """Checksum every file, write meta.json, and rename the folder into place.  Returns files."""
    files = {}
    for p in sorted(tmp_dir.rglob("*")):
        if p.is_file() and p.name != "meta.json":
            files[p.relative_to(tmp_dir).as_posix()] = sha256_file(p)
    meta = dict(meta)
    meta["files"] = files
    (tmp_dir / "meta.json").write_text(json.dumps(meta, indent=1) + "\n")
    files["meta.json"] = sha256_file(tmp_dir / "meta.json")
    if final_dir.exists():
        shutil.rmtree(final_dir)
    os.replace(tmp_dir, final_dir)
    return files


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
    corners_px: np.ndarray  # (4, 2), NaN where out of view

    @property
    def rgb(self) -> np.ndarray:
        return read_image(self.image_path)


class Sequence:
    """One sequence folder: labels, camera, IMU and pad, with lazy image loading."""

    def __init__(self, root):
        self.root = Path(root)
        self.id = self.root.name
        for name in SEQUENCE_FILES:
            if not (self.root / name).exists():
                raise InputError(f"{self.root}: missing {name}")
        self.columns = read_csv_columns(self.root / "frames.csv")
        info = json.loads((self.root / "camera.json").read_text())
        self.camera_info = info
        self.camera = Camera.from_dict(info)
        self.fps = float(info["fps"])
        self.T_B_C = np.asarray(info["T_B_C"], np.float64)
        self.meta = json.loads((self.root / "meta.json").read_text())
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
        c = self.columns
        rows = np.column_stack([c[k] for k in ("tx", "ty", "tz", "qx", "qy", "qz", "qw")])
        return np.stack([transform_from_tum(r) for r in rows])

    @property
    def phase_gt(self) -> np.ndarray:
        return self.columns["phase_gt"]

    @property
    def imu(self) -> np.ndarray:
        """``(M, 11)``: t, gyro xyz, accel xyz, AHRS quaternion xyzw."""
        if self._imu is None:
            cols = read_csv_columns(self.root / "imu.csv")
            from .imu import IMU_COLUMNS

            self._imu = np.column_stack([cols[k] for k in IMU_COLUMNS])
        return self._imu

    @property
    def pad(self):
        if self._pad is None:
            from pad_design.pad import Pad

            self._pad = Pad.load(self.root / "pad.json")
        return self._pad

    def image_path(self, k: int) -> Path:
        return self.root / str(self.columns["image"][k])

    def image(self, k: int) -> np.ndarray:
        return read_image(self.image_path(k))

    def frame(self, k: int) -> Frame:
        c = self.columns
        corners = np.array([[c[f"c{i}u"][k], c[f"c{i}v"][k]] for i in range(4)])
        return Frame(int(c["frame"][k]), float(c["t"][k]), self.image_path(k),
                     transform_from_tum([c[n][k] for n in ("tx", "ty", "tz", "qx", "qy", "qz", "qw")]),
                     str(c["phase_gt"][k]), float(c["height_above_pad"][k]), bool(c["pad_fully_visible"][k]),
                     int(c["markers_visible"][k]), corners)

    def __iter__(self):
        for k in range(len(self)):
            yield self.frame(k)

    def imu_between(self, t0: float, t1: float) -> np.ndarray:
        imu = self.imu
        return imu[(imu[:, 0] > t0) & (imu[:, 0] <= t1)]


class Dataset:
    """A generated dataset: its manifest and complete sequences (``.tmp-*`` folders are ignored)."""

    def __init__(self, root):
        self.root = Path(root)
        m = load_manifest(self.root)
        if m is None:
            raise InputError(f"{self.root}: no manifest.json (not a generated dataset)")
        self.manifest = m
        self.sequence_ids = [s["id"] for s in m["sequences"]]

    def __len__(self) -> int:
        return len(self.sequence_ids)

    def __getitem__(self, key) -> Sequence:
        sid = self.sequence_ids[key] if isinstance(key, int) else key
        if sid not in self.sequence_ids:
            raise KeyError(sid)
        return Sequence(self.root / sid)

    def __iter__(self):
        for sid in self.sequence_ids:
            yield Sequence(self.root / sid)


def frame_dataset(root):
    """A ``torch.utils.data.Dataset`` over every frame: dicts with ``image`` (3, H, W) float32 in
    [0, 1], ``cam2pad`` (4, 4) float64, ``t``, ``phase_gt``, ``sequence`` and ``frame``."""
    import torch
    from torch.utils.data import Dataset as TorchDataset

    ds = Dataset(root)
    index = [(sid, k) for sid in ds.sequence_ids for k in range(len(ds[sid]))]
    cache = {}

    class _Frames(TorchDataset):
        def __len__(self):
            return len(index)

        def __getitem__(self, i):
            sid, k = index[i]
            if sid not in cache:
                cache[sid] = ds[sid]
            f = cache[sid].frame(k)
            img = torch.from_numpy(f.rgb).permute(2, 0, 1).float() / 255.0
            return {"image": img, "cam2pad": torch.from_numpy(f.cam2pad), "t": f.t, "phase_gt": f.phase_gt,
                    "sequence": sid, "frame": k}

    return _Frames()


# ----------------------------------------------------------------------------- verify

def verify_dataset(root, check_labels: bool = True) -> list:
    """Everything wrong with a dataset folder, as readable lines (empty: it verifies)."""
    root = Path(root)
    problems = []
    try:
        m = load_manifest(root)
    except InputError as err:
        return [str(err)]
    if m is None:
        return [f"{root}: no manifest.json"]
    ids = [s["id"] for s in m["sequences"]]
    planned = [sequence_id(i) for i in range(int(m.get("sequences_planned", len(ids))))]
    for sid in planned:
        if sid not in ids:
            problems.append(f"{sid}: missing (planned in the spec, not complete)")
    for rel, digest in sorted(m.get("files", {}).items()):
        p = root / rel
        if not p.exists():
            problems.append(f"{rel}: listed in the manifest but missing")
        elif sha256_file(p) != digest:
            problems.append(f"{rel}: checksum differs from the manifest")
    leftovers = sorted(p.name for p in root.glob(".tmp-*"))
    if leftovers:
        problems.append(f"unfinished sequence folders: {', '.join(leftovers)}")
    if check_labels:
        for sid in ids:
            if (root / sid).exists():
                problems += [f"{sid}: {p}" for p in _label_problems(root / sid)]
    return problems


def _label_problems(seq_dir: Path) -> list:
    from hvloc.geometry import transform_points

    out = []
    try:
        seq = Sequence(seq_dir)
    except (InputError, ValueError, KeyError) as err:
        return [str(err)]
    c = seq.columns
    missing = [k for k in FRAME_COLUMNS if k not in c]
    if missing:
        return [f"frames.csv lacks columns {missing}"]
    n = len(seq)
    imgs = list((seq_dir / "images").glob("*.png"))
    if len(imgs) != n:
        out.append(f"{len(imgs)} images for {n} frames")
    t = c["t"]
    if n > 1 and np.any(np.diff(t) <= 0):
        out.append("frame times not increasing")
    if np.any(np.abs(t - c["frame"] / seq.fps) > 1e-6):
        out.append("frame k is not at t = k / fps")
    q = np.column_stack([c[k] for k in ("qx", "qy", "qz", "qw")])
    if np.any(np.abs(np.linalg.norm(q, axis=1) - 1) > 1e-6):
        out.append("non-unit quaternions")
    if np.any(np.abs(c["height_above_pad"] - c["tz"]) > 1e-9) or np.any(c["tz"] <= 0):
        out.append("height_above_pad is not tz > 0")
    bad_phase = set(c["phase_gt"]) - {"approaching", "adjustment", "touchdown"}
    if bad_phase:
        out.append(f"unknown phases {sorted(bad_phase)}")
    gt = read_tum(seq_dir / "groundtruth.tum")
    if gt.shape[0] != n or np.abs(gt[:, 0] - t).max(initial=0) > 1e-9 or \
            np.abs(gt[:, 1:4] - np.column_stack([c["tx"], c["ty"], c["tz"]])).max(initial=0) > 1e-9:
        out.append("groundtruth.tum disagrees with frames.csv")
    # projected corners agree with the pose
    pad_doc = json.loads((seq_dir / "pad.json").read_text())
    corners = np.asarray(pad_doc["outer_corners"], float)
    worst = 0.0
    for k in range(n):
        T = transform_from_tum([c[f][k] for f in ("tx", "ty", "tz", "qx", "qy", "qz", "qw")])
        px = seq.camera.project(transform_points(np.linalg.inv(T), corners))
        px[~seq.camera.in_image(px)] = np.nan
        lab = np.array([[c[f"c{i}u"][k], c[f"c{i}v"][k]] for i in range(4)])
        if not np.array_equal(np.isnan(px), np.isnan(lab)):
            out.append(f"frame {k}: corner visibility disagrees with the pose")
            break
        d = np.abs(px - lab)
        worst = max(worst, float(np.nanmax(d)) if np.isfinite(d).any() else 0.0)
    if worst > 1e-3:
        out.append(f"projected corners disagree with the pose by {worst:.4f} px")
    imu = read_csv_columns(seq_dir / "imu.csv")
    if len(imu.get("t", [])) < 2 or imu["t"][0] > t[0] + 1e-9 or imu["t"][-1] < t[-1] - 0.01:
        out.append("imu.csv does not cover the frames")
    return out
