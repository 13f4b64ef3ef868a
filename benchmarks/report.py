"""report.md: per-phase tables, per-dataset and per-descent tables, and PNG plots (error against
height and availability per phase per localizer; per descent, the landing as the method sees it)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from . import metrics as M

PHASE_COLORS = {"approaching": "tab:orange", "adjustment": "tab:blue", "touchdown": "tab:green"}
# ground-truth phases are drawn as pale bands behind the data, estimated phases in the full colours
PHASE_PALE = {"approaching": "#fde3c8", "adjustment": "#d2e3f3", "touchdown": "#d5efd5"}
LOCALIZER_STYLES = (("o", "tab:purple"), ("s", "tab:brown"), ("^", "tab:olive"), ("D", "tab:cyan"), ("v", "tab:pink"),
                    ("P", "tab:gray"))  # none of them a phase colour


def _f(v, scale=1.0, fmt="{:.1f}"):
    return "-" if v is None else fmt.format(v * scale)


def phase_table(summary: dict, dataset: str | None = None) -> str:
    """Markdown rows per localizer and ground-truth phase; ``dataset``: that dataset's scopes only."""
    pre = f"{dataset}/" if dataset else ""
    # "in scope": over the frames in touchdown or showing the pad whole or two markers
    lines = ["| localizer | phase (ground truth) | frames | availability | in scope | pos RMSE mm | pos p95 mm | "
             "pos median % h | rot RMSE deg | yaw median deg | false accepts | beyond cov 3 sigma | error / stated sigma | "
             "ms p50 | ms p95 |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for loc, s in summary.items():
        for scope in ["gt:approaching", "gt:adjustment", "gt:touchdown", "all"]:
            m = s.get(pre + scope, {})
            if not m.get("frames"):
                continue
            lines.append("| " + " | ".join([
                loc, scope.replace("gt:", ""), str(m["frames"]), _f(m.get("availability"), 100, "{:.1f} %"),
                _f(m.get("availability_in_scope"), 100, "{:.1f} %"),
                _f(m.get("pos_err_m_rmse"), 1000), _f(m.get("pos_err_m_p95"), 1000),
                _f(m.get("pos_err_pct_median"), 1, "{:.2f}"), _f(m.get("rot_err_deg_rmse"), 1, "{:.2f}"),
                _f(m.get("yaw_err_deg_median"), 1, "{:.2f}"), str(m["false_accepts"] if m.get("false_accepts") is not None else "-"),
                _f(m.get("beyond_cov_3sigma"), 100, "{:.1f} %"), _f(M.metric(m, "pos_cov_scale"), 1, "{:.2f}"),
                _f(m.get("ms_p50"), 1, "{:.1f}"),
                _f(m.get("ms_p95"), 1, "{:.1f}")]) + " |")
    return "\n".join(lines)


def size_table(by_size: dict) -> str:
    """Markdown rows of :func:`benchmarks.metrics.size_scopes`: per the pad's side in the image, its
    frames (the whole pad in view), availability, the error's median (% of the height), the height's
    signed median and the false accepts."""
    lines = ["| pad in the image | frames | availability | pos median % h | height median % h | false accepts |",
             "|---|---|---|---|---|---|"]
    for size, m in by_size.items():
        lines.append("| " + " | ".join([
            size, str(m["frames"]), _f(m.get("availability"), 100, "{:.1f} %"),
            _f(m.get("pos_err_pct_median"), 1, "{:.2f}"), _f(m.get("height_err_pct_median"), 1, "{:+.2f}"),
            str(m["false_accepts"] if m.get("false_accepts") is not None else "-")]) + " |")
    return "\n".join(lines)


def glance_table(summary: dict, datasets: list) -> str:
    """Markdown rows, one per localizer and dataset, the weakest first (availability in scope,
    then false accepts): what a suite of many conditions shows at a glance, each dataset's own
    phase tables below it.  "in scope" is over the frames in touchdown or showing the pad whole or
    two markers; a phase's column is its availability in scope."""
    lines = ["| dataset | localizer | frames | in scope | approaching | adjustment | touchdown | false accepts | "
             "appr. pos median % h | adj. pos RMSE mm | td. pos RMSE mm | beyond cov 3 sigma | longest gap s |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    rows = []
    for loc, s in summary.items():
        for d in datasets:
            a = s.get(f"{d}/all", {})
            if not a.get("frames"):
                continue
            ph = {p: s.get(f"{d}/gt:{p}", {}) for p in M.PHASES}
            key = (loc, a.get("availability_in_scope") if a.get("availability_in_scope") is not None else 2.0,
                   -(a.get("false_accepts") or 0))
            rows.append((key, "| " + " | ".join([
                f"`{d}`", loc, str(a["frames"]), _f(a.get("availability_in_scope"), 100, "{:.1f} %"),
                *(_f(ph[p].get("availability_in_scope") if ph[p].get("frames") else None, 100, "{:.1f} %")
                  for p in M.PHASES),
                str(a["false_accepts"] if a.get("false_accepts") is not None else "-"),
                _f(ph["approaching"].get("pos_err_pct_median"), 1, "{:.2f}"),
                _f(ph["adjustment"].get("pos_err_m_rmse"), 1000), _f(ph["touchdown"].get("pos_err_m_rmse"), 1000),
                _f(a.get("beyond_cov_3sigma"), 100, "{:.1f} %"), _f(a.get("longest_gap_s"), 1, "{:.2f}")]) + " |"))
    order = {loc: i for i, loc in enumerate(summary)}
    rows.sort(key=lambda r: (order[r[0][0]], r[0][1], r[0][2]))
    return "\n".join(lines + [r[1] for r in rows])


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
          "than 10 % of the height or 5 degrees. Availability is the share of frames with `status=ok`. "
          "Beyond cov 3 sigma: the share of `ok` poses whose position error lies beyond what their stated "
          "covariance allows 99.73 % of the time (NEES over 14.16); an honest covariance gives ~0.3 %. "
          "Error / stated sigma: how many times its stated position sigma the bulk of the errors is (the square "
          "root of the median NEES over 2.37, a 3-D Gaussian's): 1 is honest, under 1 states more error than "
          "made, over 1 is too sure.", ""]
    tiers = list(dict.fromkeys(k.split("/", 1)[0][5:] for s in results["summary"].values() for k in s
                               if k.startswith("tier:")))
    if len(tiers) > 1:
        md += ["## Per difficulty tier", "",
               "Each tier pools its datasets' frames; 95 % intervals over descents are in `results.json` (`ci95`).", ""]
        for tier in tiers:
            md += [f"### tier `{tier}`", "", phase_table(results["summary"], f"tier:{tier}"), ""]
    datasets = sorted({d for s in results["summary"].values() for d in s.get("datasets", [])})
    if len(datasets) > 1:
        md += ["## Per dataset", "", "One row per localizer and dataset, each localizer's weakest dataset first (availability "
               "in scope, then false accepts); each dataset's phase table follows.", "", glance_table(results["summary"], datasets), ""]
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
    md += descent_section(out, results, data_root, plots)
    path = out / "report.md"
    path.write_text("\n".join(md) + "\n")
    return path


def _descents(out: Path, results: dict, data_root: Path) -> list:
    """The suite's descents: ``[(title, seq, {localizer: estimates}), ...]``.  A descent rendered
    with several pads (same spec and seed, pad variant swapped) is one descent: the peers' estimates
    stand beside hvloc's.  Shown: the first hvloc localizer and every peer (ablations are in the tables)."""
    from render.dataset import Dataset

    from .run import read_estimates

    setup = results.get("localizer_setup", {})
    hier = [n for n, s in setup.items() if s.get("kind") == "hierarchical"][:1]
    shown = hier + [n for n, s in setup.items() if s.get("kind") != "hierarchical"]
    groups: dict = {}
    for droot in sorted(Path(data_root).iterdir()):
        if not (droot / "manifest.json").exists():
            continue
        for seq in Dataset(droot, verify=False):
            key = np.round(seq.cam2pad[:, :3, 3], 6).tobytes()  # the same flight, whatever the pad
            title, first, ests = groups.setdefault(key, (f"{droot.name.rsplit('-', 1)[0]}/{seq.id}", seq, {}))
            for name in shown:
                p = out / "estimates" / name / droot.name / seq.id / "estimates.csv"
                if p.exists() and name not in ests:
                    ests[name] = read_estimates(p)
    return [(t, s, e) for t, s, e in groups.values() if e]


def descent_section(out: Path, results: dict, data_root: Path, plots: Path) -> list:
    """Per descent: a table (availability, error, false accepts, where the phases switched against
    where the ground truth says they could) and the landing figure (:func:`landing_plot`)."""
    md = ["## Per descent", "",
          "Switch heights are those of accepted poses (estimated phase) beside the ground-truth phase boundaries "
          "(what a perfect detector could see, `render/phase.py`).", "",
          "| descent | localizer | family | frames | availability | pos RMSE mm | false accepts | switches (estimated) "
          "| boundaries (ground truth) |", "|---|---|---|---|---|---|---|---|---|"]
    figures = []
    for title, seq, ests in _descents(out, results, data_root):
        for name, est in ests.items():
            fe = M.frame_errors(seq.columns, est)
            s = M.score(fe)
            sw = "; ".join(f"{a[:4]}.>{b[:4]}. {h:.2f} m" for a, b, h in M.switch_heights(fe)) or "-"
            gb = "; ".join(f"{a[:4]}.>{b[:4]}. {h:.2f} m" for a, b, h in M.gt_boundaries(fe)) or "-"
            md.append(f"| {title} | {name} | {seq.meta.get('family', '-')} | {s['frames']} | "
                      f"{_f(s.get('availability'), 100, '{:.1f} %')} | {_f(s.get('pos_err_m_rmse'), 1000)} | "
                      f"{s.get('false_accepts', '-')} | {sw} | {gb} |")
        name = "landing_" + title.replace("/", "_") + ".png"
        landing_plot(seq, ests, plots / name, f"{title} ({seq.meta.get('family', '')})")
        figures += [f"![{title}](plots/{name})", ""]
    return md + [""] + figures


def landing_plot(seq, ests: dict, path: Path, title: str) -> None:
    """One descent as the method sees it.  Top: height against time, the ground-truth phase as pale
    bands, each accepted pose as a dot in its estimated phase's colour, rejected poses as crosses,
    switches of the estimated phase as dashed lines with their heights; below it the phases as two
    strips (ground truth, estimated; grey: no pose).  Bottom left: the flight seen from above in the
    pad frame, every localizer beside the truth.  Bottom right: position error against height."""
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch, Rectangle

    from hvloc.geometry import transform_from_tum

    t = np.asarray(seq.t, float)
    gt = seq.cam2pad
    h_gt = gt[:, 2, 3]
    phase_gt = np.asarray(seq.columns["phase_gt"])
    names = list(ests)
    main = ests[names[0]]
    fig = plt.figure(figsize=(14, 9))
    gs = fig.add_gridspec(3, 2, height_ratios=[3, 0.6, 3.4], hspace=0.35, wspace=0.22)
    ax_h = fig.add_subplot(gs[0, :])
    ax_s = fig.add_subplot(gs[1, :], sharex=ax_h)
    ax_xy = fig.add_subplot(gs[2, 0])
    ax_e = fig.add_subplot(gs[2, 1])
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    edges = np.concatenate([t - dt / 2, [t[-1] + dt / 2]])
    for k, p in enumerate(phase_gt):  # ground truth: pale bands
        if p in PHASE_PALE:
            ax_h.axvspan(edges[k], edges[k + 1], color=PHASE_PALE[p], lw=0)
    ax_h.plot(t, h_gt, "k-", lw=1.2, label="ground truth")
    keys = ("tx", "ty", "tz", "qx", "qy", "qz", "qw")

    def poses(est, status):
        sel = np.array([s == status for s in est["status"]])
        P = np.array([transform_from_tum([float(est[c][i]) for c in keys])[:3, 3] if sel[i] else [np.nan] * 3
                      for i in range(len(t))])
        return sel, P

    ok, P_main = poses(main, "ok")
    rej, P_rej = poses(main, "rejected")
    phase_est = np.asarray(main["phase"])
    for p in M.PHASES:
        sel = ok & (phase_est == p)
        ax_h.scatter(t[sel], P_main[sel, 2], s=9, c=PHASE_COLORS[p], zorder=3)
    if rej.any():
        ax_h.scatter(t[rej], P_rej[rej, 2], s=22, marker="x", c="crimson", zorder=4, label="rejected")
    prev = None
    low = ax_h.get_xaxis_transform()  # x in data, y in axes fractions
    for k in np.nonzero(ok)[0]:  # switches of the estimated phase, at accepted poses
        if prev is not None and phase_est[k] != prev:
            ax_h.axvline(t[k], color=PHASE_COLORS[phase_est[k]], ls="--", lw=1)
            ax_h.text(t[k], 0.03, f" {h_gt[k]:.2f} m", transform=low, rotation=90, va="bottom", ha="right",
                      fontsize=8, color=PHASE_COLORS[phase_est[k]])
        prev = phase_est[k]
    ax_h.set_ylabel("height above pad (m)")
    fig.suptitle(f"{title}: {names[0]}", fontsize=12, y=0.995)
    ax_h.grid(True, alpha=0.3)
    handles = [plt.Line2D([], [], color="k", lw=1.2, label="ground truth height")]
    handles += [Patch(color=PHASE_PALE[p], label=f"{p} (ground truth)") for p in M.PHASES]
    handles += [plt.Line2D([], [], marker="o", ls="", color=PHASE_COLORS[p], label=f"{p} (estimated)") for p in M.PHASES]
    handles += [plt.Line2D([], [], marker="x", ls="", color="crimson", label="rejected pose")]
    handles += [plt.Line2D([], [], color="grey", ls="--", label="estimated switch (height)")]
    ax_h.legend(handles=handles, fontsize=7, ncol=4, loc="lower left", bbox_to_anchor=(0.0, 1.01), frameon=False)
    # the phase strips
    for row, (lab, ph, have) in enumerate((("ground truth", phase_gt, np.ones(len(t), bool)),
                                           (f"estimated ({names[0]})", phase_est, ok))):
        for k in range(len(t)):
            colour = (PHASE_COLORS.get(ph[k], "lightgrey") if row else PHASE_PALE.get(ph[k], "lightgrey")) \
                if have[k] else "lightgrey"
            ax_s.add_patch(Rectangle((edges[k], 1 - row), edges[k + 1] - edges[k], 0.9, color=colour, lw=0))
    ax_s.set_ylim(0, 2)
    ax_s.set_yticks([1.45, 0.45], ["ground truth", "estimated"], fontsize=8)
    ax_s.set_xlim(edges[0], edges[-1])
    ax_s.set_xlabel("t (s)   (grey: no pose)")
    # from above, in the pad frame
    half = seq.pad.geometry.side_m / 2
    ax_xy.add_patch(Rectangle((-half, -half), 2 * half, 2 * half, fill=False, color="magenta", lw=1.5, label="pad"))
    ax_xy.plot(gt[:, 0, 3], gt[:, 1, 3], "k-", lw=1, label="ground truth")
    for i, name in enumerate(names):
        marker, colour = LOCALIZER_STYLES[i % len(LOCALIZER_STYLES)]
        o, P = poses(ests[name], "ok")
        ax_xy.scatter(P[o, 0], P[o, 1], s=8, marker=marker, c=colour, label=f"{name} ({100 * o.mean():.0f} % ok)",
                      alpha=0.7)
        fe = M.frame_errors(seq.columns, ests[name])
        sel = o & np.isfinite(fe["pos_err_m"]) & (fe["pos_err_m"] > 0)
        ax_e.scatter(fe["height_m"][sel], 1000 * fe["pos_err_m"][sel], s=8, marker=marker, c=colour, label=name,
                     alpha=0.7)
    ax_xy.set_aspect("equal", adjustable="datalim")
    ax_xy.set_xlabel("x in the pad frame (m)")
    ax_xy.set_ylabel("y in the pad frame (m)")
    ax_xy.set_title("camera position from above", fontsize=10)
    ax_xy.grid(True, alpha=0.3)
    ax_xy.legend(fontsize=7)
    if ax_e.collections:
        from matplotlib.ticker import NullFormatter, ScalarFormatter

        ax_e.set_xscale("log")
        ax_e.set_yscale("log")
        for axis in (ax_e.xaxis, ax_e.yaxis):
            axis.set_major_formatter(ScalarFormatter())
            axis.set_minor_formatter(NullFormatter())
        ax_e.legend(fontsize=7)
    ax_e.set_xlabel("height above pad (m)")
    ax_e.set_ylabel("position error (mm)")
    ax_e.set_title("accepted poses: error against height", fontsize=10)
    ax_e.grid(True, which="both", alpha=0.3)
    fig.savefig(path, dpi=90, bbox_inches="tight")
    plt.close(fig)
