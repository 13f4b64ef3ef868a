"""``hvloc pad ...``: make a pad's texture, geometry and printable PDFs."""
from __future__ import annotations

import argparse

from .errors import ArgumentParser, InputError, load_yaml_model, prepare_out_dir, validate_model
from .pad import DEFAULT_PPM, make_pad, write_pad
from .spec import PadSpec


def build_parser(prog: str = "hvloc pad") -> argparse.ArgumentParser:
    p = ArgumentParser(prog=prog, description="Design a landing pad.")
    sub = p.add_subparsers(dest="action", required=True)
    mk = sub.add_parser("make", help="write pad.png, pad.json, pad.pdf and pad_a4_tiles.pdf")
    mk.add_argument("--spec", help="pad spec YAML (default: the paper's 0.85 m pad)")
    mk.add_argument("--variant", choices=["paper", "nested", "aruco", "apriltag", "aruco_nested"],
                    help="override the spec's variant")
    mk.add_argument("--ppm", type=float, default=DEFAULT_PPM, help="texture pixels per metre (default 2000)")
    mk.add_argument("--no-pdf", action="store_true", help="skip the PDFs")
    mk.add_argument("--out", required=True, help="output folder")
    sch = sub.add_parser("schema", help="print the pad spec's JSON Schema")
    del sch
    return p


def main(argv: list) -> int:
    args = build_parser().parse_args(argv)
    if args.action == "schema":
        import json

        from .errors import editor_schema

        print(json.dumps(editor_schema(PadSpec.model_json_schema(), "pad_spec", "hvloc pad spec"), indent=1))
        return 0
    spec = load_yaml_model(PadSpec, args.spec) if args.spec else PadSpec()
    if args.variant:
        spec = validate_model(PadSpec, {**spec.model_dump(), "variant": args.variant}, "--variant")
    if not 0 < args.ppm <= 20000:
        raise InputError(f"--ppm: {args.ppm} is out of range (0, 20000]")
    prepare_out_dir(args.out)
    pad = make_pad(spec, args.ppm)
    files = write_pad(pad, args.out, pdf=not args.no_pdf)
    print(f"pad ({spec.variant}, {spec.side_m * 1000:.0f} mm, {pad.ppm:.0f} px/m) written:")
    for name, path in files.items():
        print(f"  {name:18s} {path}")
    return 0
