"""Switch-height sweeps that tell the truth: every grid point is a live run.

A replay of cached per-frame outputs cannot equal the live localizer: what the localizer computes on
a frame depends on its state (the region it searches, the prior that names the outline's corners,
the keyframe and tracks of the flow tracker, the gates' running vision-IMU offset).  So the sweep
runs the live localizer itself once per grid point, all of them side by side over each sequence,
sharing one :class:`hvloc.work.ImageWork`: the image work (segmentation, marker search, corner
refinement, Harris, Lucas-Kanade) is remembered per frame under keys that name everything it
depends on, so grid points in the same state ask the same question and pay for it once, and grid
points whose state differs compute their own answer.  Every grid point's estimates are exactly
those of a plain run at its thresholds (``run_sweep`` checks this at the base thresholds and at the
recommended ones); the cost is that of the work the grid points do not share.
"""
from __future__ import annotations

import math

import numpy as np

from hvloc.config import LocalizerConfig



def grid_configs(base_cfg: LocalizerConfig, adjust_heights, touchdown_heights) -> list:
    """``[(adjust_height_m, touchdown_height_m, config), ...]`` for every pair with the touchdown
    height below the adjustment height, in the order given."""
    out = []
    for ha in adjust_heights:
        for ht in touchdown_heights:
            if ht < ha:
                cfg = LocalizerConfig.model_validate({**base_cfg.model_dump(), "adjust_height_m": float(ha),
                                                      "touchdown_height_m": float(ht)})
                out.append((float(ha), float(ht), cfg))
    return out


def point_name(ha: float, ht: float) -> str:
    return f"a{ha:g}_t{ht:g}"


def frames_differing(a: dict, b: dict) -> int:
    """How many frames two read ``estimates.csv`` differ in (status, phase, method or pose; the
    time spent is ignored)."""
    n = len(a["frame"])
    if len(b["frame"]) != n:
        return max(n, len(b["frame"]))
    diff = np.zeros(n, bool)
    for c in ("status", "phase", "method"):
        diff |= np.asarray(a[c]) != np.asarray(b[c])
    for c in ("tx", "ty", "tz", "qx", "qy", "qz", "qw"):
        x, y = np.asarray(a[c], float), np.asarray(b[c], float)
        diff |= ~((x == y) | (np.isnan(x) & np.isnan(y)))
    return int(diff.sum())


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
