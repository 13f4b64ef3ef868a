"""The pad spec: a validated description of a landing pad (defaults: the paper's 0.85 m pad)."""
from __future__ import annotations

import colorsys
import math
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator


def parse_color(value) -> tuple:
    """``'#rrggbb'`` or ``[r, g, b]`` (0-255) -> ``(r, g, b)`` ints; ``ValueError`` otherwise."""
    if isinstance(value, str):
        s = value.strip().lstrip("#")
        if len(s) != 6 or any(c not in "0123456789abcdefABCDEF" for c in s):
            raise ValueError(f"{value!r} is not a colour: use '#rrggbb' or [r, g, b] with 0-255 values")
        return tuple(int(s[i:i + 2], 16) for i in (0, 2, 4))
    if isinstance(value, (list, tuple)) and len(value) == 3:
        out = []
        for v in value:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v <= 255 or int(v) != v:
                raise ValueError(f"{value!r} is not a colour: components must be integers 0-255")
            out.append(int(v))
        return tuple(out)
    raise ValueError(f"{value!r} is not a colour: use '#rrggbb' or [r, g, b] with 0-255 values")


def hsv_of(rgb) -> tuple:
    """(hue degrees, saturation 0-1, value 0-1)."""
    h, s, v = colorsys.rgb_to_hsv(*(c / 255.0 for c in rgb))
    return h * 360.0, s, v


# Hues that natural ground takes (soil, sand, dry and green grass, moss): a border colour must avoid them.
NATURAL_GROUND_HUES_DEG = (15.0, 170.0)


def _aruco_dictionary(name: str, field: str):
    import cv2

    if not name.startswith("DICT_") or not hasattr(cv2.aruco, name):
        raise ValueError(f"{field}: {name!r} is not a cv2.aruco dictionary")
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))


class PadSpec(BaseModel):
    """Everything that defines a pad.  Lengths in metres, colours as '#rrggbb' or [r, g, b]."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, validate_default=True)

    variant: Literal["paper", "nested", "aruco", "apriltag", "aruco_nested", "artwork"] = Field(
        "paper", description="paper: three corner finder markers; nested: plus a small set in the centre "
        "for low altitude; aruco: OpenCV ArUco markers of the same outer size instead of finder markers; "
        "apriltag: a recursive AprilTag pad (a large tagCustom48h12 tag over the field, a small one in its centre); "
        "aruco_nested: a large ArUco marker over the field and a small one of another dictionary in its centre; "
        "artwork: your own image over the whole pad (artwork_image), with the points a localizer may use "
        "(artwork_points); hvloc's border, cue and markers are not drawn")
    side_m: float = Field(0.85, gt=0, le=20, description="side of the square pad")
    border_m: float = Field(0.10, gt=0, description="width of the coloured border")
    border_color: tuple = Field("#ff30e0", description="saturated border colour natural ground lacks")
    border_dark_factor: float = Field(0.1, ge=0.0, lt=0.9,
                                      description="value of the border's dark checker cells, relative")
    border_checker_m: float = Field(0.0125, gt=0, description="cell of the border's inner checker")
    cue_color: tuple = Field("#ffd200", description="colour of the yaw cue (one border corner square)")
    marker_size_m: float = Field(0.12, gt=0, description="outer side of a finder marker (7 modules)")
    quiet_zone_modules: float = Field(1.0, ge=1.0, le=4.0, description="white margin around each marker")
    nested_marker_size_m: float = Field(0.035, gt=0, description="finder markers of the centre set (nested)")
    aruco_dictionary: str = Field("DICT_4X4_50", description="cv2.aruco predefined dictionary (aruco)")
    aruco_ids: tuple = Field((0, 1, 2), description="ArUco ids at Top, Right, Bottom (aruco)")
    aruco_nested_ids: tuple = Field((16, 1), description="ids of the large marker (aruco_dictionary; its centre 2x2 "
                                    "cells must be white) and of the small one in them (aruco_nested_dictionary)")
    aruco_nested_dictionary: str = Field("DICT_5X5_50", description="the small marker's cv2.aruco dictionary "
                                         "(aruco_nested): another than the large one's, so that each detector "
                                         "keeps its own marker (one detector drops a candidate inside another)")
    apriltag_ids: tuple = Field((0, 1), description="tagCustom48h12 ids of the large and the nested small tag (apriltag)")
    apriltag_total_m: float | None = Field(None, gt=0, description="outer side of the large AprilTag, data ring "
                                           "included (10 cells; its detected square is 6); default: the field less "
                                           "a one-cell white margin on each side (apriltag)")
    artwork_image: str | None = Field(None, description="artwork: the pad's image file (PNG, JPEG; square, it "
                                      "covers the whole side_m x side_m pad, top edge as printed at the top), a "
                                      "path absolute or relative to the working directory")
    artwork_points: dict[str, tuple[float, float]] = Field(
        default_factory=dict, description="artwork: named points of the artwork a localizer may use, (x, y) in "
        "metres in the pad frame (origin at the centre, x to the right edge, y to the top edge as printed)")
    texture_seed: int = Field(7, ge=0)
    texture_min_feature_m: float = Field(0.004, gt=0, description="smallest texture element")
    texture_max_feature_m: float = Field(0.03, gt=0, description="largest texture element")
    texture_density: float = Field(0.26, gt=0.02, lt=0.6, description="share of the field area the "
                                   "texture elements cover before merging")

    @field_validator("border_color", "cue_color", mode="before")
    @classmethod
    def _color(cls, v):
        return parse_color(v)

    @field_validator("border_color")
    @classmethod
    def _saturated(cls, v):
        h, s, val = hsv_of(v)
        lo, hi = NATURAL_GROUND_HUES_DEG
        if s < 0.6 or val < 0.5:
            raise ValueError(f"border colour {v} is not saturated and bright enough "
                             f"(saturation {s:.2f} >= 0.6 and value {val:.2f} >= 0.5 needed)")
        if lo <= h <= hi:
            raise ValueError(f"border colour {v} has hue {h:.0f} deg, which natural ground has "
                             f"({lo:.0f}-{hi:.0f} deg); pick a magenta, purple or blue")
        return v

    @field_validator("cue_color")
    @classmethod
    def _cue_distinct(cls, v):
        h, s, val = hsv_of(v)
        if s < 0.6 or val < 0.5:
            raise ValueError(f"cue colour {v} must be saturated (>= 0.6) and bright (>= 0.5)")
        return v

    @field_validator("aruco_ids")
    @classmethod
    def _ids(cls, v):
        v = tuple(int(i) for i in v)
        if len(v) != 3 or len(set(v)) != 3 or min(v) < 0:
            raise ValueError("aruco_ids must be three distinct non-negative ids")
        return v

    @model_validator(mode="after")
    def _fits(self):
        if self.variant == "artwork":
            if not self.artwork_image:
                raise ValueError("artwork_image: the artwork variant needs its image file")
            h = self.side_m / 2.0
            for name, (x, y) in self.artwork_points.items():
                if not (math.isfinite(x) and math.isfinite(y)) or abs(x) > h or abs(y) > h:
                    raise ValueError(f"artwork_points: {name!r} at ({x}, {y}) lies outside the {self.side_m} m pad "
                                     f"(|x|, |y| <= {h})")
            return self  # hvloc's border, cue and markers are not drawn: nothing of theirs to fit
        if self.artwork_image is not None or self.artwork_points:
            raise ValueError("artwork_image, artwork_points: only for variant artwork")
        if self.border_m * 4 > self.side_m:
            raise ValueError(f"border_m: {self.border_m} m is more than a quarter of side_m {self.side_m} m")
        hue_b, hue_c = hsv_of(self.border_color)[0], hsv_of(self.cue_color)[0]
        dh = min(abs(hue_b - hue_c), 360 - abs(hue_b - hue_c))
        if dh < 60:
            raise ValueError(f"cue_color: hue within {dh:.0f} deg of the border colour; needs >= 60 deg")
        if self.texture_min_feature_m >= self.texture_max_feature_m:
            raise ValueError("texture_min_feature_m: must be smaller than texture_max_feature_m")
        field = self.side_m - 2 * self.border_m
        block = self.marker_size_m * (1 + 2 * self.quiet_zone_modules / 7.0)
        if 2 * block > field + 1e-12:
            raise ValueError(f"marker_size_m: markers of {self.marker_size_m} m with their quiet zones "
                             f"({block:.3f} m each) overlap: two must fit across the {field:.3f} m field")
        if self.border_checker_m * 2 > self.border_m:
            raise ValueError("border_checker_m: must be at most half of border_m")
        if self.variant == "nested":
            nblock = self.nested_marker_size_m * (1 + 2 * self.quiet_zone_modules / 7.0)
            free = field - 2 * block
            if 2 * nblock > free + 1e-12:
                raise ValueError(f"nested_marker_size_m: the centre set ({2 * nblock:.3f} m across) does not "
                                 f"fit between the corner markers ({free:.3f} m free)")
        if self.variant == "apriltag":
            from .apriltag import CODES

            if len(set(self.apriltag_ids)) != 2 or any(not 0 <= i < len(CODES) for i in self.apriltag_ids):
                raise ValueError(f"apriltag_ids: two distinct ids from 0 to {len(CODES) - 1}")
            if self.apriltag_total_m is not None and self.apriltag_total_m * 1.2 > field + 1e-12:
                raise ValueError(f"apriltag_total_m: {self.apriltag_total_m} m with its one-cell white margins "
                                 f"does not fit the {field:.3f} m field")
        if self.variant == "aruco":
            n = _aruco_dictionary(self.aruco_dictionary, "aruco_dictionary").bytesList.shape[0]
            if max(self.aruco_ids) >= n:
                raise ValueError(f"aruco_ids: {self.aruco_dictionary} has ids 0-{n - 1}")
        if self.variant == "aruco_nested":
            import cv2

            big = _aruco_dictionary(self.aruco_dictionary, "aruco_dictionary")
            small = _aruco_dictionary(self.aruco_nested_dictionary, "aruco_nested_dictionary")
            if self.aruco_nested_dictionary == self.aruco_dictionary:
                raise ValueError("aruco_nested_dictionary: must differ from aruco_dictionary (one detector drops "
                                 "a marker candidate that holds another)")
            i, j = (int(v) for v in self.aruco_nested_ids)
            if not (0 <= i < big.bytesList.shape[0] and 0 <= j < small.bytesList.shape[0]):
                raise ValueError(f"aruco_nested_ids: ids in {self.aruco_dictionary} and {self.aruco_nested_dictionary}")
            cells = big.markerSize + 2
            bits = cv2.aruco.generateImageMarker(big, i, cells, borderBits=1) > 127
            c = cells // 2
            if cells % 2 or not bits[c - 1:c + 1, c - 1:c + 1].all():
                raise ValueError(f"aruco_nested_ids: marker {i} of {self.aruco_dictionary} has no white 2x2 centre "
                                 "to hold the small marker")
        return self

    def to_jsonable(self) -> dict:
        d = self.model_dump()
        d["border_color"] = "#%02x%02x%02x" % self.border_color
        d["cue_color"] = "#%02x%02x%02x" % self.cue_color
        d["aruco_ids"] = list(self.aruco_ids)
        d["aruco_nested_ids"] = list(self.aruco_nested_ids)
        d["apriltag_ids"] = list(self.apriltag_ids)
        d["artwork_points"] = {k: list(v) for k, v in self.artwork_points.items()}
        if self.variant != "artwork":  # built-in pads' documents stay as they were
            del d["artwork_image"], d["artwork_points"]
        return d
