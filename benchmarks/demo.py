"""``hvloc demo``: the main job end to end on the small built-in default."""
from __future__ import annotations

import argparse
from pathlib import Path


def main(argv: list) -> int:
    p = argparse.ArgumentParser(prog="hvloc demo", description=__doc__)
    p.add_argument("--out", default="out/demo", help="output folder (default out/demo)")
    args = p.parse_args(argv)
    out = Path(args.out)
    from pad_design import make_pad, write_pad

    files = write_pad(make_pad(), out / "pad")
    print("pad written:")
    for name, path in files.items():
        print(f"  {name:18s} {path}")
    return 0
