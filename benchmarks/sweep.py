"""Switch-height sweeps at about the cost of one localizer pass.

Each phase's per-frame output does not depend on the switching thresholds: the outline and
marker detections (with their poses) and the frame-to-frame homographies of the flow tracker.
So they are computed once per frame, and the switching policy (``hvloc.localizer.next_phase``,
the very function the live localizer uses) is replayed over them for every grid point.

What the replay simplifies, stated so the numbers are read right: the flow tracker is replayed
as the paper's chain of frame-to-frame homographies from the last anchored pose (the live
tracker refines against a keyframe instead), markers and outline are searched in the full frame
(the live localizer searches a predicted ROI first), and the gates are the reprojection and
speed gates (not the vision-IMU rotation gate).  ``compare_with_live`` puts a replay at the
default thresholds beside a real run.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from hvloc import phases as ph
from hvloc.config import LocalizerConfig
from hvloc.geometry import invert, make_transform
from hvloc.localizer import (METHOD_ORDER, METHOD_PHASE, check_image, imu_rotation, method_allowed, motion_gate,
                             next_phase, policy_height)
from hvloc.pose import pose_from_homography, solve_planar_pose

from . import metrics as M


@dataclass
class FrameCache:
    """Per-frame, threshold-independent outputs of one sequence."""

    t: np.ndarray
    outline: list = field(default_factory=list)   # (cam2pad, rms) or None
    markers: list = field(default_factory=list)   # (cam2pad, rms) or None
    h_step: list = field(default_factory=list)    # 3x3 normalised-image homography k-1 -> k, or None
    seconds: float = 0.0


def _pose_or_none(camera, det, up_C):
    if det is None:
        return None
    res = solve_planar_pose(camera, det.pts_P, det.px, up_C=up_C)
    return None if res is None else (res.cam2pad, res.rms_px)


def frame_to_frame_homography(camera, prev_gray, gray):
    pts = cv2.goodFeaturesToTrack(prev_gray, 150, 0.005, 8, blockSize=5, useHarrisDetector=True, k=0.04)
    if pts is None or len(pts) < 8:
        return None
    p1, st, _ = cv2.calcOpticalFlowPyrLK(prev_gray, gray, pts, None, **ph.LK_PARAMS)
    if p1 is None:
        return None
    pb, stb, _ = cv2.calcOpticalFlowPyrLK(gray, prev_gray, p1, None, **ph.LK_PARAMS)
    good = (st[:, 0] == 1) & (stb[:, 0] == 1) & (np.linalg.norm((pb - pts)[:, 0, :], axis=1) < 1.0)
    if good.sum() < 8:
        return None
    a = camera.normalized_from_pixels(pts[good, 0, :].astype(np.float64))
    b = camera.normalized_from_pixels(p1[good, 0, :].astype(np.float64))
    H, inl = cv2.findHomography(a, b, cv2.RANSAC, 2.0 / camera.fx)
    if H is None or inl.sum() < 8:
        return None
    return H


def precompute(seq, use_imu: bool = True) -> FrameCache:
    """One pass over a sequence: every phase's output on every frame."""
    from .run import imu_at

    t0 = time.perf_counter()
    cam, geo = seq.camera, seq.pad.geometry
    T_B_C = seq.T_B_C
    imu = seq.imu if use_imu else None
    cache = FrameCache(np.asarray(seq.t, float))
    prev = None
    for k in range(len(seq)):
        rgb, gray, _ = check_image(seq.image(k))
        up_C = None
        if imu is not None:
            R_W_B = imu_rotation(imu_at(imu, float(seq.t[k])))
            up_C = (R_W_B @ T_B_C[:3, :3]).T @ np.array([0.0, 0.0, 1.0])
        cache.outline.append(_pose_or_none(cam, ph.detect_outline(rgb, geo, cam)[0], up_C))
        cache.markers.append(_pose_or_none(cam, ph.detect_markers(gray, geo, cam, rgb=rgb)[0], up_C))
        cache.h_step.append(frame_to_frame_homography(cam, prev, gray) if prev is not None else None)
        prev = gray
    cache.seconds = time.perf_counter() - t0
    return cache


def replay(cache: FrameCache, cfg: LocalizerConfig) -> dict:
    """The switching policy over cached outputs: per-frame status, phase, pose."""
    n = len(cache.t)
    status = np.array(["lost"] * n, dtype=object)
    phase_est = np.array(["approaching"] * n, dtype=object)
    poses = [None] * n
    phase, last, last_t, last_method = "approaching", None, 0.0, ""
    anchor_H = None  # pad (x, y) -> normalised image of the current frame, chained
    for k in range(n):
        if anchor_H is not None:
            anchor_H = cache.h_step[k] @ anchor_H if cache.h_step[k] is not None else None
        h = policy_height(float(last[2, 3]) if last is not None else None, last_t, float(cache.t[k]), cfg)
        phase = next_phase(phase, h, last_method, cfg)
        phase_est[k] = phase
        for method in METHOD_ORDER[phase]:
            if not getattr(cfg, f"use_{method}") or not method_allowed(method, h, cfg):
                continue
            if method == "flow":
                if anchor_H is None:
                    continue
                T_C_P = pose_from_homography(anchor_H / anchor_H[2, 2])
                if T_C_P is None:
                    continue
                pose, rms = invert(T_C_P), 0.0
            else:
                got = (cache.outline if method == "outline" else cache.markers)[k]
                if got is None:
                    continue
                pose, rms = got
            if cfg.false_pose_detection and (rms > cfg.max_reprojection_px or
                                             motion_gate(pose, cache.t[k], last, last_t, cfg)):
                if status[k] != "rejected":  # the first rejected pose is reported; the next method is tried
                    status[k], poses[k], phase_est[k] = "rejected", pose, METHOD_PHASE[method]
                continue
            phase_est[k] = METHOD_PHASE[method]
            status[k], poses[k] = "ok", pose
            last, last_t, last_method = pose, cache.t[k], method
            near = pose[2, 3] < cfg.touchdown_height_m * 1.5 + cfg.hysteresis_m
            if method != "flow":
                if near and cfg.use_flow:
                    T = invert(pose)
                    anchor_H = np.column_stack([T[:3, 0], T[:3, 1], T[:3, 3]])
                else:
                    anchor_H = None
            break
    return {"status": status, "phase": phase_est, "poses": poses}


def replay_errors(seq, rep: dict) -> dict:
    """The replay as the metrics' per-frame arrays."""
    from hvloc.geometry import tum_from_transform

    n = len(seq)
    est = {"frame": np.arange(n, dtype=float), "t": np.asarray(seq.t, float), "status": rep["status"],
           "phase": rep["phase"], "ms": np.zeros(n)}
    rows = np.array([tum_from_transform(p) if p is not None else [np.nan] * 7 for p in rep["poses"]])
    for i, c in enumerate(("tx", "ty", "tz", "qx", "qy", "qz", "qw")):
        est[c] = rows[:, i]
    return M.frame_errors(seq.columns, est)


def sweep(sequences: list, base_cfg: LocalizerConfig, adjust_heights, touchdown_heights, use_imu: bool = True,
          progress=None) -> dict:
    caches, seconds = [], 0.0
    for seq in sequences:
        c = precompute(seq, use_imu)
        caches.append(c)
        seconds += c.seconds
        if progress:
            progress(len(seq))
    grid = []
    t0 = time.perf_counter()
    for ha in adjust_heights:
        for ht in touchdown_heights:
            if ht >= ha:
                continue
            cfg = base_cfg.model_copy(update={"adjust_height_m": float(ha), "touchdown_height_m": float(ht)})
            fes = [replay_errors(seq, replay(c, cfg)) for seq, c in zip(sequences, caches)]
            fe = M.concat(fes)
            grid.append({"adjust_height_m": float(ha), "touchdown_height_m": float(ht), "all": M.score(fe),
                         **{f"gt:{p}": M.score(fe, fe["phase_gt"] == p) for p in M.PHASES}})
    return {"grid": grid, "precompute_s": seconds, "replay_s": time.perf_counter() - t0, "caches": caches}


def recommend(grid: list, max_pos_err_pct: float = 2.0) -> dict | None:
    """The pair with the highest availability among those with no false accepts and a median
    position error within ``max_pos_err_pct`` % of height (ties: lower RMSE)."""
    ok = [g for g in grid if g["all"].get("false_accepts", 1) == 0
          and (g["all"].get("pos_err_pct_median") or math.inf) <= max_pos_err_pct]
    if not ok:
        return None
    return max(ok, key=lambda g: (round(g["all"]["availability"], 4), -(g["all"].get("pos_err_m_rmse") or math.inf)))


def write_heatmaps(grid: list, path, adjust_heights, touchdown_heights) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    A = sorted(set(adjust_heights))
    T = sorted(set(touchdown_heights))
    fig, ax = plt.subplots(1, 4, figsize=(18, 4))
    panels = [("all", "availability", "availability (%)", 100), ("gt:touchdown", "availability", "touchdown availability (%)", 100),
              ("all", "pos_err_pct_median", "median position error (% h)", 1), ("gt:touchdown", "pos_err_m_rmse", "touchdown RMSE (mm)", 1000)]
    for a, (scope, key, title, scale) in zip(ax, panels):
        Z = np.full((len(A), len(T)), np.nan)
        for g in grid:
            v = g[scope].get(key)
            if v is not None:
                Z[A.index(g["adjust_height_m"]), T.index(g["touchdown_height_m"])] = v * scale
        im = a.imshow(Z, origin="lower", aspect="auto", cmap="viridis")
        a.set_xticks(range(len(T)), [f"{x:g}" for x in T])
        a.set_yticks(range(len(A)), [f"{x:g}" for x in A])
        a.set_xlabel("touchdown height (m)")
        a.set_ylabel("adjustment height (m)")
        a.set_title(title)
        for i in range(len(A)):
            for j in range(len(T)):
                if np.isfinite(Z[i, j]):
                    a.text(j, i, f"{Z[i, j]:.1f}", ha="center", va="center", color="w", fontsize=7)
        fig.colorbar(im, ax=a)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
