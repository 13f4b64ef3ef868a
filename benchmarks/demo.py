"""``hvloc demo``: the main job end to end on the small built-in default: make the pad, render
the tiny landing sequences, localize them, score per phase, print the table and the report path."""
from __future__ import annotations

from pathlib import Path


def main(argv: list) -> int:
    from pad_design.errors import ArgumentParser, prepare_out_dir

    p = ArgumentParser(prog="hvloc demo", description=__doc__)
    p.add_argument("--out", default="out/demo", help="output folder (default out/demo)")
    p.add_quiet()
    args = p.parse_args(argv)
    out = prepare_out_dir(args.out)
    from pad_design import make_pad, write_pad

    files = write_pad(make_pad(), out / "pad")
    print(f"pad: {files['pad.png']} (+ pad.json, pad.pdf, pad_a4_tiles.pdf)")
    from .report import phase_table
    from .suite import REPO, run_suite

    res = run_suite(REPO / "data_specs" / "suites" / "smoke.yaml", out / "bench", workers=1,
                    show_progress=not args.quiet)
    print()
    print(phase_table(res["summary"]))
    print()
    print(f"dataset:  {out / 'bench' / 'datasets'}  (hvloc dataset show <dir> draws its labels)")
    print(f"report:   {out / 'bench' / 'report.md'}")
    print(f"plots:    {out / 'bench' / 'plots'}")
    return 0
