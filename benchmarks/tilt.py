"""How much of a localizer's lateral error is the tilt it took from the AHRS: per dataset and height
band, over the accepted poses of a results folder (``hvloc bench run``'s ``--out``).

    python -m benchmarks.tilt RESULTS_DIR [--localizer hierarchical] [--bands 0 1 2 3 4 6 9 14 21]

Columns: poses, lateral error RMS (mm, pad frame x and y), the pose's tilt error (the angle between
its pad normal and the true one, both in the camera frame), the AHRS's (its up direction, through
the camera mount, against the true one; the AHRS row a flight computer would have at the frame,
``benchmarks.run.imu_at``), and the lateral RMS over the height as an angle.  Where the pose's tilt
error tracks the AHRS's and the lateral angle tracks both, the gravity prior carries the AHRS's
error into the position (a tilt of 0.3 degrees is 0.5 % of the height sideways).  The last
columns are that floor for the poses made from corners (``method`` outline or markers): what
hvloc's solver makes of the same corners where the labels put them, with the AHRS's up (no
detection error left: what only the AHRS or the fusion can move).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from pad_design.errors import ArgumentParser

from hvloc.geometry import matrix_from_quat_xyzw
from hvloc.localizer import up_in_camera

from .run import imu_at, read_estimates

def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.atan2(np.linalg.norm(np.cross(a, b)), float(a @ b)))


def tilt_rows(results_dir, localizer: str = "hierarchical") -> list:
    """``(dataset, sequence, frame, height m, lateral error m, pose tilt error deg, AHRS tilt error
    deg or nan, lateral error m of the pose from the labelled corners or nan)`` for every accepted
    pose of ``localizer`` in a results folder.  The pad lies level (its normal is the world's up),
    as in every dataset hvloc renders.  The last, for poses from corners, is what the AHRS alone
    leaves them: the pose hvloc's solver makes of the corners where the labels put them, with the
    AHRS's up as its gravity prior (no image error at all): an outline pose's four outer corners; a
    markers pose's marker corners in view, weighed as hvloc weighs three markers (by their fit's
    residual, at least :data:`hvloc.localizer.MARKER_MIN_SIGMA_PX`) when all three are."""
    from render.dataset import Dataset

    root = Path(results_dir)
    est_root = root / "estimates" / localizer
    if not est_root.is_dir():
        raise SystemExit(f"{est_root}: no estimates of localizer {localizer!r} (see {root / 'estimates'})")
    rows = []
    for ds_dir in sorted(p for p in est_root.iterdir() if p.is_dir()):
        ds = Dataset(root / "datasets" / ds_dir.name)
        for seq in ds:
            path = ds_dir / seq.id / "estimates.csv"
            if not path.is_file():
                continue
            est = read_estimates(path)
            if len(est["frame"]) != len(seq):
                raise SystemExit(f"{path}: {len(est['frame'])} rows for the dataset's {len(seq)} frames")
            ok = np.asarray(est["status"]) == "ok"
            method = np.asarray(est["method"]) if "method" in est else np.full(len(ok), "")
            imu = seq.imu
            truth = seq.cam2pad
            for i in np.flatnonzero(ok):  # rows, one per frame of the dataset (its numbers have gaps where frames dropped)
                k = int(est["frame"][i])
                T = truth[i]
                R_est = matrix_from_quat_xyzw([est[c][i] for c in ("qx", "qy", "qz", "qw")])
                up_true, up_est = T[:3, :3][2], R_est[2]  # the pad's normal (the world's up) in the camera frame
                sample = imu_at(imu, float(seq.t[i]), seq.imu_time_offset_s)
                ahrs = floor = float("nan")
                if sample is not None:
                    up_C = up_in_camera(matrix_from_quat_xyzw(sample[7:11]), seq.T_B_C)
                    ahrs = _angle_deg(up_C, up_true)
                if sample is not None and method[i] in ("outline", "markers"):
                    labelled = _from_labelled_corners(seq, T, up_C, method[i])
                    if labelled is not None:
                        floor = math.hypot(*(labelled.cam2pad[:2, 3] - T[:2, 3]))
                lateral = math.hypot(float(est["tx"][i]) - T[0, 3], float(est["ty"][i]) - T[1, 3])
                rows.append((ds_dir.name, seq.id, k, float(T[2, 3]), lateral, _angle_deg(up_est, up_true), ahrs,
                             floor))
    return rows


def _from_labelled_corners(seq, T, up_C, method: str):
    """The pose hvloc's solver makes, with ``up_C`` as its gravity prior, of the corners a pose of
    ``method`` is made from, where the true pose ``T`` puts them (None where too few are in view)."""
    from hvloc.features import _inside
    from hvloc.localizer import MARKER_MIN_SIGMA_PX, MARKER_SIGMA_PER_RMS
    from hvloc.pose import solve_planar_pose

    geo, cam = seq.pad.geometry, seq.camera
    if method == "outline":
        return solve_planar_pose(cam, geo.outer_corners, cam.project_from(T, geo.outer_corners), up_C=up_C)
    P = np.concatenate([m.points for m in geo.markers])
    px = cam.project_from(T, P)
    seen = _inside(px, (cam.height, cam.width))
    if seen.sum() < 8:
        return None
    whole = all(seen[j * len(m.points):(j + 1) * len(m.points)].all() for j, m in enumerate(geo.markers))
    return solve_planar_pose(cam, P[seen], px[seen], up_C=up_C, prev_cam2pad=T,
                             sigma_from_fit=(MARKER_SIGMA_PER_RMS, MARKER_MIN_SIGMA_PX) if whole else None)


def summary(rows: list, bands) -> list:
    """Per dataset and height band: ``(dataset, lo, hi, n, lateral RMS mm, pose tilt median deg, AHRS
    tilt median deg, lateral RMS over mean height deg, poses from corners, their lateral RMS mm,
    the labelled corners' lateral RMS mm over the same frames)``."""
    out = []
    for name in sorted({r[0] for r in rows}):
        a = np.array([r[3:] for r in rows if r[0] == name], np.float64)
        for lo, hi in zip(bands[:-1], bands[1:]):
            m = (a[:, 0] >= lo) & (a[:, 0] < hi)
            if not m.any():
                continue
            lat = float(np.sqrt(np.mean(a[m, 1] ** 2)))
            o = m & np.isfinite(a[:, 4])  # the poses from corners, with their floor
            rms = (lambda v: 1000 * float(np.sqrt(np.mean(v ** 2))) if v.size else float("nan"))
            out.append((name, lo, hi, int(m.sum()), 1000 * lat, float(np.median(a[m, 2])),
                        float(np.nanmedian(a[m, 3])) if np.isfinite(a[m, 3]).any() else float("nan"),
                        math.degrees(lat / float(np.mean(a[m, 0]))), int(o.sum()), rms(a[o, 1]), rms(a[o, 4])))
    return out


def main(argv=None) -> int:
    p = ArgumentParser(prog="python -m benchmarks.tilt", description=__doc__)
    p.add_argument("results", help="a results folder of hvloc bench run")
    p.add_argument("--localizer", default="hierarchical", help="whose estimates (a name in estimates/)")
    p.add_argument("--bands", nargs="+", type=float, default=[0, 1, 2, 3, 4, 6, 9, 14, 21],
                   help="height band edges (m)")
    p.add_argument("--json", help="also write the summary rows here")
    a = p.parse_args(argv)
    bands = sorted(a.bands)
    if len(bands) < 2:
        p.error("--bands: give at least two edges")
    rows = summary(tilt_rows(a.results, a.localizer), bands)
    print("| dataset | height m | poses | lateral RMS mm | pose tilt error deg (median) | AHRS tilt error deg "
          "(median) | lateral RMS / height deg | poses from corners | their lateral RMS mm | from the labelled corners "
          "mm |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, lo, hi, n, lat, tilt, ahrs, ang, n_out, lat_out, floor in rows:
        print(f"| {name} | {lo:g}-{hi:g} | {n} | {lat:.1f} | {tilt:.3f} | {ahrs:.3f} | {ang:.3f} | {n_out} | "
              f"{lat_out:.1f} | {floor:.1f} |")
    if a.json:
        Path(a.json).write_text(json.dumps([dict(zip(("dataset", "lo_m", "hi_m", "poses", "lateral_rms_mm",
                                                       "pose_tilt_deg", "ahrs_tilt_deg", "lateral_deg",
                                                       "corner_poses", "corner_lateral_rms_mm",
                                                       "labelled_corners_lateral_rms_mm"), r))
                                            for r in rows], indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
