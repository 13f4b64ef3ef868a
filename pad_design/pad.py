"""The pad as one object: spec, exact geometry (``pad.json``) and texture; making, saving, loading."""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from .errors import InputError, validate_model
from .layout import build_geometry
from .spec import PadSpec
from .texture import pad_to_pixels, render_texture

DEFAULT_PPM = 2000.0


def texture_sha256(rgb: np.ndarray) -> str:
    """Hash of the texture's pixels (shape and RGB bytes), independent of the PNG encoder."""
    h = hashlib.sha256()
    h.update(("%dx%dx%d;" % rgb.shape).encode())
    h.update(np.ascontiguousarray(rgb, dtype=np.uint8).tobytes())
    return h.hexdigest()


@dataclass
class Pad:
    """A landing pad: ``geometry`` is the ``pad.json`` document; ``texture_rgb`` is ``(n, n, 3)`` uint8."""

    spec: PadSpec
    geometry: dict
    texture_rgb: np.ndarray = field(repr=False)
    ppm: float

    # -- features, as float64 arrays in the pad frame (metres)
    @property
    def side_m(self) -> float:
        return float(self.geometry["side_m"])

    @property
    def outer_corners_P(self) -> np.ndarray:
        """``(4, 3)``: TL, TR, BR, BL."""
        return np.asarray(self.geometry["outer_corners"], np.float64)

    def markers(self, set_name: str | None = None, kind: str | None = None) -> list:
        return [m for m in self.geometry["markers"]
                if (set_name is None or m["set"] == set_name) and (kind is None or m["kind"] == kind)]

    def marker_points_P(self, name: str, set_name: str = "corner") -> np.ndarray:
        """``(4 * n_squares, 3)`` corners of one marker's nested squares, square by square."""
        for m in self.markers(set_name):
            if m["name"] == name:
                return np.asarray([c for sq in m["squares"] for c in sq["corners"]], np.float64)
        raise KeyError(f"no marker {name!r} in set {set_name!r}")

    def to_texture_px(self, points_P) -> np.ndarray:
        return pad_to_pixels(np.asarray(points_P, np.float64)[:, :2], self.side_m, self.ppm)

    # -- io
    def document(self) -> dict:
        """``pad.json``: geometry plus the texture's resolution and hash."""
        doc = dict(self.geometry)
        doc["texture"] = {"file": "pad.png", "ppm": self.ppm, "width_px": int(self.texture_rgb.shape[1]),
                          "height_px": int(self.texture_rgb.shape[0]),
                          "pixel_convention": "OpenCV: centre of the top-left pixel at (0,0); pixel (j, i) "
                                              "centre at x = (j+0.5)/ppm - side/2, y = side/2 - (i+0.5)/ppm",
                          "sha256": texture_sha256(self.texture_rgb)}
        return doc

    @classmethod
    def load(cls, pad_json) -> "Pad":
        """Load ``pad.json``; the texture comes from ``pad.png`` beside it, else is re-made from the spec."""
        path = Path(pad_json)
        try:
            doc = json.loads(path.read_text())
        except (OSError, ValueError) as err:
            raise InputError(f"{path}: cannot read pad.json ({err})") from None
        spec = validate_model(PadSpec, doc.get("spec"), f"{path}: spec")
        tex_info = doc.get("texture", {})
        ppm = float(tex_info.get("ppm", DEFAULT_PPM))
        png = path.with_name(tex_info.get("file", "pad.png"))
        rgb = None
        if png.exists():
            bgr = cv2.imread(str(png), cv2.IMREAD_COLOR)
            if bgr is not None:
                rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        if rgb is None:
            rgb = render_texture(spec, build_geometry(spec), ppm)
        if "sha256" in tex_info and texture_sha256(rgb) != tex_info["sha256"]:
            raise InputError(f"{png}: texture does not match the sha256 in {path.name}")
        geometry = {k: v for k, v in doc.items() if k != "texture"}
        return cls(spec, geometry, rgb, ppm)


def make_pad(spec: PadSpec | dict | None = None, ppm: float = DEFAULT_PPM) -> Pad:
    """Make a pad from a spec (a :class:`PadSpec`, a dict of its fields, or ``None`` for the default)."""
    if not isinstance(spec, PadSpec):
        spec = validate_model(PadSpec, spec or {}, "pad spec")
    if not (ppm > 0 and ppm <= 20000):
        raise InputError(f"ppm: {ppm} pixels per metre is out of range (0, 20000]")
    geometry = build_geometry(spec)
    rgb = render_texture(spec, geometry, ppm)
    return Pad(spec, geometry, rgb, rgb.shape[1] / spec.side_m)


def write_pad(pad: Pad, out_dir, pdf: bool = True) -> dict:
    """Write ``pad.png``, ``pad.json`` and (optionally) ``pad.pdf`` + ``pad_a4_tiles.pdf``.

    Files are written into a temporary folder beside ``out_dir`` and moved in only when all are
    complete, so an interrupted run leaves no half-written pad.  Returns ``{name: path}``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".pad-", dir=out))
    try:
        files = {"pad.png": tmp / "pad.png", "pad.json": tmp / "pad.json"}
        if not cv2.imwrite(str(files["pad.png"]), cv2.cvtColor(pad.texture_rgb, cv2.COLOR_RGB2BGR)):
            raise OSError(f"could not write {files['pad.png']}")
        files["pad.json"].write_text(json.dumps(pad.document(), indent=1))
        if pdf:
            from .pdf import write_pdfs

            files.update(write_pdfs(pad, tmp))
        result = {}
        for name, p in files.items():
            dst = out / name
            os.replace(p, dst)
            result[name] = dst
        return result
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
