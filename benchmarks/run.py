"""Run a localizer over a dataset and write its estimates (DESIGN.md, "Localizer output").

This harness lives in ``benchmarks`` because it reads datasets with ``render``'s reader, and the
localizer package (``hvloc``) may import only ``pad_design`` (DESIGN.md, layout).
"""
from __future__ import annotations

import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from hvloc.config import LocalizerConfig, load_config
from hvloc.geometry import continuous_quaternions, tum_from_transform
from hvloc.localizer import Estimate, HierarchicalLocalizer
from pad_design.errors import ArgumentParser, InputError, prepare_out_dir, progress_bar, validate_model

# The pose covariance: 6x6 over (camera position in P [m], rotation vector [rad] of a perturbation
# R_P_C @ exp(d), i.e. about the camera's axes), upper triangle row by row; NaN without a pose.
COV_AXES = ("x", "y", "z", "rx", "ry", "rz")
COV_INDEX = [(i, j) for i in range(6) for j in range(i, 6)]
COV_COLUMNS = [f"cov_{COV_AXES[i]}_{COV_AXES[j]}" for i, j in COV_INDEX]
ESTIMATE_COLUMNS = ["frame", "t", "phase", "status", "tx", "ty", "tz", "qx", "qy", "qz", "qw", "ms",
                    "method", "n_corr", "rms_px", *COV_COLUMNS, "reason"]


def covariance_row(cov) -> list:
    """The 21 ``COV_COLUMNS`` values of a 6x6 covariance (NaN where there is none)."""
    if cov is None or np.shape(cov) != (6, 6):
        return [float("nan")] * len(COV_INDEX)
    return [float(cov[i, j]) for i, j in COV_INDEX]


def covariance_matrix(columns: dict, k: int) -> np.ndarray:
    """Row ``k``'s 6x6 covariance from the columns of a read ``estimates.csv``."""
    cov = np.empty((6, 6))
    for (i, j), name in zip(COV_INDEX, COV_COLUMNS):
        cov[i, j] = cov[j, i] = float(columns[name][k])
    return cov


def imu_at(imu: np.ndarray, t: float, offset_s: float = 0.0):
    """The latest IMU row at or before camera time ``t`` (the AHRS attitude a flight computer would
    have), read on the IMU's clock (``t + offset_s``: the sequence's ``imu_time_offset_s``, known as
    a calibrated rig knows it); ``None`` for a recording without an IMU, and for a frame before its
    first row (an imported flight whose IMU log starts late): a flight computer has no attitude yet,
    and the first row, from after the frame, is not one it could have had."""
    j = _last_row(imu, t, offset_s)
    return imu[j] if j >= 0 else None


def _last_row(imu: np.ndarray, t: float, offset_s: float) -> int:
    """The index of the IMU's last row at or before camera time ``t`` (its clock ``offset_s``
    ahead), -1 where there is none: the one search :func:`imu_at` and :func:`imu_since` share."""
    return int(np.searchsorted(imu[:, 0], t + offset_s + 1e-9)) - 1 if len(imu) else -1


def ahrs_error_scaled(seq, scale: float) -> np.ndarray:
    """``seq.imu`` with its AHRS attitude's error ``scale`` times what it is: what a better
    (``scale`` < 1) or worse AHRS would give on the same frames.  The error is the rotation from the
    true body attitude (the labels: the pad's pose in the world, the camera's on the pad, the
    mount) to the AHRS's at each row, ``R_AHRS = R_true exp(e)`` as the generator makes it
    (render.imu), and becomes ``R_true exp(scale e)``; gyro and accelerometer rows are unchanged.
    An :class:`InputError` for a sequence without the labels to know the error by."""
    from hvloc.geometry import matrix_from_quat_xyzw, quat_xyzw_from_matrix, so3_exp, so3_log

    imu = seq.imu
    if scale == 1.0 or len(imu) == 0:
        return imu
    if not (math.isfinite(scale) and scale >= 0.0):
        raise InputError(f"ahrs_error_scale: {scale!r} is no scale of an error (0 or more)")
    lacking = [c for c in ("tx", "qw", "pad2world_qw") if c not in seq.columns]
    if lacking:
        raise InputError(f"{seq.root}: an AHRS error is scaled against the labels, and frames.csv lacks {lacking}")
    R_C_B = seq.T_B_C[:3, :3].T
    out = imu.copy()
    for row in out:
        t = float(row[0]) - seq.imu_time_offset_s  # on the camera's clock, the labels'
        R_true = seq.pad2world_at(t)[:3, :3] @ seq.pose_at(t)[:3, :3] @ R_C_B
        q_old = row[7:11].copy()
        e = so3_log(R_true.T @ matrix_from_quat_xyzw(q_old))
        q = quat_xyzw_from_matrix(R_true @ so3_exp(scale * e))
        row[7:11] = q if float(q @ q_old) >= 0.0 else -q
    return out


IMU_BLOCK_MAX_S = 1.0  # a block holds at most this much: no localizer reasons from older samples


def imu_since(imu: np.ndarray, t_from: float | None, t: float, offset_s: float = 0.0):
    """The IMU's rows after camera time ``t_from`` (the last frame's) up to ``t``, oldest first, as
    the localizer takes them (``process(image, t, imu)``: a block, the last row the one
    :func:`imu_at` gives); at most :data:`IMU_BLOCK_MAX_S` of them, at least that last row.
    ``None`` where :func:`imu_at` gives none (no IMU, or no row yet at ``t``)."""
    j = _last_row(imu, t, offset_s)
    if j < 0:
        return None
    start = t - IMU_BLOCK_MAX_S if t_from is None else max(t_from, t - IMU_BLOCK_MAX_S)
    i = min(int(np.searchsorted(imu[:, 0], start + offset_s + 1e-9)), j)  # on the IMU's clock, as _last_row
    return imu[i:j + 1]


KINDS = ("hierarchical", "aruco", "apriltag")  # built in; any other localizer by entry point or import path
PAD_VARIANTS = {"hierarchical": ("paper", "nested"), "aruco": ("aruco", "aruco_nested"),
                "apriltag": ("apriltag",)}  # what each runs on by default
ENTRY_POINT_GROUP = "hvloc.localizers"


def localizer_class(kind: str):
    """The class a suite's ``kind`` names: ``hierarchical``, ``aruco``, a name registered under the
    ``hvloc.localizers`` entry point group, or an import path ``package.module:Class``.

    The protocol (README, "Bring your own localizer"): ``Class(pad, camera, config, T_B_C=...)``
    and ``.process(image, t, imu=None) -> hvloc.localizer.Estimate``; optionally ``PAD_VARIANTS``
    (the pad variants it runs on by default) and ``reset()``."""
    if kind == "hierarchical":
        return HierarchicalLocalizer
    if kind in ("aruco", "apriltag"):
        from .peers import LOCALIZERS

        return LOCALIZERS[kind]
    import importlib
    import importlib.metadata as md

    eps = {ep.name: ep for ep in md.entry_points(group=ENTRY_POINT_GROUP)}
    try:
        if kind in eps:
            cls = eps[kind].load()
        elif ":" in kind:
            mod, _, attr = kind.partition(":")
            if os.getcwd() not in sys.path and "" not in sys.path:  # as `python -m` would: your package here
                sys.path.append(os.getcwd())
            cls = importlib.import_module(mod)
            for part in attr.split("."):
                cls = getattr(cls, part)
        else:
            raise InputError(f"localizer kind {kind!r}: not hierarchical, aruco or apriltag, not an entry point of "
                             f"{ENTRY_POINT_GROUP} ({', '.join(sorted(eps)) or 'none installed'}), and not an "
                             "import path package.module:Class")
    except (ImportError, AttributeError) as err:
        raise InputError(f"localizer kind {kind!r}: cannot be imported ({type(err).__name__}: {err})") from None
    if not callable(cls) or not callable(getattr(cls, "process", None)):
        raise InputError(f"localizer kind {kind!r}: not a class with a process(image, t, imu) method")
    return cls


def pad_variants(kind: str) -> tuple:
    """The pad variants a localizer runs on by default."""
    if kind in PAD_VARIANTS:
        return PAD_VARIANTS[kind]
    from pad_design.geometry import VARIANTS

    return tuple(getattr(localizer_class(kind), "PAD_VARIANTS", VARIANTS))


def make_localizer(kind: str, seq, config: LocalizerConfig, gates: bool = False, work=None):
    """A localizer for one sequence's pad and camera; ``gates``: hvloc's false-pose gates in front
    of it (:class:`hvloc.localizer.GatedLocalizer`; hvloc's own localizer has them built in), and
    for hvloc's peers the IMU's gravity as a prior in their pose solve.
    A localizer from elsewhere always runs behind ``guarded_process``: it never raises.
    ``work``: an :class:`hvloc.work.ImageWork` that hvloc's localizers of this sequence share."""
    from hvloc.localizer import GatedLocalizer

    if kind == "hierarchical":
        loc = HierarchicalLocalizer(seq.pad, seq.camera, config, T_B_C=seq.T_B_C, work=work, line_s=seq.line_s,
                                    ref_row=seq.ref_row, exposure_s=seq.exposure_s,
                                    response=getattr(seq, "response", None))
    else:
        loc = localizer_class(kind)(seq.pad, seq.camera, config, T_B_C=seq.T_B_C)
    if gates and kind != "hierarchical":
        if hasattr(loc, "gravity_prior"):  # hvloc's peers: the IMU's gravity in their pose solve too
            loc.gravity_prior = True
        return GatedLocalizer(loc, config, seq.T_B_C)
    if kind not in KINDS:
        return _Guarded(loc)
    return loc


class _Guarded:
    """A localizer from elsewhere behind hvloc's "never raises" contract: an exception, a wrong
    return value or a bad timestamp becomes ``lost`` with the reason."""

    def __init__(self, inner):
        self.inner = inner

    def reset(self) -> None:
        if hasattr(self.inner, "reset"):
            self.inner.reset()

    IMU_BLOCK = True  # the inner localizer gets what it takes (hvloc.localizer.imu_for)

    def process(self, image, t, imu=None):
        from hvloc.localizer import guarded_process, imu_for

        return guarded_process(self.inner.process, image, t, imu_for(self.inner, imu), "")


UNREADABLE = "image unreadable: "  # the reason of a frame whose file could not be read (frame_image)


def frame_image(seq, k: int) -> tuple:
    """``(image | None, why)``: frame ``k``'s image as stored.  In a dataset read without its
    checksums (``--no-verify``: the user takes it as it is) a file that cannot be read or decoded is
    a frame without an image, which every localizer gives ``lost`` with ``why``; the frames before
    it and after it are localized as any others.  (It ended the whole run, with exit 2, and the
    sequence's estimates so far unwritten.)  Read with its checksums, a file that differs from them
    is a damaged dataset, refused as before."""
    try:
        return seq.image(k), ""
    except InputError as err:
        if getattr(seq, "expected", None) is not None:
            raise
        return None, str(err)


def localize_sequence(seq, config: LocalizerConfig, use_imu: bool = True, progress=None,
                      kind: str = "hierarchical", on_estimate=None) -> list:
    return localize_sequence_many(seq, [(config, use_imu, kind, False)], progress, on_estimate)[0]


def localize_sequence_many(seq, setups: list, progress=None, on_estimate=None, share_work: bool = True) -> list:
    """Several localizers ``[(config, use_imu, kind[, gates[, ahrs_error_scale]]), ...]`` over one
    sequence, each image read once (``ahrs_error_scale``: :func:`ahrs_error_scaled`, 1 by default).
    ``on_estimate(estimate)`` sees the first localizer's estimate of each frame as it is made.
    ``share_work``: hvloc's localizers share their image work (:mod:`hvloc.work`; each one's estimates
    are exactly what it makes alone, for less work where their states agree)."""
    from hvloc.work import ImageWork

    work = ImageWork() if share_work and sum(s[2] == "hierarchical" for s in setups) > 1 else None
    locs = [make_localizer(s[2], seq, s[0], bool(s[3]) if len(s) > 3 else False, work=work) for s in setups]
    scales = [float(s[4]) if len(s) > 4 else 1.0 for s in setups]
    imus = {c: ahrs_error_scaled(seq, c) for c in set(scales)}
    out = [[] for _ in setups]
    t_last = None
    for k in range(len(seq)):
        t = float(seq.t[k])
        img, unreadable = frame_image(seq, k)
        if work is not None:
            work.begin(k)
        samples = {c: imu_since(imu, t_last, t, seq.imu_time_offset_s) for c, imu in imus.items()}
        t_last = t
        for i, (loc, (_, use_imu, *_)) in enumerate(zip(locs, setups)):
            e = loc.process(img, t, samples[scales[i]] if use_imu else None)
            if unreadable:  # (whatever a localizer from elsewhere made of no image)
                e = Estimate(e.t, e.phase, "lost", None, ms=e.ms, reason=f"{UNREADABLE}{unreadable}")
            out[i].append(e)
        if on_estimate is not None:
            on_estimate(out[0][-1])
        if progress:
            progress(1)
    return out


def write_estimates(seq_out: Path, estimates: list, frames=None) -> None:
    """``estimates.csv`` and ``estimates.tum`` of one sequence; ``frames``: the dataset's frame indices
    (``frames.csv``'s ``frame``: gaps where frames were dropped), by default 0, 1, ..."""
    from render.dataset import write_csv, write_tum

    seq_out.mkdir(parents=True, exist_ok=True)
    rows, tum_t, tum_p = [], [], []
    poses = np.array([tum_from_transform(e.cam2pad) if e.cam2pad is not None else [np.nan] * 7 for e in estimates])
    if len(poses):
        poses[:, 3:] = continuous_quaternions(poses[:, 3:])  # one hemisphere from row to row (DESIGN.md)
    frames = range(len(estimates)) if frames is None else [int(f) for f in frames]
    for k, e, pose in zip(frames, estimates, poses.tolist()):
        rows.append([k, e.t, e.phase, e.status, *pose, round(e.ms, 3), e.method, e.n_corr, e.rms_px,
                     *covariance_row(e.cov), e.reason.replace(",", ";").replace("\n", " ")])
        if e.status == "ok":
            tum_t.append(e.t)
            tum_p.append(pose)
    tmp = seq_out / ".estimates.csv.tmp"
    write_csv(tmp, ESTIMATE_COLUMNS, rows)
    tmp.replace(seq_out / "estimates.csv")
    tmp = seq_out / ".estimates.tum.tmp"
    write_tum(tmp, tum_t, tum_p, "t tx ty tz qx qy qz qw  (estimated T_P_C, status ok only)")
    tmp.replace(seq_out / "estimates.tum")


def localize_dataset(root, out, config: LocalizerConfig | None = None, use_imu: bool = True,
                     show_progress: bool = True, kind: str = "hierarchical", verify: bool = True,
                     mavlink: str | None = None, mavlink_epoch_s: float = 0.0) -> dict:
    """Localize every sequence of a dataset; writes ``OUT/<seq>/estimates.{csv,tum}``.
    ``verify``: refuse a dataset whose files differ from their checksums (checked as read).
    ``mavlink``: also send each accepted pose as ``LANDING_TARGET`` (see ``benchmarks.mavlink``)."""
    from render.dataset import Dataset, FolderLock

    ds = Dataset(root, verify=verify)
    with FolderLock(out, "writing results into"):
        return _localize_dataset(ds, Path(out), config, use_imu, show_progress, kind, mavlink, mavlink_epoch_s)


def _localize_dataset(ds, out: Path, config, use_imu, show_progress, kind, mavlink=None, mavlink_epoch_s=0.0) -> dict:
    config = config or LocalizerConfig()
    total = sum(len(ds[s]) for s in ds.sequence_ids)
    bar = progress_bar(show_progress, total, "localize")
    t0 = time.time()
    results = {}
    stream = None
    try:
        for seq in ds:
            send = None
            if mavlink:
                from .mavlink import LandingTargetStream

                if stream is None:
                    stream = LandingTargetStream(mavlink, seq.pad.geometry.side_m, seq.T_B_C, mavlink_epoch_s)
                stream.T_B_C = seq.T_B_C
                send = stream.send
            est = localize_sequence(seq, config, use_imu, progress=bar.update if bar else None, kind=kind,
                                    on_estimate=send)
            write_estimates(out / seq.id, est, seq.columns["frame"])
            results[seq.id] = est
    finally:
        if bar:
            bar.close()
        if stream is not None:
            stream.close()
    (out / "localizer_config.json").write_text(json.dumps(config.model_dump(), indent=1) + "\n")
    return {"sequences": results, "seconds": time.time() - t0, "frames": total,
            "mavlink_sent": stream.sent if stream is not None else 0}


def score_dataset(root, results) -> dict:
    """A localizer's estimates (``hvloc localize --out results``) scored against a dataset's ground
    truth, per ground-truth phase: ``{"summary": {scope: metrics}, "by_pad_px": {size: metrics},
    "notes": [...]}`` (``by_pad_px``: by the pad's side in the image, :func:`benchmarks.metrics.size_scopes`).
    Frames without ground truth (an imported flight may have none) count toward availability only,
    and a note says so."""
    from render.dataset import Dataset

    from . import metrics as M

    ds = Dataset(root, verify=True)
    fes, notes = [], []
    for seq in ds:
        path = Path(results) / seq.id / "estimates.csv"
        if not path.is_file():
            raise InputError(f"{path}: missing (localize {root} into {results} first)")
        est = read_estimates(path, seq.columns["frame"])
        fes.append(M.frame_errors(seq.columns, est))
        no_gt = int(sum(1 for p in seq.columns["phase_gt"] if p not in M.PHASES))
        if no_gt:
            notes.append(f"{seq.id}: {no_gt} of {len(seq)} frames have no ground truth: they count toward "
                         "availability only (no error, no phase, no false accept)")
    fe = M.concat(fes)
    summary = M.phase_scopes(fe)
    if not np.isfinite(fe["height_m"]).any():  # nothing to judge a pose by: unknown, not zero
        summary["all"].update(false_accepts=None, rejections_right=None, rejections_wrong=None)
    return {"summary": summary, "by_pad_px": M.size_scopes(fe), "notes": notes}


ESTIMATE_TEXT_COLUMNS = ("phase", "status", "method", "reason")
ESTIMATE_REQUIRED = ("frame", "t", "status", "tx", "ty", "tz", "qx", "qy", "qz", "qw")
STATUSES = ("ok", "rejected", "lost")


def read_estimates(path, frames=None) -> dict:
    """An ``estimates.csv`` as ``{column: array}``, or an :class:`InputError` naming the row and
    column of what no localizer's output holds: a number that is not one, a status other than
    ``ok``, ``rejected`` or ``lost``, an ``ok`` without a finite pose; with ``frames`` (the dataset's
    ``frame`` column), rows that are not its frames in its order.  (A localizer from elsewhere
    writes this file: a word in ``tx`` ended ``hvloc bench score`` in a traceback, and two rows
    swapped, an unknown status or an ``ok`` without a pose were scored without a word, each frame
    against another's labels or counted available.)"""
    from render.dataset import read_csv_columns

    path = Path(path)
    c = read_csv_columns(path, ESTIMATE_TEXT_COLUMNS)
    missing = [k for k in ESTIMATE_REQUIRED if k not in c]
    if missing:
        raise InputError(f"{path}: lacks columns {missing}")
    bad = [k for k, s in enumerate(c["status"]) if s not in STATUSES]
    if bad:
        raise InputError(f"{path}: row {bad[0] + 2}'s status is {c['status'][bad[0]]!r}, not one of {', '.join(STATUSES)}")
    pose = np.column_stack([c[k] for k in ESTIMATE_REQUIRED[3:]])
    bad = np.nonzero((c["status"] == "ok") & ~np.isfinite(pose).all(axis=1))[0]
    if len(bad):
        raise InputError(f"{path}: row {bad[0] + 2} is ok without a finite pose (tx..qw)")
    if frames is not None:
        want = np.asarray(frames, np.float64)
        if len(c["frame"]) != len(want):
            raise InputError(f"{path}: {len(c['frame'])} frames, the dataset's sequence has {len(want)}")
        bad = np.nonzero(c["frame"] != want)[0]
        if len(bad):
            k = int(bad[0])
            raise InputError(f"{path}: row {k + 2} is frame {c['frame'][k]:g}, the dataset's row {k + 2} frame "
                             f"{want[k]:g} (an estimate per frame, in the dataset's order)")
    return c


def localize_main(argv: list) -> int:
    p = ArgumentParser(prog="hvloc localize", description="Run the hierarchical localizer over a dataset.")
    p.add_argument("dataset", help="dataset folder (made by hvloc generate)")
    p.add_argument("--out", required=True, help="results folder: <seq>/estimates.csv and estimates.tum")
    p.add_argument("--config", help="localizer config YAML (fields of hvloc/config.py)")
    p.add_argument("--no-imu", action="store_true", help="do not give the localizer the AHRS attitude")
    p.add_argument("--localizer", default="hierarchical",
                   help="hierarchical (hvloc's), aruco (the cv2.aruco peer, aruco pad), apriltag (the AprilTag 3 peer, apriltag pad), a name registered "
                        "under the hvloc.localizers entry point group, or an import path package.module:Class")
    p.add_argument("--no-verify", action="store_true",
                   help="use a dataset even if its files differ from the checksums in its manifest")
    p.add_argument("--mavlink", metavar="TARGET",
                   help="also send each accepted pose as a MAVLink LANDING_TARGET: udp:HOST:PORT, or a .tlog file path")
    p.add_argument("--mavlink-epoch", type=float, default=0.0,
                   help="seconds added to the frame time for time_usec (default 0: time since boot)")
    p.add_quiet()
    a = p.parse_args(argv)
    cfg = load_config(a.config) if a.config else LocalizerConfig()
    if not Path(a.dataset).is_dir():
        raise InputError(f"{a.dataset}: no such dataset folder")
    from render.dataset import Dataset

    if a.localizer != "hierarchical":
        localizer_class(a.localizer)  # a kind that cannot be imported is refused before anything is written
    ds = Dataset(a.dataset, verify=False)  # its pad only (localize_dataset verifies what it reads)
    if len(ds) == 0:
        raise InputError(f"{a.dataset}: the dataset has no complete sequence to localize")
    geometry = ds[0].pad.geometry
    # hvloc's own localizer reads any pad with its border and cue (the markers' phase falls through)
    usable = geometry.border is not None if a.localizer == "hierarchical" else \
        geometry.variant in pad_variants(a.localizer)
    if not usable:
        wants = "a pad with hvloc's border and cue" if a.localizer == "hierarchical" else \
            f"the {' or '.join(pad_variants(a.localizer))} pad variant"
        raise InputError(f"{a.dataset}: --localizer {a.localizer} needs a dataset of {wants}, this one has the "
                         f"{geometry.variant!r} pad")
    prepare_out_dir(a.out)
    res = localize_dataset(a.dataset, a.out, cfg, use_imu=not a.no_imu, show_progress=not a.quiet,
                           kind=a.localizer, verify=not a.no_verify, mavlink=a.mavlink, mavlink_epoch_s=a.mavlink_epoch)
    n_ok = sum(e.status == "ok" for v in res["sequences"].values() for e in v)
    print(f"{a.out}: {len(res['sequences'])} sequence(s), {res['frames']} frames, {n_ok} poses ok "
          f"({res['seconds']:.1f} s)" + (f"; {res['mavlink_sent']} LANDING_TARGET to {a.mavlink}" if a.mavlink else ""))
    unreadable = [e.reason[len(UNREADABLE):] for v in res["sequences"].values() for e in v
                  if e.reason.startswith(UNREADABLE)]
    if unreadable:  # (said where it cannot be missed: the run went on past them)
        print(f"{len(unreadable)} image(s) unreadable, localized as lost: {'; '.join(unreadable[:3])}"
              + (f"; and {len(unreadable) - 3} more" if len(unreadable) > 3 else ""), file=sys.stderr)
    return 0


__all__ = ["localize_dataset", "localize_sequence", "write_estimates", "read_estimates", "Estimate",
           "validate_model"]
