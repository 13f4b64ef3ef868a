"""Ways a dataset on disk gets damaged, each a function ``(root) -> None`` that damages a copy.

Used by the reliability tests (every kind must be reported by ``hvloc dataset verify`` and refused
by ``hvloc localize``) and by ``python -m benchmarks.reliability``.  Sequence ``seq_0000`` and
its frames 0 and 1 are the victims.
"""
from __future__ import annotations

import json
from pathlib import Path

SEQ = "seq_0000"


def _rw(path: Path, fn) -> None:
    path.write_text(fn(path.read_text()))


def _lines(path: Path, fn) -> None:
    lines = path.read_text().splitlines()
    path.write_text("\n".join(fn(lines)) + "\n")


def _csv_cell(root: Path, name: str, column: str, row: int, value: str) -> None:
    def edit(lines):
        head = lines[0].split(",")
        cells = lines[row + 1].split(",")
        cells[head.index(column)] = value
        lines[row + 1] = ",".join(cells)
        return lines
    _lines(root / SEQ / name, edit)


def _manifest(root: Path, fn) -> None:
    p = root / "manifest.json"
    m = json.loads(p.read_text())
    out = fn(m)
    p.write_text(json.dumps(m if out is None else out, indent=1))


def _json(root: Path, rel: str, fn) -> None:
    p = root / rel
    d = json.loads(p.read_text())
    fn(d)
    p.write_text(json.dumps(d, indent=1))


def _png(root: Path, k: int) -> Path:
    return root / SEQ / "images" / f"{k:06d}.png"


KINDS = {
    # the manifest
    "manifest files emptied": lambda r: _manifest(r, lambda m: m.update(files={})),
    "manifest not JSON": lambda r: (r / "manifest.json").write_text("{not json"),
    "manifest truncated": lambda r: _rw(r / "manifest.json", lambda s: s[: len(s) // 2]),
    "manifest sequences not a list": lambda r: _manifest(r, lambda m: m.update(sequences=5)),
    "manifest files a list": lambda r: _manifest(r, lambda m: m.update(files=[])),
    "manifest of another format version": lambda r: _manifest(r, lambda m: m.update(version=1)),
    "sequence dropped from the manifest": lambda r: _manifest(
        r, lambda m: m.update(sequences=[s for s in m["sequences"] if s["id"] != SEQ],
                              files={k: v for k, v in m["files"].items() if not k.startswith(SEQ + "/")})),
    "a checksum changed in the manifest": lambda r: _manifest(
        r, lambda m: m["files"].update({f"{SEQ}/frames.csv": "0" * 64})),
    "sequences_planned raised": lambda r: _manifest(r, lambda m: m.update(sequences_planned=m["sequences_planned"] + 1)),
    "manifest deleted": lambda r: (r / "manifest.json").unlink(),
    # images
    "PNG truncated": lambda r: _png(r, 1).write_bytes(_png(r, 1).read_bytes()[:200]),
    "PNG deleted": lambda r: _png(r, 1).unlink(),
    "PNG swapped with another frame's": lambda r: _png(r, 1).write_bytes(_png(r, 0).read_bytes()),
    "PNG one byte flipped": lambda r: _png(r, 1).write_bytes(
        (lambda b: b[:500] + bytes([b[500] ^ 1]) + b[501:])(_png(r, 1).read_bytes())),
    "PNG replaced by zeros": lambda r: _png(r, 1).write_bytes(bytes(_png(r, 1).stat().st_size)),
    "an extra image": lambda r: (r / SEQ / "images" / "999999.png").write_bytes(_png(r, 0).read_bytes()),
    # frames.csv
    "frames.csv: t is 'abc'": lambda r: _csv_cell(r, "frames.csv", "t", 1, "abc"),
    "frames.csv: header only": lambda r: _lines(r / SEQ / "frames.csv", lambda ls: ls[:1]),
    "frames.csv: a row deleted": lambda r: _lines(r / SEQ / "frames.csv", lambda ls: ls[:2] + ls[3:]),
    "frames.csv: empty": lambda r: (r / SEQ / "frames.csv").write_text(""),
    "frames.csv: a pose changed": lambda r: _csv_cell(r, "frames.csv", "tx", 1, "0.5"),
    "frames.csv: a row too short": lambda r: _lines(r / SEQ / "frames.csv", lambda ls: ls[:2] + [ls[2][:20]] + ls[3:]),
    "frames.csv: deleted": lambda r: (r / SEQ / "frames.csv").unlink(),
    "frames.csv: binary garbage": lambda r: (r / SEQ / "frames.csv").write_bytes(b"\x00\xff\xfe" * 50),
    # other sequence files
    "groundtruth.tum: garbage": lambda r: (r / SEQ / "groundtruth.tum").write_text("garbage here\n1 2 3\n"),
    "groundtruth.tum: a row deleted": lambda r: _lines(r / SEQ / "groundtruth.tum", lambda ls: ls[:2] + ls[3:]),
    "camera.json: fx doubled": lambda r: _json(r, f"{SEQ}/camera.json", lambda d: d.update(fx=2 * d["fx"])),
    "camera.json: not JSON": lambda r: (r / SEQ / "camera.json").write_text("{"),
    "camera.json: deleted": lambda r: (r / SEQ / "camera.json").unlink(),
    "imu.csv: NaN quaternions": lambda r: _csv_cell(r, "imu.csv", "ahrs_qw", 3, "nan"),
    "imu.csv: rows deleted": lambda r: _lines(r / SEQ / "imu.csv", lambda ls: ls[:10]),
    "pad.json: a corner moved": lambda r: _json(r, f"{SEQ}/pad.json",
                                                lambda d: d["outer_corners"][0].__setitem__(0, -0.5)),
    "pad.json: not JSON": lambda r: (r / SEQ / "pad.json").write_text("]"),
    "meta.json: deleted": lambda r: (r / SEQ / "meta.json").unlink(),
    "meta.json: a checksum changed": lambda r: _json(r, f"{SEQ}/meta.json",
                                                     lambda d: d["files"].update({"frames.csv": "1" * 64})),
    # the dataset's pad texture
    "pad.png: deleted": lambda r: (r / "pad.png").unlink(),
    "pad.png: truncated": lambda r: (r / "pad.png").write_bytes((r / "pad.png").read_bytes()[:300]),
    # stray files and folders
    "an unlisted file": lambda r: (r / SEQ / "notes.txt").write_text("hello"),
    "an unlisted sequence folder": lambda r: __import__("shutil").copytree(r / SEQ, r / "seq_0099"),
    "an unfinished .tmp folder": lambda r: (r / ".tmp-seq_0005").mkdir(),
}
