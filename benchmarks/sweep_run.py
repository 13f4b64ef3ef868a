"""``hvloc bench sweep``: datasets of a suite, one precompute pass, a replay per grid point."""
from __future__ import annotations

import json
import time
from pathlib import Path

from pad_design.errors import InputError, progress_bar


def run_sweep(a) -> int:
    from render.dataset import Dataset, atomic_write_text
    from render.generate import generate

    import numpy as np

    from hvloc.geometry import tum_from_transform

    from . import metrics as M
    from .run import localize_sequence
    from .suite import _clean, load_suite, provenance, runs_on
    from .sweep import recommend, replay, replay_errors, sweep, write_heatmaps

    suite, specs, configs, suite_hash = load_suite(a.suite)
    if any(h <= 0 for h in a.adjust_heights + a.touchdown_heights):
        raise InputError("--adjust-heights/--touchdown-heights: heights must be positive")
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    # the suite's first hvloc localizer: its switching heights are what the sweep varies
    hier = [(l, c) for l, c in configs if l.kind == "hierarchical"]
    if not hier:
        raise InputError(f"{a.suite}: no hierarchical localizer to sweep (peers have no switching heights)")
    loc, base_cfg = hier[0]
    sequences = []
    for spec in [s for s in specs if runs_on(loc, s)]:
        droot = out / "datasets" / f"{spec.name}-{spec.sha256()[:10]}"
        generate(spec, droot, workers=a.workers, show_progress=not a.quiet)
        sequences += list(Dataset(droot))
    bar = progress_bar(not a.quiet, sum(len(s) for s in sequences), "sweep precompute")
    res = sweep(sequences, base_cfg, a.adjust_heights, a.touchdown_heights, loc.use_imu, bar.update if bar else None)
    if bar:
        bar.close()
    # one plain localizer run at the base thresholds: the cost reference, and the replay's check
    t0 = time.perf_counter()
    live = [localize_sequence(seq, base_cfg, loc.use_imu) for seq in sequences]
    live_s = time.perf_counter() - t0
    fes_live = []
    for seq, est in zip(sequences, live):
        cols = {"frame": seq.columns["frame"], "t": seq.columns["t"], "status": [e.status for e in est],
                "phase": [e.phase for e in est], "ms": [e.ms for e in est]}
        rows = np.array([tum_from_transform(e.cam2pad) if e.cam2pad is not None else [np.nan] * 7 for e in est])
        for i, c in enumerate(("tx", "ty", "tz", "qx", "qy", "qz", "qw")):
            cols[c] = rows[:, i]
        cols = {k: np.asarray(v, dtype=object if k in ("status", "phase") else float) for k, v in cols.items()}
        fes_live.append(M.frame_errors(seq.columns, cols))
    live_score = M.score(M.concat(fes_live))
    replay_default = M.score(M.concat([replay_errors(s, replay(c, base_cfg)) for s, c in zip(sequences, res["caches"])]))
    rec = recommend(res["grid"], a.max_pos_err_pct)
    write_heatmaps(res["grid"], out / "sweep_heatmaps.png", a.adjust_heights, a.touchdown_heights)
    doc = {"schema": "hvloc-sweep/1", "suite": suite.name, "suite_sha256": suite_hash, "provenance": provenance(),
           "base_localizer": loc.name, "grid": res["grid"], "recommended": rec, "bound_pos_err_pct": a.max_pos_err_pct,
           "cost_s": {"precompute": res["precompute_s"], "replay_all_points": res["replay_s"],
                      "one_plain_localizer_run": live_s,
                      "sweep_over_plain_run": (res["precompute_s"] + res["replay_s"]) / max(live_s, 1e-9)},
           "check_at_base_thresholds": {"live": live_score, "replay": replay_default}}
    atomic_write_text(out / "sweep.json", json.dumps(_clean(doc), indent=1) + "\n")
    lines = ["| adjust h (m) | touchdown h (m) | availability | appr. | adj. | td. | pos median % h | td. RMSE mm | false accepts |",
             "|---|---|---|---|---|---|---|---|---|"]
    for g in res["grid"]:
        f = lambda s, k, sc=100.0: "-" if g[s].get(k) is None else f"{g[s][k] * sc:.1f}"  # noqa: E731
        lines.append(f"| {g['adjust_height_m']:g} | {g['touchdown_height_m']:g} | {f('all', 'availability')} % | "
                     f"{f('gt:approaching', 'availability')} | {f('gt:adjustment', 'availability')} | "
                     f"{f('gt:touchdown', 'availability')} | {f('all', 'pos_err_pct_median', 1.0)} | "
                     f"{f('gt:touchdown', 'pos_err_m_rmse', 1000.0)} | {g['all'].get('false_accepts')} |")
    table = "\n".join(lines)
    (out / "sweep.md").write_text(table + "\n")
    print(table)
    c = doc["cost_s"]
    print(f"\nrecommended (no false accepts, median error <= {a.max_pos_err_pct} % h): "
          + (f"adjust {rec['adjust_height_m']:g} m, touchdown {rec['touchdown_height_m']:g} m "
             f"(availability {100 * rec['all']['availability']:.1f} %)" if rec else "none meets the bound"))
    print(f"cost: precompute {c['precompute']:.1f} s + replay of {len(res['grid'])} points {c['replay_all_points']:.1f} s "
          f"= {c['sweep_over_plain_run']:.2f}x one plain localizer run ({c['one_plain_localizer_run']:.1f} s)")
    lv, rp = doc["check_at_base_thresholds"]["live"], doc["check_at_base_thresholds"]["replay"]
    print(f"check at the base thresholds: live availability {100 * lv['availability']:.1f} %, replay "
          f"{100 * rp['availability']:.1f} %; live median error {lv.get('pos_err_pct_median') or float('nan'):.2f} % h, "
          f"replay {rp.get('pos_err_pct_median') or float('nan'):.2f} % h")
    print(f"written {out / 'sweep.json'}, {out / 'sweep.md'}, {out / 'sweep_heatmaps.png'}")
    return 0
