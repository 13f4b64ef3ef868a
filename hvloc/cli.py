"""The ``hvloc`` front door: it only dispatches.  Each package owns its subcommands' code, imported
lazily so that ``hvloc --help`` is fast.  Known input errors become one line and exit code 2."""
from __future__ import annotations

import importlib
import sys

# subcommand -> (module with main(argv) -> int, one-line help)
COMMANDS = {
    "pad": ("pad_design.cli", "design a landing pad: texture, pad.json geometry, printable PDFs"),
    "generate": ("render.cli:generate_main", "render labelled landing sequences from a dataset spec"),
    "import": ("render.cli:import_main", "a real flight (video or images, calibration, IMU, ground truth) as a dataset"),
    "dataset": ("render.cli:dataset_main", "verify or look at a generated dataset"),
    "camera": ("render.cli:camera_main", "import a camera calibration (Kalibr, ROS CameraInfo, OpenCV) into a spec"),
    "export": ("render.export:export_main", "write a dataset as EuRoC/ASL folders, ROS 2 bags or COCO keypoints"),
    # the harness that feeds datasets to the localizer reads them with render/, which hvloc/ may not
    # import (DESIGN.md layout), so it lives in benchmarks/
    "localize": ("benchmarks.run:localize_main", "run the hierarchical localizer over a dataset"),
    "bench": ("benchmarks.cli", "score localizers: run suites, sweep switch heights, compare, leaderboard, diagnose"),
    "demo": ("benchmarks.demo", "render, localize and score the tiny built-in default end to end"),
}

USAGE = "usage: hvloc <command> [options]   (hvloc <command> --help for more)\n\ncommands:\n" + "".join(
    f"  {name:10s} {helptext}\n" for name, (_, helptext) in COMMANDS.items())


def _load(target: str):
    mod, _, func = target.partition(":")
    return getattr(importlib.import_module(mod), func or "main")


def main(argv: list | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(USAGE, end="")
        return 0 if argv else 2
    if argv[0] == "--version":
        from hvloc import __version__

        print(f"hvloc {__version__}")
        return 0
    name = argv[0]
    if name not in COMMANDS:
        print(f"hvloc: unknown command {name!r}\n\n{USAGE}", end="", file=sys.stderr)
        return 2
    from pad_design.errors import InputError

    try:
        return int(_load(COMMANDS[name][0])(argv[1:]) or 0)
    except InputError as err:
        print(f"hvloc {name}: error: {err}", file=sys.stderr)
        return 2
    except OSError as err:  # the file system said no (disk full, permissions): one line, not a traceback
        where = f": {err.filename}" if getattr(err, "filename", None) else ""
        print(f"hvloc {name}: error: {err.strerror or err}{where}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"hvloc {name}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
