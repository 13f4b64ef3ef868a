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
from .geometry import PadGeometry
from .layout import build_geometry
from .spec import PadSpec
from .texture import pad_to_pixels, pixels_to_pad, render_texture

DEFAULT_PPM = 2000.0


def texture_sha256(rgb: np.ndarray) -> str:
    """Hash of the texture's pixels (shape and RGB bytes), independent of the PNG encoder."""
    h = hashlib.sha256()
    h.update(("%dx%dx%d;" % rgb.shape).encode())
    h.update(np.ascontiguousarray(rgb, dtype=np.uint8).tobytes())
    return h.hexdigest()


@dataclass
class Pad:
    """A landing pad: its spec, its validated geometry and its texture ``(n, n, 3)`` uint8 RGB."""

    spec: PadSpec
    geometry: PadGeometry
    texture_rgb: np.ndarray = field(repr=False)
    ppm: float

    # -- features, as float64 arrays in the pad frame (metres)
    @property
    def side_m(self) -> float:
        return self.geometry.side_m

    @property
    def outer_corners_P(self) -> np.ndarray:
        """``(4, 3)``: TL, TR, BR, BL."""
        return self.geometry.outer_corners

    def markers(self, set_name: str | None = None, kind: str | None = None) -> list:
        return self.geometry.markers_in(set_name, kind)

    def marker_points_P(self, name: str, set_name: str = "corner") -> np.ndarray:
        """``(4 * n_squares, 3)`` corners of one marker's nested squares, square by square."""
        return self.geometry.marker(name, set_name).points

    def to_texture_px(self, points_P) -> np.ndarray:
        return pad_to_pixels(np.asarray(points_P, np.float64)[:, :2], self.side_m, self.ppm)

    def from_texture_px(self, px) -> np.ndarray:
        """Texture pixels ``(N, 2)`` -> ``(N, 3)`` pad-frame points on its surface (z = 0)."""
        xy = pixels_to_pad(px, self.side_m, self.ppm)
        return np.column_stack([xy, np.zeros(len(xy))])

    # -- io
    def document(self, texture_file: str = "pad.png") -> dict:
        """``pad.json``: geometry plus the texture's file (relative to pad.json), resolution and hash."""
        doc = self.geometry.to_document()
        doc["texture"] = {"file": texture_file, "ppm": self.ppm, "width_px": int(self.texture_rgb.shape[1]),
                          "height_px": int(self.texture_rgb.shape[0]),
                          "pixel_convention": "OpenCV: centre of the top-left pixel at (0,0); pixel (j, i) "
                                              "centre at x = (j+0.5)/ppm - side/2, y = side/2 - (i+0.5)/ppm",
                          "sha256": texture_sha256(self.texture_rgb)}
        return doc

    @classmethod
    def load(cls, pad_json) -> "Pad":
        """Load ``pad.json`` and the texture it names (``texture.file``, relative to pad.json).

        The texture is read, never re-rasterised: a pad must look exactly as it did when its
        images were made, whatever OpenCV draws today.  Its pixels must match the hash."""
        path = Path(pad_json)
        try:
            doc = json.loads(path.read_text())
        except (OSError, ValueError) as err:
            raise InputError(f"{path}: cannot read pad.json ({err})") from None
        if not isinstance(doc, dict):
            raise InputError(f"{path}: not a pad.json document")
        spec = validate_model(PadSpec, doc.get("spec"), f"{path}: spec")
        geometry = PadGeometry.from_document(doc, str(path))
        tex_info = doc.get("texture")
        if not isinstance(tex_info, dict) or not isinstance(tex_info.get("file"), str):
            raise InputError(f"{path}: texture.file: missing (which image is this pad's texture?)")
        png = (path.parent / tex_info["file"]).resolve()
        bgr = cv2.imread(str(png), cv2.IMREAD_COLOR) if png.is_file() else None
        if bgr is None:
            raise InputError(f"{path}: its texture {tex_info['file']} is missing or not a readable image")
        rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        if "sha256" in tex_info and texture_sha256(rgb) != tex_info["sha256"]:
            raise InputError(f"{png}: texture does not match the sha256 in {path.name}")
        ppm = tex_info.get("ppm", rgb.shape[1] / geometry.side_m)
        if isinstance(ppm, bool) or not isinstance(ppm, (int, float)) or not ppm > 0:
            raise InputError(f"{path}: texture.ppm: expected a positive number, got {ppm!r}")
        return cls(spec, geometry, rgb, float(ppm))


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
