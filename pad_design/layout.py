"""Exact 3D geometry of a pad in the pad frame P (metres): what ``pad.json`` holds.

Pad frame (DESIGN.md): origin at the pad centre on its surface, z up, x toward the right edge,
y toward the top edge as printed.  Every square's corners are listed in the order
top-left, top-right, bottom-right, bottom-left as printed, i.e. (-,+), (+,+), (+,-), (-,-),
which is also OpenCV ArUco's corner order and the ``c0..c3`` order of ``frames.csv``.
"""
from __future__ import annotations

from .geometry import MARKER_NAMES, PadGeometry
from .spec import PadSpec, hsv_of

PAD_JSON_VERSION = 1
# Where each marker sits, as (sign x, sign y): Top is the right-angle corner (top-left as printed).
MARKER_SIGNS = {"Top": (-1, 1), "Right": (1, 1), "Bottom": (-1, -1)}
# A finder marker's nested squares, as (name, side in modules, colour inside the square).
FINDER_SQUARES = (("outer", 7, "black"), ("ring_inner", 5, "white"), ("centre", 3, "black"))


def square_corners(cx: float, cy: float, side: float) -> list:
    """Corners (x, y, 0) of an axis-aligned square in the pad order TL, TR, BR, BL."""
    h = side / 2.0
    return [[cx - h, cy + h, 0.0], [cx + h, cy + h, 0.0], [cx + h, cy - h, 0.0], [cx - h, cy - h, 0.0]]


def _marker_set(set_name: str, size: float, quiet_modules: float, offset: float, kind: str, ids=None) -> list:
    module = size / 7.0 if kind == "finder" else size / 6.0
    out = []
    for i, name in enumerate(MARKER_NAMES):
        sx, sy = MARKER_SIGNS[name]
        cx, cy = sx * offset, sy * offset
        if kind == "finder":
            squares = [{"name": sq, "side_m": n * size / 7.0, "color_inside": col,
                        "corners": square_corners(cx, cy, n * size / 7.0)} for sq, n, col in FINDER_SQUARES]
        else:
            squares = [{"name": "outer", "side_m": size, "color_inside": "black",
                        "corners": square_corners(cx, cy, size)}]
        m = {"name": name, "set": set_name, "kind": kind, "center": [cx, cy, 0.0], "size_m": size,
             "module_m": module, "quiet_zone_m": quiet_modules * size / 7.0, "squares": squares}
        if ids is not None:
            m["aruco_id"] = int(ids[i])
        out.append(m)
    return out


def _nested_tags(total_m: float, ids) -> list:
    """The apriltag variant: a large tagCustom48h12 tag centred on the pad and a small one in its free
    centre (one fifth the size).  Each marker's square is the square the detector finds; its quiet
    zone reaches the tag's outer edge (the large one's also over a one-cell white margin)."""
    from .apriltag import BORDER_CELLS, CENTRE_CELLS, TOTAL_CELLS

    out = []
    for name, total, tid, margin in (("Large", total_m, ids[0], 1), ("Small", total_m * CENTRE_CELLS / TOTAL_CELLS,
                                                                     ids[1], 0)):
        cell = total / TOTAL_CELLS
        side = BORDER_CELLS * cell
        out.append({"name": name, "set": "tag", "kind": "apriltag", "center": [0.0, 0.0, 0.0], "size_m": side,
                    "module_m": cell, "quiet_zone_m": ((TOTAL_CELLS - BORDER_CELLS) / 2 + margin) * cell,
                    "aruco_id": int(tid),
                    "squares": [{"name": "outer", "side_m": side, "color_inside": "white",
                                 "corners": square_corners(0.0, 0.0, side)}]})
    return out


def aruco_dictionary_of(spec: dict, marker) -> str:
    """The cv2.aruco dictionary a marker of a pad is drawn from (the small nested one's is its own)."""
    if marker.set == "nested" and marker.name == "Small":
        return spec["aruco_nested_dictionary"]
    return spec["aruco_dictionary"]


def _nested_aruco(field_m: float, spec: PadSpec) -> list:
    """The aruco_nested variant: a large marker over the field (a one-cell white margin) and a small
    one of another dictionary in its white centre 2x2 cells, 0.63 of their width (so that each of
    them still reads white to the large marker's detector, and the small one has a white margin)."""
    import cv2

    big_cells = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, spec.aruco_dictionary)).markerSize + 2
    small_cells = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, spec.aruco_nested_dictionary)).markerSize + 2
    cell = field_m / (big_cells + 2)
    small = 2 * cell * 0.63
    out = []
    for name, side, module, quiet, mid in (("Large", big_cells * cell, cell, cell, spec.aruco_nested_ids[0]),
                                           ("Small", small, small / small_cells, cell - small / 2,
                                            spec.aruco_nested_ids[1])):
        out.append({"name": name, "set": "nested", "kind": "aruco", "center": [0.0, 0.0, 0.0], "size_m": side,
                    "module_m": module, "quiet_zone_m": quiet, "aruco_id": int(mid),
                    "squares": [{"name": "outer", "side_m": side, "color_inside": "black",
                                 "corners": square_corners(0.0, 0.0, side)}]})
    return out


def segmentation_range(rgb, hue_halfwidth_deg: float = 20.0, s_min: float = 0.45, v_min: float = 0.18) -> dict:
    """An OpenCV HSV range (H 0-180, S and V 0-255) around a colour, for ``cv2.inRange``.

    ``lo``/``hi`` may wrap around hue 0: then ``hue_wraps`` is true and the range is
    ``H >= lo[0] or H <= hi[0]``.
    """
    h, _, _ = hsv_of(rgb)
    lo_h = (h - hue_halfwidth_deg) % 360.0 / 2.0
    hi_h = (h + hue_halfwidth_deg) % 360.0 / 2.0
    return {"lo": [round(lo_h, 2), round(s_min * 255), round(v_min * 255)],
            "hi": [round(hi_h, 2), 255, 255], "hue_wraps": bool(lo_h > hi_h)}


FRAME_NOTE = "P: origin at pad centre on its surface, x to the right edge, y to the top edge, z up; metres"
CORNER_NOTE = "TL, TR, BR, BL as printed: (-x,+y), (+x,+y), (+x,-y), (-x,-y)"


def build_geometry(spec: PadSpec) -> PadGeometry:
    """The pad's features in the pad frame (the ``pad.json`` document, without texture info, validated)."""
    if spec.variant == "artwork":  # the user's image over the whole pad, and the points it names
        return PadGeometry.from_document({
            "version": PAD_JSON_VERSION, "frame": FRAME_NOTE, "corner_order": CORNER_NOTE, "variant": "artwork",
            "side_m": spec.side_m, "border_m": 0.0, "field_side_m": spec.side_m,
            "outer_corners": square_corners(0.0, 0.0, spec.side_m), "field_corners": square_corners(0.0, 0.0, spec.side_m),
            "border": None, "cue": None, "markers": [],
            "points": [{"name": k, "xyz": [float(x), float(y), 0.0]} for k, (x, y) in spec.artwork_points.items()],
            "spec": spec.to_jsonable()}, "pad layout")
    h = spec.side_m / 2.0
    f = h - spec.border_m
    size = spec.marker_size_m
    q = spec.quiet_zone_modules * size / 7.0
    offset = f - q - size / 2.0
    markers = []
    if spec.variant in ("paper", "nested"):
        markers += _marker_set("corner", size, spec.quiet_zone_modules, offset, "finder")
    if spec.variant == "nested":
        n = spec.nested_marker_size_m
        nblock = n * (1 + 2 * spec.quiet_zone_modules / 7.0)
        markers += _marker_set("centre", n, spec.quiet_zone_modules, nblock / 2.0, "finder")
    if spec.variant == "aruco":
        markers += _marker_set("corner", size, spec.quiet_zone_modules, offset, "aruco", spec.aruco_ids)
    if spec.variant == "aruco_nested":
        markers += _nested_aruco(2 * f, spec)
    if spec.variant == "apriltag":
        markers += _nested_tags(spec.apriltag_total_m or 2 * f / 1.2, spec.apriltag_ids)
    b = spec.border_m
    cue = {"kind": "corner_square", "corner": "bottom_right", "color_rgb": list(spec.cue_color),
           "corners": square_corners(h - b / 2.0, -h + b / 2.0, b),
           "segmentation_hsv": segmentation_range(spec.cue_color, 20.0, 0.45, 0.25),
           "note": "The bottom-right border square (the corner without a marker) has the cue colour; "
                   "the other three border corners have the border colour, so the outline alone tells yaw."}
    return PadGeometry.from_document({
        "version": PAD_JSON_VERSION,
        "frame": FRAME_NOTE,
        "corner_order": CORNER_NOTE,
        "variant": spec.variant,
        "side_m": spec.side_m,
        "border_m": spec.border_m,
        "field_side_m": 2 * f,
        "outer_corners": square_corners(0.0, 0.0, spec.side_m),
        "field_corners": square_corners(0.0, 0.0, 2 * f),
        "border": {"color_rgb": list(spec.border_color),
                   "dark_color_rgb": [round(c * spec.border_dark_factor) for c in spec.border_color],
                   "solid_band_m": spec.border_m / 4.0, "checker_m": spec.border_checker_m,
                   "segmentation_hsv": segmentation_range(spec.border_color)},
        "cue": cue,
        "markers": markers,
        "spec": spec.to_jsonable(),
    }, "pad layout")
