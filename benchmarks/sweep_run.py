"""``hvloc bench sweep``: every grid point a live run, side by side (benchmarks/sweep.py), then the
checks that it told the truth: a plain run at the base thresholds and at the recommended ones, each
compared frame by frame with the grid's."""
from __future__ import annotations

import json
import time
from pathlib import Path

from pad_design.errors import InputError, progress_bar


def _run_setups(droots_seqs: list, setups: list, names: list, est_root: Path, workers: int, share: bool,
                label: str, quiet: bool) -> float:
    """Localize every (dataset, sequence) with every setup; estimates under ``est_root/<name>/``.
    Returns the wall time."""
    from render.executor import run_units

    from .suite import _localize_unit

    total = sum(n for _, _, n in droots_seqs)
    bar = progress_bar(not quiet, total, label)
    jobs = [(str(droot), sid, setups, [str(est_root / name / droot.name / sid) for name in names], True, share)
            for droot, sid, _ in sorted(droots_seqs, key=lambda x: -x[2])]  # longest first
    t0 = time.perf_counter()
    for _ in run_units(_localize_unit, jobs, workers, progress=bar.update if bar else None):
        pass
    if bar:
        bar.close()
    return time.perf_counter() - t0


def run_sweep(a) -> int:
    from render.dataset import Dataset, atomic_write_text
    from render.generate import generate

    from . import metrics as M
    from .run import read_estimates
    from .suite import _clean, load_suite, provenance, runs_on
    from .sweep import frames_differing, grid_configs, point_name, recommend, write_heatmaps

    suite, specs, configs, suite_hash = load_suite(a.suite)
    if any(h <= 0 for h in a.adjust_heights + a.touchdown_heights):
        raise InputError("--adjust-heights/--touchdown-heights: heights must be positive")
    # the suite's first hvloc localizer: its switching heights are what the sweep varies
    hier = [(l, c) for l, c in configs if l.kind == "hierarchical"]
    if not hier:
        raise InputError(f"{a.suite}: no hierarchical localizer to sweep (peers have no switching heights)")
    loc, base_cfg = hier[0]
    points = grid_configs(base_cfg, a.adjust_heights, a.touchdown_heights)
    if not points:
        raise InputError("--touchdown-heights: none is below any of --adjust-heights")
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    names = [point_name(ha, ht) for ha, ht, _ in points]
    cfgs = [c for _, _, c in points]
    base_name = next((n for n, c in zip(names, cfgs) if c == base_cfg), None)
    if base_name is None:  # the base thresholds ride along, for the check against a plain run
        names.append("base")
        cfgs.append(base_cfg)
        base_name = "base"
    runs, labels = [], []  # (dataset root, sequence id, frames); each sequence's frames.csv columns, read once
    for spec in [s for s in specs if runs_on(loc, s)]:
        droot = out / "datasets" / f"{spec.name}-{spec.sha256()[:10]}"
        generate(spec, droot, workers=a.workers, show_progress=not a.quiet)
        for seq in Dataset(droot):
            runs.append((droot, seq.id, len(seq)))
            labels.append(seq.columns)
    setups = [(c.model_dump(), loc.use_imu, "hierarchical", False, loc.ahrs_error_scale) for c in cfgs]
    sweep_s = _run_setups(runs, setups, names, out / "estimates", a.workers, True,
                          f"sweep x{len(setups)}", a.quiet)

    def scored(root: Path, name: str) -> tuple:
        fes, ests = [], []
        for (droot, sid, _), cols in zip(runs, labels):
            est = read_estimates(root / name / droot.name / sid / "estimates.csv")
            ests.append(est)
            fes.append(M.frame_errors(cols, est))
        return M.phase_scopes(M.concat(fes)), ests

    grid, ests_by_name = [], {}
    for (ha, ht, _), name in zip(points, names):
        s, ests_by_name[name] = scored(out / "estimates", name)
        grid.append({"adjust_height_m": ha, "touchdown_height_m": ht, "name": name, **s})
    if base_name == "base":
        ests_by_name["base"] = scored(out / "estimates", "base")[1]

    def check(name: str, cfg) -> tuple:
        """A plain run (no shared work) at ``cfg``, compared frame by frame with the grid's run."""
        live_s = _run_setups(runs, [(cfg.model_dump(), loc.use_imu, "hierarchical", False, loc.ahrs_error_scale)], [name],
                             out / "live", a.workers, False, f"live {name}", a.quiet)
        live_score, live_ests = scored(out / "live", name)
        differ = sum(frames_differing(x, y) for x, y in zip(live_ests, ests_by_name[name]))
        return {"name": name, "adjust_height_m": cfg.adjust_height_m, "touchdown_height_m": cfg.touchdown_height_m,
                "live": live_score["all"], "frames_differing": differ,
                "frames": sum(n for _, _, n in runs)}, live_s

    base_check, live_s = check(base_name, base_cfg)
    rec = recommend(grid, a.max_pos_err_pct)
    rec_check = None
    if rec is not None:
        rec_check = base_check if rec["name"] == base_name else check(rec["name"], cfgs[names.index(rec["name"])])[0]
    write_heatmaps(grid, out / "sweep_heatmaps.png", a.adjust_heights, a.touchdown_heights)
    doc = {"schema": "hvloc-sweep/2", "suite": suite.name, "suite_sha256": suite_hash, "provenance": provenance(),
           "base_localizer": loc.name, "grid": grid, "recommended": rec, "bound_pos_err_pct": a.max_pos_err_pct,
           "workers": a.workers,
           "cost_s": {"sweep": sweep_s, "one_plain_run": live_s, "grid_points": len(points),
                      "sweep_over_plain_run": sweep_s / max(live_s, 1e-9)},
           "check_at_base_thresholds": base_check, "check_at_recommended": rec_check}
    atomic_write_text(out / "sweep.json", json.dumps(_clean(doc), indent=1) + "\n")
    lines = ["| adjust h (m) | touchdown h (m) | availability | appr. | adj. | td. | pos median % h | td. RMSE mm | false accepts |",
             "|---|---|---|---|---|---|---|---|---|"]
    for g in grid:
        f = lambda s, k, sc=100.0: "-" if g[s].get(k) is None else f"{g[s][k] * sc:.1f}"  # noqa: E731
        lines.append(f"| {g['adjust_height_m']:g} | {g['touchdown_height_m']:g} | {f('all', 'availability')} % | "
                     f"{f('gt:approaching', 'availability')} | {f('gt:adjustment', 'availability')} | "
                     f"{f('gt:touchdown', 'availability')} | {f('all', 'pos_err_pct_median', 1.0)} | "
                     f"{f('gt:touchdown', 'pos_err_m_rmse', 1000.0)} | {g['all'].get('false_accepts')} |")
    table = "\n".join(lines)
    atomic_write_text(out / "sweep.md", table + "\n")
    print(table)
    c = doc["cost_s"]
    print(f"\ncost: {len(points)} grid points in {c['sweep']:.1f} s = {c['sweep_over_plain_run']:.2f}x one plain "
          f"localizer run ({c['one_plain_run']:.1f} s), {a.workers} worker(s)")
    for what, chk in (("base thresholds", base_check), ("recommended", rec_check)):
        if chk is not None:
            print(f"check at the {what} ({chk['name']}): a plain run differs from the sweep in "
                  f"{chk['frames_differing']} of {chk['frames']} frames")
    bad = [chk for chk in (base_check, rec_check) if chk is not None and chk["frames_differing"]]
    if rec is None:
        print(f"recommended (no false accepts, median error <= {a.max_pos_err_pct} % h): none meets the bound")
    elif bad:
        print("recommended: none printed, the sweep and a plain run disagree (a bug: please report it)")
    else:
        print(f"recommended (no false accepts, median error <= {a.max_pos_err_pct} % h), confirmed by a plain run: "
              f"adjust {rec['adjust_height_m']:g} m, touchdown {rec['touchdown_height_m']:g} m "
              f"(availability {100 * rec['all']['availability']:.1f} %)")
    print(f"written {out / 'sweep.json'}, {out / 'sweep.md'}, {out / 'sweep_heatmaps.png'}; estimates per grid "
          f"point in {out / 'estimates'}")
    return 1 if bad else 0
