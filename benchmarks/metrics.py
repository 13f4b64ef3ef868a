"""Scores of a localizer on labelled sequences: per ground-truth phase, per estimated phase and
over the suite.  No trajectory alignment: poses are in the pad frame and must be right as they are.

Units in names: ``_m`` metres, ``_deg`` degrees (reports only), ``_pct`` percent of height,
``_ms`` milliseconds, ``_s`` seconds.
"""
from __future__ import annotations

import math

import numpy as np

from hvloc.geometry import heading_turn, rotation_angle, transform_from_tum

PHASES = ("approaching", "adjustment", "touchdown")
FALSE_ACCEPT_REL = 0.10   # an accepted pose off by more than 10 % of height ...
FALSE_ACCEPT_DEG = 5.0    # ... or 5 degrees is a false accept
# a pose's position error beyond what its covariance allows 99.73 % of the time (3 sigma in one
# dimension): the squared Mahalanobis distance over 3 degrees of freedom
NEES_3SIGMA = 14.156
NEES_MEDIAN = 2.366  # the median of chi-squared with 3 degrees of freedom: an honest covariance's median NEES


def cov_sigma_scale(nees_median: float | None) -> float | None:
    """How many times its stated position sigma a localizer's errors are, read from the median NEES
    of its accepted poses: 1 for an honest covariance, 0.25 for one that states four times the error
    it makes (a filter fusing it would trust it 16 times too little), 3 for one three times too sure.
    The share beyond 3 sigma catches the few poses far outside their covariance; this, the bulk."""
    return None if nees_median is None else math.sqrt(nees_median / NEES_MEDIAN)


def metric(scope: dict, key: str):
    """``scope[key]``, or for ``pos_cov_scale`` its value from the median NEES where a results file
    made before it was scored holds only that."""
    v = scope.get(key)
    if v is None and key == "pos_cov_scale":
        v = cov_sigma_scale(scope.get("pos_nees_median"))
    return v


def frame_errors(gt_cols: dict, est_cols: dict) -> dict:
    """Per-frame arrays: position error (m), orientation error (deg), yaw error (deg), height (m)."""
    n = len(gt_cols["frame"])
    if len(est_cols["frame"]) != n:
        raise ValueError(f"estimates have {len(est_cols['frame'])} frames, labels {n}")
    pos_err = np.full(n, np.nan)
    z_err = np.full(n, np.nan)
    rot_err = np.full(n, np.nan)
    yaw_err = np.full(n, np.nan)
    nees = np.full(n, np.nan)
    keys = ("tx", "ty", "tz", "qx", "qy", "qz", "qw")
    cov_cols = [f"cov_{a}_{b}" for a, b in (("x", "x"), ("x", "y"), ("x", "z"), ("y", "y"), ("y", "z"), ("z", "z"))]
    has_cov = all(c in est_cols for c in cov_cols)
    has = np.array([s in ("ok", "rejected") for s in est_cols["status"]])
    for k in np.nonzero(has)[0]:
        E = transform_from_tum([est_cols[c][k] for c in keys])
        G = transform_from_tum([gt_cols[c][k] for c in keys])
        if not np.all(np.isfinite(E)):
            continue
        d = E[:3, 3] - G[:3, 3]
        pos_err[k] = float(np.linalg.norm(d))
        z_err[k] = float(d[2])
        if has_cov:
            xx, xy, xz, yy, yz, zz = (float(est_cols[c][k]) for c in cov_cols)
            C = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
            if np.all(np.isfinite(C)) and np.all(np.linalg.eigvalsh(C) > 0):
                nees[k] = float(d @ np.linalg.solve(C, d))
        rot_err[k] = math.degrees(rotation_angle(E[:3, :3], G[:3, :3]))
        yaw_err[k] = abs(math.degrees(heading_turn(G[:3, :3], E[:3, :3])))
    return {"pos_err_m": pos_err, "z_err_m": z_err, "rot_err_deg": rot_err, "yaw_err_deg": yaw_err,
            "height_m": np.asarray(gt_cols["tz"], float), "t_s": np.asarray(gt_cols["t"], float),
            "status": np.asarray(est_cols["status"]), "phase_est": np.asarray(est_cols["phase"]),
            "phase_gt": np.asarray(gt_cols["phase_gt"]), "ms": np.asarray(est_cols["ms"], float),
            "pos_nees": nees, "in_scope": in_scope(gt_cols), "pad_px": pad_px(gt_cols)}


# the pad's side in the image (px) at which ``hvloc bench score`` splits its frames: where a camera's
# availability is set by how many pixels the pad spans (a 1 m pad is 14 px from 20 m under a 120 degree
# lens at 960x540; hvloc does not try under 16 px), not by the conditions
PAD_PX_BINS = (16.0, 20.0, 30.0, 45.0, 64.0, 140.0)


def pad_px(gt_cols: dict) -> np.ndarray:
    """(N,) the pad's mean side in the image (px) from its labelled corners where all four are in
    view (``c0u`` ... ``c3_visible``); NaN elsewhere, and for a dataset without those columns."""
    n = len(gt_cols["frame"])
    cols = [f"c{i}{a}" for i in range(4) for a in "uv"] + [f"c{i}_visible" for i in range(4)]
    if not all(c in gt_cols for c in cols):
        return np.full(n, np.nan)
    c = np.stack([np.column_stack([np.asarray(gt_cols[f"c{i}u"], float), np.asarray(gt_cols[f"c{i}v"], float)])
                  for i in range(4)], axis=1)  # (N, 4, 2)
    seen = np.all([np.asarray(gt_cols[f"c{i}_visible"], float) > 0.5 for i in range(4)], axis=0)
    side = np.linalg.norm(c - np.roll(c, 1, axis=1), axis=2).mean(axis=1)
    return np.where(seen & np.isfinite(side), side, np.nan)


def size_scopes(fe: dict) -> dict:
    """``{"16-20 px": metrics, ...}``: the metrics over the frames whose whole pad spans so many
    pixels in the image (:data:`PAD_PX_BINS`; labelled corners), bins without frames left out."""
    px = fe["pad_px"]
    edges = (0.0,) + PAD_PX_BINS + (math.inf,)
    out = {}
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (px >= lo) & (px < hi)
        if m.any():
            name = f"under {hi:g} px" if lo == 0 else f"{lo:g} px and more" if math.isinf(hi) else f"{lo:g}-{hi:g} px"
            out[name] = score(fe, m)
    return out


def in_scope(gt_cols: dict) -> np.ndarray:
    """(N,) the frames a localizer should pose: in touchdown, or with the pad wholly in view, or at
    least two of its markers (what a pose can be made from).  Datasets without the visibility
    columns: every frame."""
    n = len(gt_cols["frame"])
    if not all(c in gt_cols for c in ("pad_fully_visible", "markers_visible")):
        return np.ones(n, bool)
    full = np.asarray(gt_cols["pad_fully_visible"], float) > 0.5
    markers = np.asarray(gt_cols["markers_visible"], float) >= 2
    return (np.asarray(gt_cols["phase_gt"]) == "touchdown") | full | markers


def _stats(x: np.ndarray, prefix: str) -> dict:
    x = x[np.isfinite(x)]
    if x.size == 0:
        return {f"{prefix}_rmse": None, f"{prefix}_median": None, f"{prefix}_p95": None}
    return {f"{prefix}_rmse": float(np.sqrt(np.mean(x * x))), f"{prefix}_median": float(np.median(x)),
            f"{prefix}_p95": float(np.percentile(x, 95))}


def longest_gap_s(t: np.ndarray, ok: np.ndarray) -> float:
    """Longest time without an accepted pose: between consecutive ok frames, and from the first
    frame / to the last frame (the whole span when nothing was ok)."""
    if t.size == 0:
        return 0.0
    marks = np.concatenate([[t[0]], t[ok], [t[-1]]])
    return float(np.max(np.diff(marks)))


def wrong_poses(fe: dict) -> np.ndarray:
    """(N,) the frames whose pose, were it accepted, would be a false accept: off by more than
    :data:`FALSE_ACCEPT_REL` of the height or :data:`FALSE_ACCEPT_DEG` (NaN errors are not)."""
    return (fe["pos_err_m"] > FALSE_ACCEPT_REL * fe["height_m"]) | (fe["rot_err_deg"] > FALSE_ACCEPT_DEG)


def score(fe: dict, mask: np.ndarray | None = None) -> dict:
    """All metrics over the frames in ``mask`` (default all)."""
    m = np.ones_like(fe["pos_err_m"], bool) if mask is None else mask
    n = int(m.sum())
    out = {"frames": n}
    if n == 0:
        return out
    ok = (fe["status"] == "ok") & m
    rej = (fe["status"] == "rejected") & m
    h = fe["height_m"]
    pe, re = fe["pos_err_m"], fe["rot_err_deg"]
    wrong = wrong_poses(fe)
    out["availability"] = float(ok.sum() / n)
    # in scope: touchdown, or the pad whole or two markers in view (frames where a pose can be made)
    scope = fe["in_scope"] & m
    out["availability_in_scope"] = float((ok & scope).sum() / scope.sum()) if scope.any() else None
    out["longest_gap_s"] = longest_gap_s(fe["t_s"][m], ok[m])
    out.update(_stats(pe[ok], "pos_err_m"))
    out.update(_stats(100.0 * pe[ok] / h[ok], "pos_err_pct"))
    # the height's bias: the signed median of its error (% of the height; a far outline's step edges
    # read the pad too large or too small, which no spread of the error shows)
    z = 100.0 * fe["z_err_m"][ok] / h[ok]
    z = z[np.isfinite(z)]
    out["height_err_pct_median"] = float(np.median(z)) if z.size else None
    out.update(_stats(re[ok], "rot_err_deg"))
    out.update(_stats(fe["yaw_err_deg"][ok], "yaw_err_deg"))
    out["false_accepts"] = int((ok & wrong).sum())
    # is the stated covariance honest: the share of accepted poses (with one) whose position error
    # lies beyond its 3 sigma (an honest one: 0.27 %), and the median NEES (an honest one: ~2.4)
    nees = fe["pos_nees"][ok] if "pos_nees" in fe else np.array([])
    nees = nees[np.isfinite(nees)]
    out["beyond_cov_3sigma"] = float(np.mean(nees > NEES_3SIGMA)) if nees.size else None
    out["pos_nees_median"] = float(np.median(nees)) if nees.size else None
    out["pos_cov_scale"] = cov_sigma_scale(out["pos_nees_median"])
    out["rejections_right"] = int((rej & wrong).sum())
    out["rejections_wrong"] = int((rej & ~wrong).sum())
    out["wrong_phase_frames"] = int((ok & (fe["phase_est"] != fe["phase_gt"])).sum())
    ms = fe["ms"][m]
    out["ms_p50"] = float(np.percentile(ms, 50))
    out["ms_p95"] = float(np.percentile(ms, 95))
    return out


def switch_heights(fe: dict) -> list:
    """(from, to, height) each time the estimated phase of accepted poses changed."""
    out = []
    prev = None
    for st, ph, h in zip(fe["status"], fe["phase_est"], fe["height_m"]):
        if st != "ok":
            continue
        if prev is not None and ph != prev:
            out.append((prev, str(ph), float(h)))
        prev = str(ph)
    return out


def gt_boundaries(fe: dict) -> list:
    out = []
    prev = None
    for ph, h in zip(fe["phase_gt"], fe["height_m"]):
        if prev is not None and ph != prev:
            out.append((prev, str(ph), float(h)))
        prev = str(ph)
    return out


def phase_scopes(fe: dict) -> dict:
    """``{"all": ..., "gt:<phase>": ...}``: the metrics over all frames and per ground-truth phase."""
    return {"all": score(fe), **{f"gt:{p}": score(fe, fe["phase_gt"] == p) for p in PHASES}}


def score_sequence(fe: dict) -> dict:
    res = {"all": score(fe)}
    for p in PHASES:
        res[f"gt:{p}"] = score(fe, fe["phase_gt"] == p)
        res[f"est:{p}"] = score(fe, (fe["phase_est"] == p) & (fe["status"] != "lost"))
    res["switches"] = switch_heights(fe)
    res["gt_boundaries"] = gt_boundaries(fe)
    # touchdown drift: position error at contact (last frame)
    last = len(fe["pos_err_m"]) - 1
    res["contact_pos_err_m"] = float(fe["pos_err_m"][last]) if fe["status"][last] == "ok" else None
    return res


def concat(fes: list) -> dict:
    return {k: np.concatenate([f[k] for f in fes]) for k in fes[0]}


# ----------------------------------------------------------------------------- confidence intervals

CI_METRICS = ("availability", "pos_err_m_rmse", "rot_err_deg_rmse", "false_accepts")


def sufficient_stats(fe: dict, mask: np.ndarray | None = None) -> np.ndarray:
    """``[frames, ok, sum of squared position errors, sum of squared rotation errors, false accepts]``
    of one sequence's frames in ``mask``: what :data:`CI_METRICS` over several sequences add up from."""
    m = np.ones_like(fe["pos_err_m"], bool) if mask is None else mask
    ok = (fe["status"] == "ok") & m
    pe, re, h = fe["pos_err_m"][ok], fe["rot_err_deg"][ok], fe["height_m"][ok]
    wrong = (pe > FALSE_ACCEPT_REL * h) | (re > FALSE_ACCEPT_DEG)
    return np.array([m.sum(), ok.sum(), float(np.sum(pe * pe)), float(np.sum(re * re)), wrong.sum()], np.float64)


def metrics_from_stats(S: np.ndarray) -> dict:
    """:data:`CI_METRICS` from summed sufficient statistics ``(..., 5)`` (arrays broadcast)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return {"availability": S[..., 1] / S[..., 0], "pos_err_m_rmse": np.sqrt(S[..., 2] / S[..., 1]),
                "rot_err_deg_rmse": np.sqrt(S[..., 3] / S[..., 1]), "false_accepts": S[..., 4]}


def bootstrap_ci(stats: np.ndarray, level: float = 0.95, n_boot: int = 4000, seed: int = 0) -> dict:
    """Percentile bootstrap over descents: ``stats`` ``(n_sequences, 5)`` rows of
    :func:`sufficient_stats`; sequences are resampled with replacement (a descent is the unit that
    varies: its trajectory, scene and light), each metric recomputed from the resampled sums.
    ``{metric: [lo, hi]}`` (``None`` where undefined); deterministic for a given ``seed``."""
    stats = np.asarray(stats, np.float64).reshape(-1, 5)
    n = len(stats)
    if n == 0:
        return {k: None for k in CI_METRICS}
    counts = np.random.default_rng(seed).multinomial(n, np.full(n, 1.0 / n), size=n_boot)
    boot = metrics_from_stats(counts @ stats)
    a = (1.0 - level) / 2.0
    out = {}
    for k, v in boot.items():
        v = v[np.isfinite(v)]
        out[k] = [float(np.quantile(v, a)), float(np.quantile(v, 1 - a))] if len(v) > n_boot // 2 else None
    return out
