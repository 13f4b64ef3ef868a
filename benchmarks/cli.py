"""``hvloc bench run|sweep|score|compare|leaderboard|diagnose``."""
from __future__ import annotations

import json

from pad_design.errors import ArgumentParser, InputError, prepare_out_dir, workers_arg


def _executor_args(p) -> None:
    from render.executor import EXECUTORS

    p.add_argument("--executor", choices=EXECUTORS, default="local",
                   help="where sequences are rendered and localized: local processes, or a Ray cluster")
    p.add_argument("--ray-address", help="Ray cluster to join (default: start one on this machine); see README")


# subcommands whose module has its own command line (also runnable as ``python -m benchmarks.X``)
DELEGATED = {"leaderboard": ("benchmarks.leaderboard", "rewrite a frozen suite's committed leaderboard (LEADERBOARD*.md) from its run"),
             "diagnose": ("benchmarks.diagnose", "per phase: why a dataset's frames were lost or rejected"),
             "fuzz": ("benchmarks.fuzz", "random scenes from the whole spec space, rendered, localized, every false "
                                         "accept listed")}


def main(argv: list) -> int:
    if argv and argv[0] in DELEGATED:
        import importlib

        return importlib.import_module(DELEGATED[argv[0]][0]).main(argv[1:], prog=f"hvloc bench {argv[0]}")
    p = ArgumentParser(prog="hvloc bench", description="Score localizers per landing phase.")
    sub = p.add_subparsers(dest="action", required=True)
    r = sub.add_parser("run", help="generate/reuse a suite's datasets, localize, score, report")
    r.add_argument("suite", help="suite YAML, or a name in data_specs/suites/")
    r.add_argument("--out", required=True, help="results folder: datasets/, estimates/, results.json, report.md, plots/")
    r.add_argument("--workers", type=workers_arg, default=1, help="processes that render, then localize (one sequence each)")
    _executor_args(r)
    r.add_argument("--no-verify", action="store_true",
                   help="use datasets even if their files differ from the checksums in their manifests")
    r.add_quiet()
    w = sub.add_parser("sweep", help="grid over the two switch heights: every point a live run, image work shared")
    w.add_argument("suite", help="suite YAML, or a name in data_specs/suites/ (its first localizer is swept)")
    w.add_argument("--adjust-heights", type=float, nargs="+", default=[3.0, 5.0, 7.0, 9.0, 12.0],
                   help="heights (m) below which the markers take over from the outline")
    w.add_argument("--touchdown-heights", type=float, nargs="+", default=[0.4, 0.7, 1.0, 1.5, 2.0],
                   help="heights (m) below which flow tracking takes over from the markers")
    w.add_argument("--max-pos-err-pct", type=float, default=2.0, help="error bound for the recommendation")
    w.add_argument("--out", required=True, help="folder for sweep.json, the heat maps and the datasets")
    w.add_argument("--workers", type=workers_arg, default=1,
                   help="processes that render the suite's datasets, then localize (one sequence each)")
    w.add_quiet()
    sc = sub.add_parser("score", help="score a localizer's estimates on any dataset (an imported flight too)")
    sc.add_argument("dataset", help="dataset folder (made by hvloc generate or hvloc import)")
    sc.add_argument("results", help="the localizer's output folder (hvloc localize --out)")
    c = sub.add_parser("compare", help="exit 1 with a table of metrics that got worse than the baseline")
    c.add_argument("new", help="results.json (or its folder)")
    c.add_argument("baseline", help="results.json (or its folder)")
    c.add_argument("--significant", action="store_true",
                   help="count a worse metric only beyond the baseline's 95 %% interval over descents (ci95)")
    for name, (_, helptext) in DELEGATED.items():
        sub.add_parser(name, help=helptext, add_help=False)  # listed here, parsed by their own module
    a = p.parse_args(argv)
    from .suite import compare, load_results, load_suite, run_suite

    if a.action in ("run", "sweep"):
        load_suite(a.suite)  # a bad suite is refused before anything is written
        prepare_out_dir(a.out)
    if a.action == "run":
        res = run_suite(a.suite, a.out, workers=a.workers, show_progress=not a.quiet, executor=a.executor,
                        ray_address=a.ray_address, verify=not a.no_verify)
        from .report import phase_table

        print(phase_table(res["summary"]))
        print(f"\nreport: {a.out}/report.md (plots in {a.out}/plots/); results: {a.out}/results.json")
        return 0
    if a.action == "sweep":
        from .sweep_run import run_sweep

        return run_sweep(a)
    if a.action == "score":
        from .report import phase_table
        from .run import score_dataset

        res = score_dataset(a.dataset, a.results)
        print(phase_table({"estimates": res["summary"]}))
        if res["by_pad_px"]:
            from .report import size_table

            print("\nby the pad's size in the image (its labelled corners; frames with the whole pad in view):\n")
            print(size_table(res["by_pad_px"]))
        for note in res["notes"]:
            print(f"note: {note}")
        return 0
    new, base = load_results(a.new), load_results(a.baseline)
    if new.get("suite_sha256") != base.get("suite_sha256"):
        raise InputError("results are of different suites (suite_sha256 differs); nothing to compare")
    worse = compare(new, base, significant=a.significant)
    if not worse:
        print("no metric got worse than the baseline")
        return 0
    print("| localizer | scope | metric | baseline | new |\n|---|---|---|---|---|")
    for loc, scope, m, b, n in worse:
        print(f"| {loc} | {scope} | {m} | {json.dumps(b)} | {json.dumps(n)} |")
    return 1
