"""report.md with per-phase tables and PNG plots (position/attitude against time coloured by
phase with ground truth, error against height, availability per phase, phase timeline)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from . import metrics as M

PHASE_COLORS = {"approaching": "tab:orange", "adjustment": "tab:blue", "touchdown": "tab:green"}


def _f(v, scale=1.0, fmt="{:.1f}"):
    return "-" if v is None else fmt.format(v * scale)


def phase_table(summary: dict, dataset: str | None = None) -> str:
    """Markdown rows per localizer and ground-truth phase; ``dataset``: that dataset's scopes only."""
    pre = f"{dataset}/" if dataset else ""
    lines = ["| localizer | phase (ground truth) | frames | availability | pos RMSE mm | pos p95 mm | "
             "pos median % h | rot RMSE deg | yaw median deg | false accepts | ms p50 | ms p95 |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for loc, s in summary.items():
        for scope in ["gt:approaching", "gt:adjustment", "gt:touchdown", "all"]:
            m = s.get(pre + scope, {})
            if not m.get("frames"):
                continue
            lines.append("| " + " | ".join([
                loc, scope.replace("gt:", ""), str(m["frames"]), _f(m.get("availability"), 100, "{:.1f} %"),
                _f(m.get("pos_err_m_rmse"), 1000), _f(m.get("pos_err_m_p95"), 1000),
                _f(m.get("pos_err_pct_median"), 1, "{:.2f}"), _f(m.get("rot_err_deg_rmse"), 1, "{:.2f}"),
                _f(m.get("yaw_err_deg_median"), 1, "{:.2f}"), str(m.get("false_accepts", "-")),
                _f(m.get("ms_p50"), 1, "{:.1f}"), _f(m.get("ms_p95"), 1, "{:.1f}")]) + " |")
    return "\n".join(lines)


def write_report(out: Path, results: dict, fes_by_loc: dict, data_root: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    plots = out / "plots"
    plots.mkdir(exist_ok=True)
    md = [f"# Benchmark `{results['suite']}`", "",
          f"commit `{results['provenance'].get('commit')}`, {results['provenance']['machine']['platform']}, "
          f"{results['provenance']['date']}", "", "## Per landing phase", "", phase_table(results["summary"]), "",
          "Position errors are in the pad frame, without alignment. A false accept is an `ok` pose off by more "
          "than 10 % of the height or 5 degrees. Availability is the share of frames with `status=ok`.", ""]
    datasets = sorted({d for s in results["summary"].values() for d in s.get("datasets", [])})
    if len(datasets) > 1:
        md += ["## Per dataset", ""]
        for d in datasets:
            md += [f"### `{d}`", "", phase_table(results["summary"], d), ""]
    # error vs height and availability per phase, one figure per localizer
    for loc, fes in fes_by_loc.items():
        fe = M.concat(fes)
        fig, ax = plt.subplots(1, 3, figsize=(15, 4))
        ok = fe["status"] == "ok"
        for p in M.PHASES:
            sel = ok & (fe["phase_est"] == p)
            ax[0].scatter(fe["height_m"][sel], 1000 * fe["pos_err_m"][sel], s=3, c=PHASE_COLORS[p], label=p)
            ax[1].scatter(fe["height_m"][sel], fe["rot_err_deg"][sel], s=3, c=PHASE_COLORS[p], label=p)
        for a, lab, err in ((ax[0], "position error (mm)", fe["pos_err_m"]), (ax[1], "orientation error (deg)",
                                                                            fe["rot_err_deg"])):
            if np.any(ok & (fe["height_m"] > 0) & (err > 0)):  # log axes need a positive value (a localizer
                a.set_xscale("log")                             # with no pose at all has none)
                a.set_yscale("log")
            a.set_xlabel("height above pad (m)")
            a.set_ylabel(lab)
            a.grid(True, which="both", alpha=0.3)
            a.legend(markerscale=3)
        av = [float(np.mean(ok[fe["phase_gt"] == p])) if np.any(fe["phase_gt"] == p) else 0 for p in M.PHASES]
        ax[2].bar(M.PHASES, [100 * a for a in av], color=[PHASE_COLORS[p] for p in M.PHASES])
        ax[2].set_ylabel("availability (%)")
        ax[2].set_ylim(0, 105)
        ax[2].set_title("availability per ground-truth phase")
        fig.suptitle(f"{loc}: error against height")
        fig.tight_layout()
        name = f"{loc}_error_vs_height.png"
        fig.savefig(plots / name, dpi=90)
        plt.close(fig)
        md += [f"## {loc}", "", f"![error vs height](plots/{name})", ""]
    # per-sequence trajectories (first localizer, each dataset sequence)
    from render.dataset import Dataset

    from .run import read_estimates

    first = next(iter(fes_by_loc))
    for droot in sorted(Path(data_root).iterdir()):
        if not (droot / "manifest.json").exists():
            continue
        ds = Dataset(droot)
        for seq in ds:
            est_path = out / "estimates" / first / droot.name / seq.id / "estimates.csv"
            if not est_path.exists():
                continue
            est = read_estimates(est_path)
            name = f"{first}_{droot.name}_{seq.id}_trajectory.png"
            trajectory_plot(seq, est, plots / name, f"{first} on {droot.name}/{seq.id} ({seq.meta.get('family')})")
            md += [f"![trajectory](plots/{name})", ""]
    path = out / "report.md"
    path.write_text("\n".join(md) + "\n")
    return path


def trajectory_plot(seq, est: dict, path: Path, title: str) -> None:
    import matplotlib.pyplot as plt

    from hvloc.geometry import transform_from_tum

    t = seq.t
    gt = seq.cam2pad
    keys = ("tx", "ty", "tz", "qx", "qy", "qz", "qw")
    ok = np.array([s == "ok" for s in est["status"]])

    def rpy(T):
        # roll in [0, 360): a downward camera sits near 180, where (-180, 180] would wrap
        R = T[:3, :3]
        return np.degrees([np.arctan2(R[2, 1], R[2, 2]) % (2 * np.pi), -np.arcsin(np.clip(R[2, 0], -1, 1)),
                           np.arctan2(R[1, 0], R[0, 0])])

    E = [transform_from_tum([est[k][i] for k in keys]) if ok[i] else None for i in range(len(t))]
    fig, ax = plt.subplots(2, 3, figsize=(15, 6), sharex=True)
    for j, lab in enumerate(("x (m)", "y (m)", "z (m)")):
        ax[0, j].plot(t, gt[:, j, 3], "k-", lw=1, label="ground truth")
        for p in M.PHASES:
            sel = ok & (est["phase"] == p)
            ax[0, j].scatter(t[sel], [E[i][j, 3] for i in np.nonzero(sel)[0]], s=4, c=PHASE_COLORS[p], label=p)
        ax[0, j].set_ylabel(lab)
    g_rpy = np.array([rpy(T) for T in gt])
    for j, lab in enumerate(("roll (deg)", "pitch (deg)", "yaw (deg)")):
        ax[1, j].plot(t, g_rpy[:, j], "k-", lw=1)
        for p in M.PHASES:
            sel = ok & (est["phase"] == p)
            if sel.any():
                ax[1, j].scatter(t[sel], [rpy(E[i])[j] for i in np.nonzero(sel)[0]], s=4, c=PHASE_COLORS[p])
        ax[1, j].set_ylabel(lab)
        ax[1, j].set_xlabel("t (s)")
    ax[0, 0].legend(fontsize=7, markerscale=3)
    fig.suptitle(title + " (orientation of T_P_C as roll/pitch/yaw about the pad axes)")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
