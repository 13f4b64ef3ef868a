"""The pad's geometry as a typed, validated object (what ``pad.json`` holds, in the pad frame P).

Every array is float64 and checked once, when the object is made from a document
(:meth:`PadGeometry.from_document`); code downstream reads attributes, never string keys.
Squares list their corners TL, TR, BR, BL as printed: ``(-x,+y), (+x,+y), (+x,-y), (-x,-y)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .errors import InputError

MARKER_NAMES = ("Top", "Right", "Bottom")
TAG_NAMES = ("Large", "Small")  # the AprilTags of the apriltag variant: one nested in the other
MARKER_KINDS = ("finder", "aruco", "apriltag")
VARIANTS = ("paper", "nested", "aruco", "apriltag", "aruco_nested", "artwork")
_CORNER_SIGNS = np.array([[-1, 1], [1, 1], [1, -1], [-1, -1]])


def _array(value, shape: tuple, where: str) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{where}: not an array of numbers") from None
    if a.shape != shape:
        raise InputError(f"{where}: expected shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{where}: values must be finite")
    a.setflags(write=False)
    return a


def _number(value, where: str, positive: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(f"{where}: expected a finite number, got {value!r}")
    if positive and value <= 0:
        raise InputError(f"{where}: must be positive, got {value}")
    return float(value)


def _get(doc: dict, key: str, where: str):
    if not isinstance(doc, dict):
        raise InputError(f"{where}: expected a mapping, got {type(doc).__name__}")
    if key not in doc:
        raise InputError(f"{where}.{key}: missing")
    return doc[key]


def _square_corners(value, where: str) -> np.ndarray:
    """(4, 3) corners of an axis-aligned square on the pad plane, in the order TL, TR, BR, BL."""
    c = _array(value, (4, 3), where)
    if np.any(np.abs(c[:, 2]) > 1e-9):
        raise InputError(f"{where}: corners must lie on the pad plane (z = 0)")
    centre = c[:, :2].mean(axis=0)
    if not np.array_equal(np.sign(np.round(c[:, :2] - centre, 12)), _CORNER_SIGNS):
        raise InputError(f"{where}: corners must be ordered TL, TR, BR, BL as printed")
    return c


@dataclass(frozen=True)
class ColourRange:
    """An OpenCV HSV range (H 0-180, S and V 0-255); ``hue_wraps``: ``H >= lo[0] or H <= hi[0]``."""

    lo: np.ndarray
    hi: np.ndarray
    hue_wraps: bool

    @classmethod
    def from_document(cls, d, where: str) -> "ColourRange":
        return cls(_array(_get(d, "lo", where), (3,), f"{where}.lo"), _array(_get(d, "hi", where), (3,), f"{where}.hi"),
                   bool(d.get("hue_wraps", False)))

    def to_document(self) -> dict:
        return {"lo": [float(v) for v in self.lo], "hi": [float(v) for v in self.hi], "hue_wraps": self.hue_wraps}


def _rgb(value, where: str) -> tuple:
    a = _array(value, (3,), where)
    if np.any(a < 0) or np.any(a > 255):
        raise InputError(f"{where}: colour components must be 0-255")
    return tuple(int(round(v)) for v in a)


@dataclass(frozen=True)
class Square:
    """One nested square of a marker: its side, the colour inside its outline, its corners (4, 3)."""

    name: str
    side_m: float
    color_inside: str
    corners: np.ndarray


@dataclass(frozen=True)
class Marker:
    """A marker of a set (``corner``: the three at the pad's corners; ``centre``: the nested set)."""

    name: str
    set: str
    kind: str
    center: np.ndarray     # (3,)
    size_m: float          # outer side
    module_m: float
    quiet_zone_m: float
    squares: tuple         # of Square, outermost first
    aruco_id: int | None = None   # the id of an ArUco marker, or of an AprilTag (its family: the pad spec's)

    @property
    def outer_corners(self) -> np.ndarray:
        """``(4, 3)``: the outer square's corners TL, TR, BR, BL."""
        return self.squares[0].corners

    @property
    def points(self) -> np.ndarray:
        """``(4 * n_squares, 3)``: every square's corners, square by square."""
        return np.concatenate([s.corners for s in self.squares])

    @property
    def modules_across(self) -> int:
        if self.kind == "aruco":  # its cells, border included: the module
            return int(round(self.size_m / self.module_m))
        return {"finder": 7, "apriltag": 6}[self.kind]  # the apriltag: cells of its detected square


@dataclass(frozen=True)
class Border:
    color_rgb: tuple
    dark_color_rgb: tuple
    solid_band_m: float
    checker_m: float
    segmentation_hsv: ColourRange


@dataclass(frozen=True)
class Cue:
    kind: str
    corner: str
    color_rgb: tuple
    corners: np.ndarray    # (4, 3)
    segmentation_hsv: ColourRange
    note: str = ""


@dataclass(frozen=True)
class PadGeometry:
    """Everything a localizer or renderer needs to know about a pad's features (metres, pad frame)."""

    version: int
    variant: str
    side_m: float
    border_m: float
    field_side_m: float
    outer_corners: np.ndarray   # (4, 3) TL, TR, BR, BL
    field_corners: np.ndarray   # (4, 3)
    border: Border | None       # None on an artwork pad (hvloc's border, cue and markers are not drawn)
    cue: Cue | None
    markers: tuple              # of Marker
    spec: dict = field(default_factory=dict)
    frame: str = ""
    corner_order: str = ""
    points: dict = field(default_factory=dict)  # name -> (3,): an artwork's points a localizer may use

    # ------------------------------------------------------------------ queries
    def markers_in(self, set_name: str | None = None, kind: str | None = None) -> list:
        return [m for m in self.markers if (set_name is None or m.set == set_name) and (kind is None or m.kind == kind)]

    def marker(self, name: str, set_name: str = "corner") -> Marker:
        for m in self.markers:
            if m.name == name and m.set == set_name:
                return m
        raise KeyError(f"no marker {name!r} in set {set_name!r}")

    @property
    def marker_sets(self) -> dict:
        """``{set name: {marker name: Marker}}``."""
        out: dict = {}
        for m in self.markers:
            out.setdefault(m.set, {})[m.name] = m
        return out

    @property
    def half_side_m(self) -> float:
        return self.side_m / 2.0

    # ------------------------------------------------------------------ documents
    @classmethod
    def from_document(cls, doc: dict, source: str = "pad.json") -> "PadGeometry":
        """Validate a ``pad.json`` document (the texture part is ignored) into a PadGeometry, or
        raise :class:`InputError` naming the first field that is wrong."""
        w = source
        if not isinstance(doc, dict):
            raise InputError(f"{w}: expected a JSON object, got {type(doc).__name__}")
        version = _get(doc, "version", w)
        if version != 1:
            raise InputError(f"{w}.version: {version!r} is not a pad.json version this hvloc reads (1)")
        variant = _get(doc, "variant", w)
        if variant not in VARIANTS:
            raise InputError(f"{w}.variant: {variant!r} is not one of {', '.join(VARIANTS)}")
        side = _number(_get(doc, "side_m", w), f"{w}.side_m")
        art = variant == "artwork"
        border_m = _number(_get(doc, "border_m", w), f"{w}.border_m", positive=not art)
        field_side = _number(_get(doc, "field_side_m", w), f"{w}.field_side_m")
        if not math.isclose(field_side, side - 2 * border_m, rel_tol=0, abs_tol=1e-9):
            raise InputError(f"{w}.field_side_m: {field_side} is not side_m - 2 border_m")
        outer = _square_corners(_get(doc, "outer_corners", w), f"{w}.outer_corners")
        if not np.allclose(np.abs(outer[:, :2]), side / 2, atol=1e-9):
            raise InputError(f"{w}.outer_corners: must be the square of side side_m centred on the pad origin")
        fieldc = _square_corners(_get(doc, "field_corners", w), f"{w}.field_corners")
        points = {}
        plist = doc.get("points", [])
        if not isinstance(plist, list):
            raise InputError(f"{w}.points: expected a list")
        for i, pt in enumerate(plist):
            name = str(_get(pt, "name", f"{w}.points.{i}"))
            xyz = _array(_get(pt, "xyz", f"{w}.points.{i}"), (3,), f"{w}.points.{i}.xyz")
            if name in points:
                raise InputError(f"{w}.points.{i}.name: {name!r} twice")
            if abs(xyz[2]) > 1e-9 or np.any(np.abs(xyz[:2]) > side / 2 + 1e-9):
                raise InputError(f"{w}.points.{i}.xyz: must lie on the pad (z = 0, |x|, |y| <= side_m / 2)")
            points[name] = xyz
        if art:
            if doc.get("border") is not None or doc.get("cue") is not None or doc.get("markers"):
                raise InputError(f"{w}: an artwork pad has no border, cue or markers of hvloc's (they must be null)")
            spec = doc.get("spec") or {}
            if not isinstance(spec, dict):
                raise InputError(f"{w}.spec: expected a mapping")
            return cls(1, variant, side, border_m, field_side, outer, fieldc, None, None, (), dict(spec),
                       str(doc.get("frame", "")), str(doc.get("corner_order", "")), points)
        b = _get(doc, "border", w)
        border = Border(_rgb(_get(b, "color_rgb", f"{w}.border"), f"{w}.border.color_rgb"),
                        _rgb(_get(b, "dark_color_rgb", f"{w}.border"), f"{w}.border.dark_color_rgb"),
                        _number(_get(b, "solid_band_m", f"{w}.border"), f"{w}.border.solid_band_m"),
                        _number(_get(b, "checker_m", f"{w}.border"), f"{w}.border.checker_m"),
                        ColourRange.from_document(_get(b, "segmentation_hsv", f"{w}.border"), f"{w}.border.segmentation_hsv"))
        c = _get(doc, "cue", w)
        cue = Cue(str(_get(c, "kind", f"{w}.cue")), str(_get(c, "corner", f"{w}.cue")),
                  _rgb(_get(c, "color_rgb", f"{w}.cue"), f"{w}.cue.color_rgb"),
                  _square_corners(_get(c, "corners", f"{w}.cue"), f"{w}.cue.corners"),
                  ColourRange.from_document(_get(c, "segmentation_hsv", f"{w}.cue"), f"{w}.cue.segmentation_hsv"),
                  str(c.get("note", "")))
        mlist = _get(doc, "markers", w)
        if not isinstance(mlist, list):
            raise InputError(f"{w}.markers: expected a list")
        markers = []
        seen = set()
        for i, m in enumerate(mlist):
            mw = f"{w}.markers.{i}"
            name, set_name, kind = _get(m, "name", mw), str(_get(m, "set", mw)), _get(m, "kind", mw)
            if kind not in MARKER_KINDS:
                raise InputError(f"{mw}.kind: {kind!r} is not one of {', '.join(MARKER_KINDS)}")
            names = TAG_NAMES if kind == "apriltag" else MARKER_NAMES + TAG_NAMES if kind == "aruco" else MARKER_NAMES
            if name not in names:
                raise InputError(f"{mw}.name: {name!r} is not one of {', '.join(names)}")
            if (set_name, name) in seen:
                raise InputError(f"{mw}: a second {name} marker in set {set_name!r}")
            seen.add((set_name, name))
            sq = _get(m, "squares", mw)
            if not isinstance(sq, list) or not sq:
                raise InputError(f"{mw}.squares: expected a non-empty list")
            squares = tuple(Square(str(_get(s, "name", f"{mw}.squares.{j}")),
                                   _number(_get(s, "side_m", f"{mw}.squares.{j}"), f"{mw}.squares.{j}.side_m"),
                                   str(_get(s, "color_inside", f"{mw}.squares.{j}")),
                                   _square_corners(_get(s, "corners", f"{mw}.squares.{j}"), f"{mw}.squares.{j}.corners"))
                            for j, s in enumerate(sq))
            if any(a.side_m <= b_.side_m for a, b_ in zip(squares, squares[1:])):
                raise InputError(f"{mw}.squares: must be listed outermost first, each inside the last")
            aruco_id = m.get("aruco_id")
            if kind in ("aruco", "apriltag") and (isinstance(aruco_id, bool) or not isinstance(aruco_id, int)
                                                  or aruco_id < 0):
                raise InputError(f"{mw}.aruco_id: an ArUco marker or an AprilTag needs a non-negative integer id")
            markers.append(Marker(name, set_name, kind, _array(_get(m, "center", mw), (3,), f"{mw}.center"),
                                  _number(_get(m, "size_m", mw), f"{mw}.size_m"),
                                  _number(_get(m, "module_m", mw), f"{mw}.module_m"),
                                  _number(_get(m, "quiet_zone_m", mw), f"{mw}.quiet_zone_m", positive=False),
                                  squares, int(aruco_id) if aruco_id is not None else None))
        spec = doc.get("spec") or {}
        if not isinstance(spec, dict):
            raise InputError(f"{w}.spec: expected a mapping")
        return cls(1, variant, side, border_m, field_side, outer, fieldc, border, cue, tuple(markers), dict(spec),
                   str(doc.get("frame", "")), str(doc.get("corner_order", "")), points)

    def to_document(self) -> dict:
        """The ``pad.json`` document (without the texture part): the inverse of :meth:`from_document`."""
        def sq(s: Square) -> dict:
            return {"name": s.name, "side_m": s.side_m, "color_inside": s.color_inside, "corners": s.corners.tolist()}

        markers = []
        for m in self.markers:
            d = {"name": m.name, "set": m.set, "kind": m.kind, "center": m.center.tolist(), "size_m": m.size_m,
                 "module_m": m.module_m, "quiet_zone_m": m.quiet_zone_m, "squares": [sq(s) for s in m.squares]}
            if m.aruco_id is not None:
                d["aruco_id"] = m.aruco_id
            markers.append(d)
        b, c = self.border, self.cue
        doc = {"version": self.version, "frame": self.frame, "corner_order": self.corner_order,
               "variant": self.variant, "side_m": self.side_m, "border_m": self.border_m,
               "field_side_m": self.field_side_m, "outer_corners": self.outer_corners.tolist(),
               "field_corners": self.field_corners.tolist(),
               "border": None if b is None else {
                   "color_rgb": list(b.color_rgb), "dark_color_rgb": list(b.dark_color_rgb),
                   "solid_band_m": b.solid_band_m, "checker_m": b.checker_m,
                   "segmentation_hsv": b.segmentation_hsv.to_document()},
               "cue": None if c is None else {
                   "kind": c.kind, "corner": c.corner, "color_rgb": list(c.color_rgb), "corners": c.corners.tolist(),
                   "segmentation_hsv": c.segmentation_hsv.to_document(), "note": c.note},
               "markers": markers, "spec": dict(self.spec)}
        if self.points:  # (built-in pads' documents stay as they were)
            doc["points"] = [{"name": k, "xyz": v.tolist()} for k, v in self.points.items()]
        return doc
