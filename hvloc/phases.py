"""The three phases as plain functions, usable alone: outline detection (Approaching), finder
markers (Adjustment) and the flow tracker (Touchdown).  Each detector returns correspondences
(pad points in metres, image pixels) or ``None`` with a reason; pose comes from :mod:`.pose`."""
from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from . import markers as mk
from .features import (_inside, band_centroid_offsets, banded_edge_offsets, banded_profile_offsets, refine_quad,
                       refine_quads, rise_offsets, sample_at, srgb_to_linear, step_blur, ncc as _ncc)
from pad_design.geometry import PadGeometry

from .geometry import Camera, ideal_grid, invert, rotation_angle, so3_exp, transform_points
from .pose import robust_sigma
from .work import ImageWork, array_key


@dataclass
class Detection:
    """Correspondences found in one image: ``pts_P`` (N, 3) metres, ``px`` (N, 2) pixels."""

    pts_P: np.ndarray
    px: np.ndarray
    kind: str
    info: dict = field(default_factory=dict)


def _signed_area(q: np.ndarray) -> float:
    x, y = q[:, 0], q[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _crop(img: np.ndarray, roi):
    """``(view, x0, y0)``: the region of interest (x0, y0, x1, y1), or the whole image."""
    if roi is None:
        return img, 0, 0
    x0, y0, x1, y1 = roi
    return img[y0:y1, x0:x1], x0, y0


def _hsv_mask(hsv: np.ndarray, rng) -> np.ndarray:
    lo, hi = rng.lo, rng.hi
    if rng.hue_wraps:
        a = cv2.inRange(hsv, np.array([lo[0], lo[1], lo[2]]), np.array([180, hi[1], hi[2]]))
        b = cv2.inRange(hsv, np.array([0, lo[1], lo[2]]), np.array([hi[0], hi[1], hi[2]]))
        return a | b
    return cv2.inRange(hsv, lo, hi)


# ----------------------------------------------------------------------------- Approaching

CENTROID_SIGMA_PER_SMEAR = 0.1  # a centroid-placed corner's noise (px) per px of smear
# a profile-fitted one's: soft_gusty_deck's Adjustment poses (mostly such outlines) stated 2.4x the
# error they made at 0.1, 1.5x at 0.04 (benchmarks/blur_bias.py: 0.1-0.3 px of error under 6-16 px)
PROFILE_SIGMA_PER_SMEAR = 0.04
# a corner of the colour hull itself (no side fitted, no centroid read): the colour is smeared past the
# pad along the motion, and the hull reaches as far as it shows.  unseen49's fisheye at 1-2.5 m under
# 7-19 px of smear (as read): corners 0.3-1.9 smears off per axis, median 0.6 (stated 0.1, a pose at
# 1.2 m 69 mm off with 13 mm stated: NEES 21, and the flow's keyframe made from it)
HULL_SIGMA_PER_SMEAR = 0.6
# a corner of sides an edge fit placed under smear (past LIGHT_FIT_SMEAR_PX: where no centroid or
# fitted profile placed them, the pad cut by the image's edge or a stretch unread): fitted in light
# up to SMEARED_PX, in display values past it, where a smeared edge's half level lies toward its
# dark side.  On 16 scenes (conditions and seven unseen ones, against the raw labels) the larger
# axis's error of corners in view was 0.16 smears in the median, 0.32 at the 90th percentile under
# 3-5 px of smear (1,369 corners), 0.15 and 0.3-0.4 under 5-10 px (3,400).  Stated at the centroid's
# 0.1 past SMEARED_PX, at the 0.3 px floor alone below it: unseen51's cut pad at 1 m, a side 3.8 px
# out under 9.7 px of smear, its hidden corner 7 px out, stated 1 and 1.3 px (NEES 13); unseen47's at
# 2 m under 4.6 px, corners 2.2 px out stated 0.3 px (NEES 31)
EDGE_SIGMA_PER_SMEAR = 0.2


@dataclass
class OutlineQuad:
    """The pad's outline found in an image, not yet named: ``quad_px`` (4, 2) sub-pixel corners in
    image order (counter-clockwise on screen), ``cue`` (2, 4) how clearly each corner holds the cue,
    by colour and by brightness (:func:`_cue_scores`)."""

    quad_px: np.ndarray
    cue: np.ndarray
    side_px: float
    line_rms: object
    field_px: np.ndarray | None = None  # the field's corners, where they are to be used instead (:func:`_field_quad`)
    sigma_scale: np.ndarray | None = None  # (4,) how much less sure each corner is than a seen one (:func:`_corner_sigma_scale`)
    smear_px: float = 0.0  # how far motion smears its edges (px, in luma: :func:`_smear_near`)
    sigma_per_smear: float = CENTROID_SIGMA_PER_SMEAR  # a smear-placed corner's noise (px) per px of smear (:func:`_deblurred`)
    edge_fitted: bool = False  # its sides placed by an edge fit (no centroid, profile or hull): it holds to EDGE_FIT_SMEAR_PX
    field_sigma_px: float = 0.0  # the noise field_px's corners carry beyond a found corner's (a loose fit's scatter)
    read_after_fit: bool = False  # read as the design only at a lower bar: it must read so where its design fit puts it
    # why its corners are a hull's alone (no side fitted: a cut pad's colour hull, a grey field's blob), where
    # they are: such an outline is taken only where its design fit places it
    hull_only: str = ""
    washed: bool = False  # its band washed out along a stretch, placed where its field and its colour agree (:func:`_field_rescue`)


def detect_outline(rgb: np.ndarray, pad_geometry: PadGeometry, camera: Camera | None = None, roi=None,
                   yaw_hint_corner0: np.ndarray | None = None, max_scale: int = 8) -> tuple:
    """The pad's outer corners (TL, TR, BR, BL) by colour segmentation.

    Returns ``(Detection | None, reason)``.  Decoys are rejected by shape (convex quad, side
    ratios), by how much of the quad is border colour (a pad is a ring, a decoy patch is solid),
    and the corner order comes from the yellow cue corner (bottom-right), or, when the cue cannot
    be read, from ``yaw_hint_corner0``: the predicted pixel of the TL corner.
    """
    found, why = find_outline(rgb, pad_geometry, camera, roi, max_scale)
    if found is None:
        return None, why
    return name_outline(found, pad_geometry, yaw_hint_corner0)


_LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)  # Rec. 709 / sRGB weights, on linear values
SWOLLEN_WHEN = ("its sides and its colour hull disagree", "its border band is missing along a side",
                "its border band is missing beside a corner", "its colour swells past its white field")
MISREAD_WHEN = ("its sides and its colour hull disagree", "its border band is missing along a side")
SIDES_NOT_FOUND = "its sides not found, and nothing smears them"
NO_QUADRILATERAL = "its sides, as placed, make no quadrilateral"
OCCLUDED_WHEN = ("no pad-coloured quadrilateral", "its border band is missing along a side",
                 "its border band is missing beside a corner", "its sides and its colour hull disagree",
                 SIDES_NOT_FOUND)


def find_outline(rgb: np.ndarray, pad_geometry: PadGeometry, camera: Camera | None = None, roi=None,
                 max_scale: int = 8, halved: bool | None = None) -> tuple:
    """``(OutlineQuad | None, reason)``: the image work of :func:`detect_outline` (segmentation,
    quad, sub-pixel sides, the cue colour at each corner), which no prior influences.  A pad with a
    corner hidden by something in the scene is looked for when no whole one is found
    (:func:`_occluded_outline`).  ``halved``: :func:`chroma_halved` of the frame, where already told
    (it is the frame's, not the window's: told once, whatever is searched)."""
    if halved is None:
        halved = chroma_halved(rgb)
    found, why = _whole_outline(rgb, pad_geometry, camera, roi, max_scale, halved=halved)
    swollen = found is None and why in SWOLLEN_WHEN
    if found is None and why in OCCLUDED_WHEN:
        hidden, why_hidden = _occluded_outline(rgb, pad_geometry, camera, roi, max_scale)
        if hidden is not None:
            return hidden, "ok"
        if why_hidden:
            why = f"{why} (and {why_hidden})"
    if swollen:  # neither whole nor partly hidden: the colour grown into shadow may have swollen
        again, _ = _whole_outline(rgb, pad_geometry, camera, roi, max_scale, shadow=False, halved=halved)
        if again is not None and _field_agrees(rgb, again.quad_px, pad_geometry, camera):
            return again, "ok"
    return found, why


def _segment(rgb: np.ndarray, pad_geometry: PadGeometry, roi, max_scale: int, shadow: bool = True) -> tuple:
    """``(img, x0, y0, scale, small, hsv, mask)``: the searched area, its copy reduced ``scale`` times
    (when large: the corners are refined at full resolution afterwards, so this costs no accuracy),
    and the border colour's mask there, in shadow too."""
    img, x0, y0 = _crop(rgb, roi)
    scale = 1
    while scale < max_scale and img.shape[1] // (2 * scale) >= 480 and img.shape[0] // (2 * scale) >= 270:
        scale *= 2
    small = img if scale == 1 else cv2.resize(img, (img.shape[1] // scale, img.shape[0] // scale),
                                                interpolation=cv2.INTER_AREA)
    hsv = cv2.cvtColor(small, cv2.COLOR_RGB2HSV)
    border = pad_geometry.border.segmentation_hsv
    mask = _hsv_mask(hsv, border)
    box = _around(mask) if shadow else None
    if box is not None:  # in shadow, colour read relative to brightness (the shadowed part of a pad lies next to its lit part)
        sl = np.s_[box[1]:box[3], box[0]:box[2]]
        mask[sl] = _shadowed_too(small[sl], hsv[sl], mask[sl], border, pad_geometry.border.color_rgb)
    return img, x0, y0, scale, small, hsv, mask


def _whole_outline(rgb: np.ndarray, pad_geometry: PadGeometry, camera: Camera | None = None, roi=None,
                   max_scale: int = 8, shadow: bool = True, halved: bool = True) -> tuple:
    """:func:`find_outline` for a pad of which at least a corner and its sides' stretches toward
    the others are in view (a corner may be out of the image); ``halved``: the frame's chroma is
    (:func:`chroma_halved`)."""
    if min(_crop(rgb, roi)[0].shape[:2]) < 8:
        return None, "image too small"
    img, x0, y0, scale, small, hsv, mask = _segment(rgb, pad_geometry, roi, max_scale, shadow)
    border = pad_geometry.border.segmentation_hsv
    # The cue square is left out of the mask: whatever of the ground has its colour (brown soil
    # lies in a yellow cue's range) would join it and swell the hull.  Its corner comes back where
    # the two sides beside it meet (:func:`_hull_quad`).  The sides of the searched area that are
    # the image's own edges are where a pad can be cut off.
    H_img, W_img = rgb.shape[:2]
    cut_edges = (x0 == 0, y0 == 0, x0 + img.shape[1] >= W_img, y0 + img.shape[0] >= H_img)
    whole = _best_ring(mask, pad_geometry, cut_edges, scale=scale)
    tries = [] if whole is None else [whole]
    if whole is None or _at_cut(whole, small.shape, cut_edges).any():
        # the pad running out of the image: three corners and the sides toward the fourth (also when a
        # ring read whole touches the image's edge, and its outline is not found: a corner just out of
        # view is read either way, a piece of a cut ring only as cut)
        other = _best_ring(mask, pad_geometry, cut_edges, cut=True, scale=scale)
        if other is None:
            # nothing saturated enough: glare on a glossy pad adds white light, which keeps the hue and
            # the colour's own chroma but takes half the saturation (magenta 198,51,176 -> 232,138,218
            # under noon glare); then the colour is read relative to brightness everywhere, as in shadow
            # (the checker's dark cells wash out first: the ring may be the solid band alone)
            band = 1.0 - (1.0 - 2 * pad_geometry.border.solid_band_m / pad_geometry.side_m) ** 2
            for bright in (None, GLARE_MIN_CHROMA):  # the washed-out pale last (GLARE_MIN_CHROMA)
                ev = _colour_evidence(small, hsv, border, pad_geometry.border.color_rgb, bright_chroma=bright)
                # read whole, then cut by the image's edge, as the plain mask is
                other = _best_ring(ev, pad_geometry, cut_edges, min_share=0.5 * band, scale=scale)
                if other is None:
                    other = _best_ring(ev, pad_geometry, cut_edges, cut=True, min_share=0.5 * band, scale=scale)
                if other is not None:
                    break
        tries += [] if other is None else [other]
    if not tries:
        if scale > 1:  # far away the pad may be too small in the reduced copy: look at full size
            return _whole_outline(rgb, pad_geometry, camera, roi, max_scale=1, shadow=shadow, halved=halved)
        return None, "no pad-coloured quadrilateral"
    for quad in tries:
        if scale > 1 and np.linalg.norm(quad[0] - quad[2]) < 45:
            # small in the reduced copy: its corners would be too coarse to start from
            return _whole_outline(rgb, pad_geometry, camera, roi, max_scale=1, shadow=shadow, halved=halved)
        found, why = _outline_from_ring(rgb, quad, small, scale, (x0, y0), cut_edges, pad_geometry, camera, halved)
        if found is not None:
            return found, why
    return found, why


def _outline_from_ring(rgb: np.ndarray, quad: np.ndarray, small: np.ndarray, scale: int, origin, cut_edges,
                       pad_geometry: PadGeometry, camera: Camera | None, halved: bool = True) -> tuple:
    """``(OutlineQuad | None, reason)`` from a ring's quadrilateral ``quad`` found in ``small`` (the
    searched area reduced ``scale`` times, at ``origin`` in the image)."""
    # a corner out of view, or at the image's edge (a hull that ran along it a little: the corner just
    # out of view, its sides there fitted on the stretches in view)
    cut = not ((quad >= -0.5) & (quad <= [small.shape[1] - 0.5, small.shape[0] - 0.5])).all() \
        or bool(_at_cut(quad, small.shape, cut_edges).any())
    if _signed_area(quad) < 0:
        quad = quad[::-1]
    if scale > 1:  # sharpen the coarse quad where it was found before going to full resolution
        sq, _ = refine_quad(_border_channel(small), quad, half_width=2.0)
        if sq is not None and np.max(np.linalg.norm(sq - quad, axis=1)) < 2.5:
            quad = sq
    quad = (quad + 0.5) * scale - 0.5 + np.asarray(origin)
    # sub-pixel first: edges on a channel linear in the colours, where the border is bright; the
    # cue is read afterwards, at full resolution (far away its square is a few pixels, and a
    # downscaled copy blends it away), where the exact quad puts it.
    side_px = _mean_side(quad)
    found, why = _outline_from_hull(rgb, quad, side_px, cut, pad_geometry, camera, halved=halved)
    if found is None and why in MISREAD_WHEN:
        # glare washes out the border's rim and the colour hull lies a pixel or two inside a far
        # pad: the sides' coarse profiles then hold its whole 3-4 px border, and by their own ends
        # half of a side's crossings were the border's inner edge (a side tilted 7 degrees).  Once
        # more from the same hull, the coarse fit told the border's polarity.  (Only then: on clean
        # far outlines the plain fit's corners are a little more precise, which the four-corner
        # tilt without an IMU needs.)
        again, _ = _outline_from_hull(rgb, quad, side_px, cut, pad_geometry, camera, polarity=True, halved=halved)
        if again is not None:
            return again, "ok"
    return found, why


def _outline_from_hull(rgb: np.ndarray, quad: np.ndarray, side_px: float, cut: bool, pad_geometry: PadGeometry,
                       camera: Camera | None, polarity: bool = False, halved: bool = True) -> tuple:
    """``(OutlineQuad | None, reason)``: the sides fitted from the colour hull's ``quad`` (full-resolution
    pixels; ``cut``: a corner out of view) and the checks a found outline must pass; ``polarity``:
    the coarse side fit knows the border is brighter than what lies beyond it (:func:`_fit_sides`);
    ``halved``: the frame's chroma is (:func:`chroma_halved`: a sharp side is then placed in display
    values)."""
    refined, res, f, chan, (bx0, by0) = _fit_sides(rgb, quad, side_px, pad_geometry, camera, polarity=polarity)
    cam_s = _shifted(camera, bx0, by0)
    field, edge, field_noise = None, False, 0.0
    washed = False  # its band washed out where its field and colour agree (_field_rescue)
    if cut and (refined is None or _too_smeared(rgb, refined + [bx0, by0], pad_geometry, camera, limit_px=EDGE_FIT_SMEAR_PX)):
        # smeared past the edge fit's window (it holds to twice its window): the border's centroid
        # over the stretches of each side that are in view, the hidden corner where two sides meet
        start = quad if refined is None else refined + [bx0, by0]
        smeared, smear, fitted, _ = _smeared_in_view(rgb, start, pad_geometry, camera, in_view=True)
        # a corner in view must agree with the hull; the hidden one, where two of the swollen hull's
        # sides were carried out of view, up to the smear further (the hull's a few pixels wide of
        # the pad along a smeared side turns its corner by as much: 8-17 px under 14 px of smear,
        # with the corner read from the centroids 4-7 px from the labelled one)
        if smeared is None or (np.linalg.norm(smeared - quad, axis=1)
                               > max(3.0, 0.1 * side_px) + np.where(_seen(smeared, rgb.shape), 0.0, smear)).any() \
                or _seen(smeared, rgb.shape).sum() < 3:
            if refined is None and _seen(quad, rgb.shape).sum() == 3 and not smear > SMEARED_PX:  # (read just above)
                # a sharp pad whose side toward the hidden corner is in view over a few pixels only (a
                # corner just out of view: too short a stretch to fit a line on, fz310's ~13 px): its
                # colour hull's corners, three in view within a few pixels of the pad's, to be placed
                # by its design over the pixels in view (the localizer takes it only so placed)
                got, why = _outline_quad(rgb, quad, pad_geometry, camera, side_px, float("inf"), None, cut, smear)
                return (None, why) if got is None else (replace(
                    got, hull_only="pad cut by the image's edge, its side toward the hidden corner too short to fit"), "ok")
            return None, ("pad cut by the image's edge, and its sides there not found" if refined is None
                          else "pad cut by the image's edge and smeared by motion")
        return _outline_quad(rgb, smeared, pad_geometry, camera, side_px, res, None, cut, smear, fitted)
    if refined is None:
        # too few edge points on a side (blur): the hull's corners, for what they are worth, unless
        # the border's profile says where it lies under the blur
        smeared, smear, _, per_smear = _deblurred(rgb, quad, pad_geometry, camera)
        if smeared is None and not smear > SMEARED_PX:
            # but nothing smears it: something hides a stretch of a side (a box over two corners,
            # whose hull's corner lay 35 px from the pad's, taken as it was)
            return None, SIDES_NOT_FOUND
        if smeared is None:  # the hull's own corners: its colour smeared past the pad along the motion
            refined, per_smear = quad, HULL_SIGMA_PER_SMEAR
        else:
            refined = smeared
    elif np.max(np.linalg.norm(refined + [bx0, by0] - quad, axis=1)) > max(HULL_SLACK_PX, 0.1 * side_px):
        return None, "its sides and its colour hull disagree"
    else:
        # motion blur wider than the fit's window leaves no edge to fit: the border's centroid tells
        # where it is; otherwise the border's own profile, not a half level, says where its edge is
        # (placed by the centroid: the border's profile is fitted once, where it is read again below)
        smeared, smear, _, per_smear = _deblurred(rgb, refined + [bx0, by0], pad_geometry, camera, profile=False,
                                                  min_blur_px=LIGHT_FIT_SMEAR_PX)
        reach = smeared is not None and smear <= SMEARED_PX  # (within an edge fit's reach: placed if fitted)
        if smeared is None and _near_edge(refined + [bx0, by0], rgb.shape, 20.0):
            # the cross-profiles of some stretch run out of the image: the stretches in view
            smeared, smear, _, per_smear = _smeared_in_view(rgb, refined + [bx0, by0], pad_geometry, camera,
                                                           min_blur_px=5.0)
        unresolved = smear > max(STRUCTURE_SMEAR_PX, UNRESOLVED_SMEAR * float(_bands_px(quad, pad_geometry)[:, 1].min()))
        if smeared is None and (smear > EDGE_FIT_SMEAR_PX or unresolved):
            # no edge to fit and no centroid to read: fitted as sharp edges, such sides lay half the
            # smear out (unseen18: the pad read 6 % large under 43 px of smear, a false accept); so
            # too where the smear is over twice the border's width (soft_gusty_deck: a 34 px pad under
            # a 2 px lens blur read 9.9 px, one of its centroids read 33 px off, and the edge fit put
            # its corners 2-5 px out, the height 11.3 % low, "ok"), past what a sharp small pad's own
            # structure reads (a 24 px JPEG pad: 5.3 px, its sides fitted and mended by its field)
            return None, TOO_SMEARED
        if smeared is not None:  # (the band's check reads half a band either side of a sharp edge)
            # once more from there: a smeared side that was pixels out shifted the others' stretches
            again, smear_again, _, per_again = _deblurred(rgb, smeared, pad_geometry, camera, min_blur_px=0.0)
            if reach:
                # within an edge fit's reach the border's fitted profile places it (an edge fit in light
                # put a small pad's corners 1-2.5 px off under 4.5 px of motion, its solid band 1.7 px
                # wide: the fit 0.1-0.5 px); where the profile is not fitted (the noise stated says how
                # the sides were placed) the edge fit does, as before
                if again is not None and per_again == PROFILE_SIGMA_PER_SMEAR and smear_again > LIGHT_FIT_SMEAR_PX:
                    refined, smear, per_smear = again, smear_again, per_again
                else:
                    smeared, per_smear = None, CENTROID_SIGMA_PER_SMEAR
            elif smear_again > SMEARED_PX or smear > EDGE_FIT_SMEAR_PX:
                refined, smear = (smeared if again is None else again), smear_again
                per_smear = per_smear if again is None else per_again
            else:
                # read around where the centroid put it, the pad is sharp: the smear was read off
                # sides that were not the pad's (a box's edge across its corner read 5.04 px, the
                # centroid then put that corner 10 px out, "ok"; read again there, 2.3 px).  Not
                # past what structure can widen an edge by: under 30-45 px of smear a placed pad's
                # field edge is so shallow that the field's texture is steeper (read again, 2.7 px)
                smeared = smear = None
                per_smear = CENTROID_SIGMA_PER_SMEAR
        if smeared is None:
            edge = True
            if smear is not None and smear > LIGHT_FIT_SMEAR_PX:
                per_smear = EDGE_SIGMA_PER_SMEAR
            # a blur of light (a soft lens, motion) shows in luma and is symmetric in light: the edge is
            # fitted there (fitted in display values, a 1 px lens blur put a 40 px pad's corners 3.7 %
            # of its half side out, 0.3 % in light: benchmarks/blur_bias.py); JPEG smears chroma in
            # display values and leaves luma sharp: there it is fitted in those values, as they smear.
            # (Past the smear the edge fit is made for, where the centroid could not place the pad, as
            # before: fitted in light such sides passed the band's check 3 px out, in display values not)
            # Where the frame's chroma is whole (not compressed), a sharp edge is placed in light too:
            # a frame's pixels sum light, and fitted in display values a sharp pad's corners lay 0.1-0.3
            # px outward together on every dataset (the height as much low: 0.4-1.1 % at 30-60 px).  Not
            # past SMEARED_PX (above): placed in light there, a 60 px pad cut by the image's edge under
            # 10 px of smear was posed 0.36 m off at 9 m, "ok" (test_a_far_pad_cut_by_the_edge_...)
            soft = smear is not None and LIGHT_FIT_SMEAR_PX < smear <= SMEARED_PX
            light = soft or (not (smear is not None and smear > SMEARED_PX) and not halved)
            refined = _on_banded_edge(_border_channel(srgb_to_linear(f)) if light else chan, refined, pad_geometry,
                                      cam_s) + [bx0, by0]
            why = "its border band is missing along a side" if _band_missing(rgb, refined, pad_geometry, camera) \
                else "its border band is missing beside a corner" if _corner_missing(rgb, refined, pad_geometry, camera) \
                else None
            if why is not None:
                rescued = None if cut else _field_rescue(f, refined - [bx0, by0], pad_geometry, cam_s)
                if rescued is None:
                    return None, why
                refined, field, washed = rescued[0] + [bx0, by0], rescued[1], rescued[2]  # (the field is kept in the fit's window)
                smear = None  # (read on a swollen quad: read again where the field puts the pad)
        # (under a blur past an edge fit's reach the field's luma edge is smeared as much as the colour's;
        # within it, JPEG may smear the colour further, and the field's luma edges, where found, place
        # the pad: unseen49's 76 px pads at 10 m through JPEG 55 under 3.3-3.8 px of smear, placed by
        # the border's fitted profile, were posed 2.4-2.9 % of the height off, by the field 0.7-0.9 %)
        if (smeared is None or reach) and field is None:
            field, far, fitted, outside, field_noise = _field_quad(f, refined - [bx0, by0], pad_geometry, cam_s)
            if field is None and not cut and outside > max(FIELD_OUTSIDE_PX, FIELD_OUTSIDE_SHARE * side_px):
                return None, f"its white field lies {outside:.1f} px outside where its colour puts it"
            if (far or fitted is None) and not cut:
                # the colour swelled further than a corner's move may mend, or so far that the field
                # was out of the fit's reach: the field, found further in, says where the pad is
                rescued = _field_rescue(f, refined - [bx0, by0], pad_geometry, cam_s)
                if rescued is not None:
                    refined, field, smear, field_noise, washed = rescued[0] + [bx0, by0], rescued[1], None, 0.0, rescued[2]
                elif far:
                    return None, "its colour swells past its white field"
    found, why = _outline_quad(rgb, refined, pad_geometry, camera, side_px, res,
                               None if field is None else field + [bx0, by0], cut, smear, per_smear=per_smear, edge=edge,
                               field_sigma=field_noise)
    return (replace(found, washed=True) if found is not None and washed else found), why


def _outline_quad(rgb, refined, geo: PadGeometry, camera: Camera | None, side_px, res, field, cut: bool,
                  smear: float | None = None, fitted: np.ndarray | None = None,
                  per_smear: float = CENTROID_SIGMA_PER_SMEAR, edge: bool = False, field_sigma: float = 0.0) -> tuple:
    """``(OutlineQuad | None, reason)`` of a quad found: the cue read, a hidden corner's noise scaled;
    ``smear``: the motion smear already read around it (read here when ``None``); ``fitted``: the
    stretch of each side its line was fitted on, when not all of it in view (:func:`_deblurred`);
    ``per_smear``: the noise of a corner placed under smear, px per px of it (:func:`_deblurred`);
    ``edge``: its sides placed by an edge fit."""
    if not _quad_shaped(refined):  # (whichever way its sides were placed)
        return None, NO_QUADRILATERAL
    cue = _cue_scores(rgb, refined, geo, camera)
    scale_sigma = _corner_sigma_scale(refined, rgb.shape, fitted=fitted) if cut else None
    if scale_sigma is not None and not np.isfinite(scale_sigma).all():
        return None, "pad cut by the image's edge, a side of its hidden corner out of view"
    if smear is None:
        smear = _smear_near(rgb, refined, geo, camera, 12.0)[2]
    return OutlineQuad(refined, cue, side_px, res, field, scale_sigma, smear, per_smear, edge, field_sigma), "ok"


def _seen(px: np.ndarray, shape, visible=None) -> np.ndarray:
    """(N,) pixels in the image and, with ``visible`` (a test of pixels), not hidden."""
    px = np.asarray(px, np.float64).reshape(-1, 2)
    ok = _inside(px, shape)
    return ok if visible is None else ok & visible(px)


def _occluded_outline(rgb: np.ndarray, geo: PadGeometry, camera: Camera | None, roi, max_scale: int) -> tuple:
    """``(OutlineQuad | None, reason)``: a pad with one corner hidden by something in the scene (a
    box, a leg), none found whole.  Its colour's hull is then cut by the occluder's edge: each of
    the hull's sides is tried as that cut, the rest of the hull read as a stretch of one side, two
    whole sides and a stretch of the fourth (:func:`_chain_quad`), the hidden corner beyond the cut.
    Only what is on the near side of the cut is read (the fit, the band, the cue); the outline must
    agree with its hull, show its band along every side in view, and be the only reading that does.
    The hidden corner's pixel noise is scaled as for a corner out of the image."""
    img, x0, y0, scale, small, hsv, mask = _segment(rgb, geo, roi, max_scale)
    full = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8))
    contours, _ = cv2.findContours(full, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    found = []
    for c in sorted(contours, key=cv2.contourArea, reverse=True)[:3]:
        if cv2.contourArea(c) < 36:
            break
        hull = cv2.convexHull(c)
        poly = cv2.approxPolyDP(hull, max(0.01 * cv2.arcLength(hull, True), 0.5), True)[:, 0, :].astype(np.float64)
        if not 5 <= len(poly) <= 8:
            continue
        centre = poly.mean(axis=0)
        for i in range(len(poly)):
            a, b = poly[i], poly[(i + 1) % len(poly)]  # the cut, a -> b
            quad = _chain_quad(np.roll(poly, -(i + 1), axis=0))
            if quad is None:
                continue
            n = np.array([b[1] - a[1], a[0] - b[0]]) / max(np.linalg.norm(b - a), 1e-9)
            n = n if (a - centre) @ n > 0 else -n  # away from the pad's seen part, toward what hides it
            if (quad[3] - a) @ n < 1.0:
                continue  # the hidden corner must lie behind the cut
            got = _refine_occluded(rgb, (quad + 0.5) * scale - 0.5 + [x0, y0], (a + 0.5) * scale - 0.5 + [x0, y0],
                                   (b + 0.5) * scale - 0.5 + [x0, y0], n, geo, camera)
            if got is not None:
                found.append(got)
    if not found:
        return None, ""
    if any(min(np.abs(np.roll(f.quad_px, k, axis=0) - found[0].quad_px).max() for k in range(4)) > 2.0
           for f in found[1:]):
        return None, "a pad partly hidden, read more than one way"
    return found[0], "ok"


def _window(img: np.ndarray, quad_px: np.ndarray, margin_px: float) -> tuple:
    """``(crop, (x0, y0))``: the part of ``img`` around ``quad_px``, ``margin_px`` beyond it on every
    side (clipped to the image), and the crop's origin."""
    lo = np.maximum(np.floor(np.asarray(quad_px).min(axis=0) - margin_px), 0).astype(int)
    hi = np.ceil(np.asarray(quad_px).max(axis=0) + margin_px + 1).astype(int)
    return img[lo[1]:hi[1], lo[0]:hi[0]], lo


SIDE_FIT_PASSES = 4  # the wide side fit is made at most this many times (_fit_sides) ...
SIDE_FIT_SETTLED_PX = 0.5  # ... until another pass moves no corner further than this


def _fit_sides(rgb: np.ndarray, quad: np.ndarray, side_px: float, geo: PadGeometry, camera: Camera | None,
               visible=None, polarity: bool = False) -> tuple:
    """``(refined | None, rms, crop, border channel, (x0, y0))``: the sides of the coarse ``quad``
    fitted on the border channel of the quad's neighbourhood (only that is converted: a full 1080p
    frame costs milliseconds), first over a wide window, then narrow around the fitted sides;
    ``refined`` in the crop's pixels.  With ``visible`` (a test of image pixels), what it rejects
    reads NaN: nothing behind an occluder's edge is fitted."""
    hw = float(np.clip(side_px * geo.border.solid_band_m / geo.side_m * 0.9, 1.0, 3.0))
    f, (bx0, by0) = _window(rgb, quad, 6)
    chan = _border_channel(f)
    if f.shape[0] < 8 or f.shape[1] < 8:
        return None, float("inf"), f, chan, (bx0, by0)
    if visible is not None:
        yy, xx = np.mgrid[by0:by0 + f.shape[0], bx0:bx0 + f.shape[1]]
        chan[~visible(np.column_stack([xx.ravel(), yy.ravel()])).reshape(f.shape[:2])] = np.nan
    cam_s = _shifted(camera, bx0, by0)
    # ``polarity``: the coarse window may hold the whole border (a far pad's, from a hull a pixel or
    # two inside it), so the border's polarity says which crossing is its outer edge (the border
    # channel is higher on the border than beyond it, in shadow and glare alike).  The narrow window
    # around the fitted sides holds the outer edge alone, placed by each profile's own ends.
    wide = max(hw, 2.5)
    refined, res = refine_quad(chan, quad - [bx0, by0], half_width=wide, camera=cam_s, inside_brighter=polarity)
    # again from where it put the sides, until they settle: where the hull lay a few pixels off a
    # side, the window held the edge over a short stretch only, and a line through it can be turned
    # by degrees (fz355: a pad cut by the image's top edge, its corner in view 5.5 px out along the
    # next side after the narrow pass, 0.3 px once settled; posed 11.9 % of the height off, "ok").
    # Made again only while a corner in view moves (a hidden corner, far along two sides, moves with
    # any turn of them), and where the solid band is wider than the window: one that holds both of
    # its edges walks across it pass by pass (small pads' sides went off their colour hull)
    for _ in range(SIDE_FIT_PASSES - 1 if side_px * geo.border.solid_band_m / geo.side_m > 2.0 * wide else 0):
        if refined is None:
            break
        again, res2 = refine_quad(chan, refined, half_width=wide, camera=cam_s, inside_brighter=polarity)
        seen = _seen(refined + [bx0, by0], rgb.shape)
        if again is None or not seen.any() \
                or np.max(np.linalg.norm(again - refined, axis=1)[seen]) <= SIDE_FIT_SETTLED_PX:
            break
        refined, res = again, res2
    if refined is not None:  # then narrow, around the refined sides
        again, res2 = refine_quad(chan, refined, half_width=hw, camera=cam_s)
        if again is not None:
            refined, res = again, res2
    return refined, res, f, chan, (bx0, by0)


def _refine_occluded(rgb, quad, a, b, n, geo: PadGeometry, camera: Camera | None):
    """The :func:`_occluded_outline` candidate ``quad`` (full-resolution pixels; the cut from ``a`` to
    ``b`` with normal ``n`` toward the hidden part) refined and checked, or ``None``."""
    def visible(px):  # the seen side of the cut, a pixel and a half clear of it
        return (np.asarray(px, np.float64).reshape(-1, 2) - a) @ n < -1.5

    def beyond(px):  # the hidden side, as clear of it (not merely not seen: the strip along the cut is neither)
        return (np.asarray(px, np.float64).reshape(-1, 2) - a) @ n > 1.5

    # an occluder's edge crosses the pad: just this side of it lies the field, not the border (a
    # hull side that is the pad's own edge has its band all along; then nothing is hidden)
    along = a + np.linspace(0.2, 0.8, 16)[:, None] * (b - a) - 2.5 * n
    v = sample_at(rgb, along)
    border = np.asarray(geo.border.color_rgb, np.float64)
    level = float(border @ _colour_direction(border)) / max(border.sum(), 30.0)
    if np.mean((v @ _colour_direction(border)) / np.maximum(v.sum(axis=1), 30.0) > 0.5 * level) > 0.5:
        return None

    side_px = _mean_side(quad)
    if side_px < 12 or not _quad_shaped(quad):
        return None
    refined, res, _, _, (bx0, by0) = _fit_sides(rgb, quad, side_px, geo, camera, visible)
    if refined is None or res > 0.5:
        return None
    refined = refined + [bx0, by0]
    if np.max(np.linalg.norm(refined - quad, axis=1)) > max(3.0, 0.1 * side_px):
        return None  # its sides and its colour hull disagree
    if visible(refined[3:4])[0] or not visible(refined[:3]).all():
        return None  # three corners seen, the fourth behind the cut
    smear = _smear_near(rgb, refined, geo, camera, 12.0)[2]
    if (_band_missing(rgb, refined, geo, camera, visible=visible) or _corner_missing(rgb, refined, geo, camera, visible)
            or smear > SMEARED_PX):  # (the outline of a partly seen pad cannot be placed under more: see _too_smeared)
        return None
    # and something does hide it: behind the cut, the border's band must be missing (a whole pad
    # whose outline was refused for another reason, JPEG's smeared colour, is no hidden one)
    got = _band_stretches(rgb, refined, geo, camera, segments=6, per=3)
    hidden = _band_stretches(rgb, refined, geo, camera, segments=6, per=3, visible=beyond, min_share=1.0)
    if got is None or hidden is None or not hidden[2].any():
        return None
    (rel, _, seen), (_, _, behind) = got, hidden
    med = float(np.median(rel[seen & ~behind])) if (seen & ~behind).any() else 0.0
    if med <= 0 or np.any(rel[behind] >= 0.25 * med):
        return None
    scale_sigma = _corner_sigma_scale(refined, rgb.shape, visible)
    if not np.isfinite(scale_sigma).all():
        return None
    return OutlineQuad(refined, _cue_scores(rgb, refined, geo, camera, visible), side_px, res, None, scale_sigma, smear,
                       edge_fitted=True)


def _corner_sigma_scale(quad_px: np.ndarray, shape, visible=None, fitted: np.ndarray | None = None) -> np.ndarray:
    """(4,) for a quad with corners out of the image: 1 for a seen corner, and for a hidden one how
    many times less sure it is, as the intersection of lines fitted to the stretches of its two
    sides that are seen (``fitted``, (4, 2): only between these fractions of each side, from its
    first corner).  A line fitted over a stretch ``l`` long is off at distance ``D`` from the
    stretch's middle by sqrt(1 + 12 D^2 / l^2) times its error there; a seen corner lies at the end
    of its stretches (D = l / 2), a hidden one beyond.  The worse of its two sides counts."""
    out = np.ones(4)
    t = np.linspace(0.0, 1.0, 257)
    for k in range(4):
        if _seen(quad_px[k:k + 1], shape, visible)[0]:
            continue
        worst = 1.0
        for other in ((k - 1) % 4, (k + 1) % 4):
            a, b = quad_px[other], quad_px[k]
            seen = t[_seen(a + t[:, None] * (b - a), shape, visible)]
            if len(seen) < 2:
                return np.full(4, np.inf)
            s0, s1 = seen[0], seen[-1]
            if fitted is not None:  # (t runs from the other corner to this one)
                f0, f1 = fitted[other] if other == (k - 1) % 4 else 1.0 - fitted[k][::-1]
                s0, s1 = max(s0, f0), min(s1, f1)
            length = (s1 - s0) * np.linalg.norm(b - a)
            D = (1.0 - 0.5 * (s0 + s1)) * np.linalg.norm(b - a)
            worst = max(worst, np.sqrt(1.0 + 12.0 * D**2 / max(length, 1e-9) ** 2) / 2.0)
        out[k] = worst
    return out


def _at_cut(px: np.ndarray, shape, cut_edges, tol: float = 1.5) -> np.ndarray:
    """(N, 4) whether each point lies on the left, top, right, bottom edge of an image of ``shape``,
    for the edges flagged in ``cut_edges`` (those of the searched area that are the image's)."""
    x, y = px[:, 0], px[:, 1]
    near = np.stack([x <= tol, y <= tol, x >= shape[1] - 1 - tol, y >= shape[0] - 1 - tol], axis=1)
    return near & np.asarray(cut_edges, bool)[None, :]


def _cut_quad(hull: np.ndarray, shape, cut_edges, min_seen: float = 0.25) -> np.ndarray | None:
    """The whole quadrilateral of a pad whose convex hull ``hull`` is cut by the image's edge, one
    corner outside it, or ``None``.  Along the hull, away from the image's edge, lie a stretch of
    one side, two whole sides and a stretch of the fourth (cut corners merged as in
    :func:`_hull_quad`); the hidden corner is where the two stretches' lines meet, outside the
    image.  Each stretch must be at least ``min_seen`` of a whole side, so that the corner is
    extrapolated less than three times as far as its sides are seen."""
    pts = hull.reshape(-1, 2).astype(np.float64)
    on = _at_cut(pts, shape, cut_edges)
    along = np.any(on & np.roll(on, -1, axis=0), axis=1)  # side i (pts[i] -> pts[i + 1]) runs along an edge
    starts = np.nonzero(np.roll(along, 1) & ~along)[0]
    if not along.any() or len(starts) != 1:
        return None  # not cut, or cut in two places
    # from the image's edge round to it again, simplified as an open curve (its ends stay on the edge,
    # however short the cut: a corner just out of view)
    run = np.roll(pts, -int(starts[0]), axis=0)[:int((~along).sum()) + 1]
    eps = max(0.01 * cv2.arcLength(hull.reshape(-1, 1, 2).astype(np.float32), True), 0.5)
    chain = cv2.approxPolyDP(run.reshape(-1, 1, 2).astype(np.float32), eps, False)[:, 0, :].astype(np.float64)
    got = _chain_quad(chain, min_seen)
    if got is None:
        return None
    quad, hidden = got, got[3]
    inside = (hidden >= -0.5).all() and (hidden <= [shape[1] - 0.5, shape[0] - 0.5]).all()
    return None if inside else quad


def _chain_quad(chain: np.ndarray, min_seen: float = 0.25) -> np.ndarray | None:
    """The quadrilateral whose outline runs along the open polyline ``chain``: a stretch of one side,
    two whole sides, a stretch of the fourth, the rest hidden (cut corners between them merged as
    in :func:`_hull_quad`).  Its corners in order, the hidden one (where the stretches' lines meet,
    beyond both) last; ``None`` when a stretch is under ``min_seen`` of a side or they do not meet
    beyond their ends."""
    chain = np.array(chain, np.float64)
    while len(chain) > 5:  # cut corners between the whole sides: merged as in _hull_quad
        lengths = np.linalg.norm(np.diff(chain, axis=0), axis=1)
        i = 1 + int(np.argmin(lengths[1:-1]))  # the short side chain[i] -> chain[i + 1], not a stretch
        x = _meet(chain[i - 1], chain[i], chain[i + 1], chain[i + 2], lengths[i])
        if x is not None:
            chain[i] = x
        chain = np.delete(chain, i + 1, axis=0)
    if len(chain) != 5:
        return None
    a0, a1, b0, b1 = chain[0], chain[1], chain[3], chain[4]
    da, db = a0 - a1, b1 - b0
    den = da[0] * db[1] - da[1] * db[0]
    if abs(den) < 1e-9:
        return None
    t = ((b0[0] - a1[0]) * db[1] - (b0[1] - a1[1]) * db[0]) / den
    hidden = a1 + t * da
    u = ((hidden - b0) @ db) / max(db @ db, 1e-12)  # along the other stretch: beyond its end too
    whole = np.linalg.norm(chain[2] - chain[1]) + np.linalg.norm(chain[3] - chain[2])
    seen = min(np.linalg.norm(da), np.linalg.norm(db)) / (whole / 2)
    if t <= 1.0 or u <= 1.0 or seen < min_seen:
        return None
    return np.array([chain[1], chain[2], chain[3], hidden])


def _best_ring(mask: np.ndarray, pad_geometry: PadGeometry, cut_edges=(False,) * 4, min_share: float | None = None,
               cut: bool = False, scale: int = 1) -> np.ndarray | None:
    """The mask's blob most like the pad's border ring (a convex quadrilateral whose area is
    border-coloured in about the ring's share, at least ``min_share``: half the ring's by default),
    by area and share.  ``cut_edges`` flags the mask's sides that are the image's own: a whole
    ring's hull may not touch them (a hull squeezed against the image's edge has corners that are
    not the pad's); with ``cut``, only blobs running into them are read, as a pad cut by the image's
    edge (:func:`_cut_quad`).  ``scale``: image pixels per mask pixel."""
    if cut and not any(cut_edges):
        return None
    full = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8))
    contours, _ = cv2.findContours(full, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    contours = list(contours)
    rejoined = None  # (hulls of pieces the cue's gap split, the indices of those pieces), when needed
    if cut:
        rejoined = _rejoined_pieces(full, contours, pad_geometry)
        contours += rejoined[0]
    ring_share = 1.0 - (pad_geometry.field_side_m / pad_geometry.side_m) ** 2  # the border's share of the pad
    best, best_score = None, -1.0
    for i, c in enumerate(contours):
        area = cv2.contourArea(c)
        if area < 36:
            continue
        if cut:
            if not _at_cut(c[:, 0, :].astype(np.float64), mask.shape, cut_edges).any():
                continue
            quad = _cut_quad(cv2.convexHull(c), mask.shape, cut_edges)
        else:
            hull = cv2.convexHull(c)
            quad = _hull_quad(hull)
            if quad is not None and _at_cut(quad, mask.shape, cut_edges).any():
                if _along_cut(hull, mask.shape, cut_edges) > 0.25 * _mean_side(quad):
                    continue  # squeezed against the image's edge: read as cut, if at all
                rejoined = rejoined or _rejoined_pieces(full, contours, pad_geometry)
                if i in rejoined[1]:
                    continue  # a piece of a ring cut by the edge, which the cue's gap split: read as cut
        if quad is None:
            continue
        if not _quad_shaped(quad):
            continue
        qa = abs(_signed_area(quad))
        sides = np.linalg.norm(np.roll(quad, -1, axis=0) - quad, axis=1)
        share = _mask_share(full, quad)
        if not ((0.5 * ring_share if min_share is None else min_share) <= share <= _ring_share_ceiling(pad_geometry, scale * sides.mean())):
            continue  # a solid patch of the colour, or a thin frame: not the pad
        score = qa * (1.0 - abs(share - ring_share))
        if score > best_score:
            best, best_score = quad, score
    return best


RING_SWELL_PX = (3.0, 1.0)  # px a ring's colour may spread past its outer edge, and into its hole


def _ring_share_ceiling(geo: PadGeometry, hull_side_px: float) -> float:
    """The largest share of a ring's hull (mean side ``hull_side_px``) its colour may cover and
    still be the pad's border, not a solid patch of the colour: 1.6 times the ring's own share, or
    more on a small pad, whose colour JPEG's half-resolution chroma (8 x 8 blocks of it, 16 px)
    spreads ``RING_SWELL_PX`` out past the pad and into its white field.  On unseen29's 17-20 px
    pads under JPEG 50 the hull came out 3 px wider on each side and the hole 1 px narrower: 68-74 %
    of the hull coloured, where the ring is 42 % of the pad, and all were refused as solid.  Never
    more than 0.9: a solid patch, its corners rounded, covers 95 % of its hull."""
    out, into = RING_SWELL_PX
    f = geo.field_side_m / geo.side_m
    side = max(hull_side_px - 2.0 * out, 1.0)
    hole = max(f * side - 2.0 * into, 0.0)
    swollen = 1.0 - (hole / max(hull_side_px, 1.0)) ** 2
    return float(min(0.9, max(1.6 * (1.0 - f * f), swollen)))


def _along_cut(hull: np.ndarray, shape, cut_edges) -> float:
    """How long (px) a convex hull runs along the image's edges flagged in ``cut_edges``.  A short
    run is a corner just out of view, or the smear of a blurred corner just in it: the hull's
    quadrilateral (:func:`_hull_quad`, which puts a corner cut off back where its sides meet) is the
    pad's; a long one is a pad cut by the edge (:func:`_cut_quad`)."""
    pts = hull.reshape(-1, 2).astype(np.float64)
    on = _at_cut(pts, shape, cut_edges)
    along = np.any(on & np.roll(on, -1, axis=0), axis=1)
    return float(np.linalg.norm(np.roll(pts, -1, axis=0) - pts, axis=1)[along].sum())


def _quad_shaped(quad: np.ndarray | None, min_ratio: float = 0.4) -> bool:
    """A quadrilateral a pad's outline can be, seen from any view it is found in: finite, convex,
    not folded, its shortest side at least ``min_ratio`` of its longest."""
    if quad is None or not np.isfinite(quad).all() or abs(_signed_area(quad)) <= 0:
        return False
    sides = np.linalg.norm(np.roll(quad, -1, axis=0) - quad, axis=1)
    return bool(sides.min() >= min_ratio * sides.max()
                and cv2.isContourConvex(np.asarray(quad, np.float32).reshape(-1, 1, 2)))


def _mean_side(quad: np.ndarray) -> float:
    """The mean length (px) of a quadrilateral's four sides."""
    return float(np.mean(np.linalg.norm(np.roll(quad, -1, axis=0) - quad, axis=1)))


def _rejoined_pieces(full: np.ndarray, contours, geo: PadGeometry) -> tuple:
    """Contours of the pieces of a ring that the cue's gap split: the cue square is left out of the
    border's mask, so a ring that also runs out of the image falls apart in two (a stretch of one
    side from the image's edge to the cue, and the rest).  Pieces whose gap is at most about the
    border's width (the cue's side) are joined: each piece's pixels grown by the width its own area
    and length say the border has, and the pieces that then touch make one contour (the convex hull
    of their own pixels, nothing grown).  ``(hulls of the groups of two pieces or more, the indices
    in ``contours`` of those pieces)``."""
    pieces = [i for i, c in enumerate(contours) if cv2.contourArea(c) >= 36]
    if len(pieces) < 2:
        return [], set()
    # a strip's width: its area over half its perimeter; the gap is the cue's side, in border widths
    width = max(2.0 * cv2.contourArea(contours[i]) / max(cv2.arcLength(contours[i], True), 1.0) for i in pieces)
    cue_side = 0.0 if geo.cue is None else float(np.ptp(geo.cue.corners[:, 0]))
    k = max(3, min(int(np.ceil(1.2 * width * cue_side / geo.border_m)), 64))
    grown = cv2.dilate(full, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
    _, labels = cv2.connectedComponents(grown)
    groups = {}
    for i in pieces:
        x, y = contours[i][0, 0]
        groups.setdefault(int(labels[y, x]), []).append(i)
    joined = [g for g in groups.values() if len(g) >= 2]
    return ([cv2.convexHull(np.concatenate([contours[i] for i in g])) for g in joined],
            {i for g in joined for i in g})


def _on_banded_edge(chan: np.ndarray, quad: np.ndarray, geo: PadGeometry, camera: Camera | None) -> np.ndarray:
    """``quad`` with each side moved onto the border's outer edge as :func:`banded_edge_offsets`
    finds it (the solid band and the checker inside it, at each side's own scale); a side it
    cannot tell, or would move by a pixel or more, stays."""
    e = banded_edge_offsets(chan, quad, _bands_px(quad, geo), camera)
    e = np.where(np.isfinite(e) & (np.abs(e) < 1.0), e, 0.0)
    if not np.any(e):
        return quad
    return _moved_sides(quad, e)


def side_normals(quad: np.ndarray) -> tuple:
    """``(sides (4, 2), unit normals (4, 2))`` of ``quad``: side j runs from corner j to j + 1, its
    normal points inward."""
    quad = np.asarray(quad, np.float64)
    d = np.roll(quad, -1, axis=0) - quad
    n = np.stack([-d[:, 1], d[:, 0]], axis=1) / np.maximum(np.linalg.norm(d, axis=1), 1e-9)[:, None]
    return d, n * np.sign(np.sum((quad.mean(axis=0) - quad) * n, axis=1))[:, None]


def _moved_sides(quad: np.ndarray, e: np.ndarray) -> np.ndarray:
    """``quad`` with side j (corner j to j + 1) moved by ``e[j]`` px along its inward normal, the
    corners where the moved sides meet."""
    n = side_normals(quad)[1]
    out = quad.copy()
    for j in range(4):  # corner j lies on sides j - 1 and j: move it onto both moved lines
        A = np.stack([n[j - 1], n[j]])
        if abs(np.linalg.det(A)) > 1e-6:
            out[j] = quad[j] + np.linalg.solve(A, [e[j - 1], e[j]])
    return out


SMEAR_REACH_PX, SMEAR_WIDEN = 20.0, 2  # the smear is read within 20 px of the field's edge, or 40, or 80
CENTROID_WIDEN = 2  # a border's centroid is read within 16 px of it, or 32, or 64 (a smear that runs on)
EDGE_FIT_SMEAR_PX = 10.0  # px of smear an edge fit holds to (twice its window)
TOO_SMEARED = "smeared past where its sides can be placed"
CHROMA_STEPS_MIN = 20       # sharp chroma steps a frame must show to be told whole (fewer: taken as halved) ...
CHROMA_PARITY_SHARE = 0.14  # ... and how far past half of them may fall on one column parity


def chroma_halved(rgb: np.ndarray) -> bool:
    """Whether ``rgb``'s chroma was kept at half resolution, as JPEG and H.264 keep it (4:2:0), told
    by the column parity of its sharp steps along the rows (every other row read): upsampled from
    half resolution, a chroma edge's largest step falls between the same two columns of a pair
    wherever the edge lies (libjpeg spreads a sample's step 1/4, 1/2, 1/4), while a whole chroma's
    edges fall on either parity alike.  The sharp steps (local maxima along a row, at least 8 levels
    and a quarter of the frame's strongest) on odd columns: 0.48-0.56 of them on the stored frames
    of four uncompressed datasets (320x320 to 1920x1080, 217-80,938 steps) and on rendered views
    near and far, 0.72-1.00 on the same through JPEG 30-95 and on two JPEG 50/70 datasets.  A frame
    with fewer than :data:`CHROMA_STEPS_MIN` sharp steps is taken as halved (JPEG's smoothing leaves
    a smooth ground's frame none): there the sides are placed as before."""
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[1] < 16:
        return False
    rows = np.ascontiguousarray(rgb[::2])
    if rows.dtype != np.uint8:
        rows = np.clip(rows * (255.0 if rows.max() <= 1.0 else 1.0), 0, 255).astype(np.uint8)
    ycc = cv2.cvtColor(rows, cv2.COLOR_RGB2YCrCb)
    cr, cb = cv2.extractChannel(ycc, 1), cv2.extractChannel(ycc, 2)
    d = cv2.max(cv2.absdiff(cr[:, 1:], cr[:, :-1]), cv2.absdiff(cb[:, 1:], cb[:, :-1]))  # the larger chroma step
    n = np.cumsum(np.bincount(d.ravel(), minlength=256))
    if n[0] == n[-1]:
        return False  # no chroma steps at all (a grey frame)
    top = int(np.searchsorted(n, 0.999 * n[-1]))  # (the 99.9th percentile)
    peak = (d[:, 1:-1] > d[:, :-2]) & (d[:, 1:-1] >= d[:, 2:]) & (d[:, 1:-1] >= max(8.0, 0.25 * top))
    cols = np.nonzero(peak)[1] + 1
    if len(cols) < CHROMA_STEPS_MIN:
        return True
    return abs(float(np.mean(cols % 2)) - 0.5) > CHROMA_PARITY_SHARE


SMEARED_PX = 5.0  # px of motion smear beyond which the outline's sides are placed by the border's centroid
# How far a small pad's colour hull may lie from its fitted sides: JPEG keeps chroma at half
# resolution, so a hull read from colour can be two chroma samples (4 px) off a corner of a 23 px pad
# whose sides fit within 2 px (bench_v2's v2_wide_jpeg55 at 20 m: 3.1-4.8 px; refused at 3 px, 18 of
# 239 frames lost).  Larger pads allow a tenth of their side.
HULL_SLACK_PX = 4.0
LIGHT_FIT_SMEAR_PX = 3.0  # px of luma smear past which the border's profile is fitted, else its edge in light
# A border's blurred profile is fitted where the smear read in luma is at most 1.5 of its width (the
# field's edge merges with the checker's: a 56 px pad under 4.5 px of motion and a 1 px lens read
# 8.2 px on half its views, against 4.9), and kept where the kernel fitted in the border's own
# channel is no wider than the border (JPEG smears that channel further than luma)
RESOLVED_SMEAR, RESOLVED_WIDTH = 1.5, 1.0
UNRESOLVED_SMEAR = 2.0  # smear (in border widths) past which a border no centroid placed is not fitted as sharp
STRUCTURE_SMEAR_PX = 7.0  # smear a sharp small pad's structure may read (JPEG, glare: 5-6 px, see _smear_near)
PROFILE_AGREE_PX, PROFILE_AGREE_PER_SMEAR = 1.0, 0.15  # how far (px, + per px of smear) it may move the centroid's side


def _deblurred(rgb: np.ndarray, quad_px: np.ndarray, geo: PadGeometry, camera: Camera | None,
               min_blur_px: float = SMEARED_PX, reach_px: float = 16.0, segments: int = 2,
               partial: bool = False, trim: float = 0.25, in_view: bool = False, profile: bool = True) -> tuple:
    """``(quad | None, smear px, fitted (4, 2) | None, noise per smear)``: ``quad_px`` with its sides
    moved to where the border's centroid puts them (:func:`band_centroid_offsets`), or, with
    ``profile``, where its blurred profile is fitted (:func:`banded_profile_offsets`) if the border is
    resolved (:data:`RESOLVED_SMEAR`, :data:`RESOLVED_WIDTH`), when some side is smeared by more than ``min_blur_px``
    (beyond the reach of an edge fit's window); ``None`` when no side is, or when a side cannot be
    read or would move further than its smear explains, or when the sides so moved meet in no
    quadrilateral a pad can be (:func:`_quad_shaped`: unseen47's 21 px pads at dusk under JPEG 45 and a
    1 px lens blur read 7 px of smear, with 0.5 px of motion, and one side's centroid fell across the
    pad: two corners at one pixel, "found").  The smear is what :func:`_smear_near` read
    around ``quad_px`` (kept with the outline: it is read once); ``fitted``: from where to where
    (fractions of each side, from its first corner) the side's line was fitted; noise per smear: a
    corner's pixel noise per px of smear, as placed (:data:`CENTROID_SIGMA_PER_SMEAR`,
    :data:`PROFILE_SIGMA_PER_SMEAR`).

    Measured on the conditions suite's gusty descent (12 px of blur at 12 m, a 55 px pad): the
    edge fit put every corner 4-5 px outside the pad, the pose 3.8 m off, accepted; the centroid
    leaves 0.5-0.7 px, the outward bias of an image whose tone curve is not exactly sRGB."""
    levels = _border_channel(srgb_to_linear(np.array([geo.border.color_rgb, geo.border.dark_color_rgb])))
    lin, lo, smear, pairs = _smear_near(rgb, quad_px, geo, camera, reach_px + 3)
    if levels[0] <= 0 or not smear > min_blur_px:
        return None, smear, None, CENTROID_SIGMA_PER_SMEAR
    widen = 0 if partial else CENTROID_WIDEN
    if widen:  # a crop that holds the widest profiles (only here: a smeared pad)
        crop, lo = _window(rgb, quad_px, reach_px * 2 ** widen + float(_bands_px(quad_px, geo).max()) + 3.0)
        lin = srgb_to_linear(crop)
    q, cam, bands = quad_px - lo, _shifted(camera, *lo), _bands_px(quad_px, geo)
    if partial:
        # the profiles reach no further than the smear across the side needs (its pair's: one blur
        # kernel smears both alike), so that a side near the image's edge stays read: a pad cut by
        # the right edge under 14 px of smear across its top and bottom, 3 px across its sides, had
        # every profile of the cut side reach out of view when all reached as far as the top's
        across = np.where(np.isfinite(pairs), pairs, smear)[[0, 1, 0, 1]]
        reach_px = np.minimum(reach_px, np.maximum(6.0, 0.75 * across + 3.0))
    per_smear = CENTROID_SIGMA_PER_SMEAR
    chan = _border_channel(lin)  # (of the crop around the pad: read by the centroid and the fit)
    e, blur, at = band_centroid_offsets(chan, q, bands, [1.0, 0.5 * (1.0 + levels[1] / levels[0])],
                                        cam, reach_px=reach_px, trim=trim, segments=segments, in_view=in_view,
                                        widen=widen)
    if profile and not in_view and smear <= RESOLVED_SMEAR * float(bands[:, 1].min()):
        # the border resolved (smeared over no more than its width): its blurred profile fitted, if on
        # every stretch that agrees with the centroid (what else lies across a profile, a box's edge,
        # moves a fit further than the centroid's bias); the spread the centroid read is no measure
        # of a lens's blur (a Gaussian's tails are cut: it read 0 under 3 px), the smear read in luma is
        near = PROFILE_AGREE_PX + PROFILE_AGREE_PER_SMEAR * smear
        fit = banded_profile_offsets(chan, q, bands, e, near, smear, cam, trim=trim,
                                     max_width_px=RESOLVED_WIDTH * bands[:, 1])
        # a side whose every stretch is fitted so is placed by its fit (a large pad whose one side no
        # fit placed kept the centroid on all four, 1-2.4 px outward, where three were fitted within
        # 0.35 px); a corner beside a side the centroid placed has the centroid's noise, and the
        # outline states their RMS over its corners
        agree = ((np.abs(fit - e) < near) | ~np.isfinite(e)).all(axis=1) & np.isfinite(e).any(axis=1)
        e = np.where(agree[:, None] & np.isfinite(e), fit, e)
        blur = np.where(agree[:, None], smear, blur)
        if agree.all():
            per_smear = PROFILE_SIGMA_PER_SMEAR
        elif agree.any():  # (corner j lies between sides j - 1 and j)
            corner = np.where(agree & np.roll(agree, 1), PROFILE_SIGMA_PER_SMEAR, CENTROID_SIGMA_PER_SMEAR)
            per_smear = float(np.sqrt(np.mean(corner**2)))
    read = np.isfinite(e)
    if not ((read.sum(axis=1) >= 2).all() if partial else read.all()) or np.any(np.abs(e[read]) > blur[read] / 2 + 2.0):
        return None, smear, None, CENTROID_SIGMA_PER_SMEAR
    # each side through its stretches' edge points (the side's angle is as uncertain as its place);
    # with ``partial`` (a pad cut by the image's edge) through the first and last of those in view
    d, n = side_normals(q)
    p = q[:, None, :] + at[..., None] * d[:, None, :] + np.where(read, e, 0.0)[..., None] * n[:, None, :]
    first, last = read.argmax(axis=1), segments - 1 - read[:, ::-1].argmax(axis=1)
    a, u = p[np.arange(4), first], p[np.arange(4), last] - p[np.arange(4), first]
    out = q.copy()
    for j in range(4):  # corner j where sides j - 1 and j meet
        A = np.stack([u[j - 1], -u[j]], axis=1)
        if abs(np.linalg.det(A)) < 1e-9:
            return None, smear, None, CENTROID_SIGMA_PER_SMEAR
        s = np.linalg.solve(A, a[j] - a[j - 1])
        out[j] = a[j - 1] + s[0] * u[j - 1]
    if not _quad_shaped(out):
        return None, smear, None, CENTROID_SIGMA_PER_SMEAR
    return out + lo, smear, np.stack([at[np.arange(4), first], at[np.arange(4), last]], axis=1), per_smear


def _smeared_in_view(rgb: np.ndarray, quad_px: np.ndarray, geo: PadGeometry, camera: Camera | None,
                     min_blur_px: float = 0.0, in_view: bool = False) -> tuple:
    """:func:`_deblurred` for a pad at or across the image's edge: each side through the border's
    centroid over those of five stretches of its middle (from a tenth of the side on) whose
    cross-profiles lie in view, at least two per side, reaching no further than the smear across
    that side needs.  ``in_view``: the five stretches share the part of the middle in view (a side
    mostly cut off is read on what is left of it; where an edge fit can be made, that reads such a
    side better: at 4 m under 7 px of smear, 40 mm against 77 mm from the centroids of a tenth of
    the side)."""
    return _deblurred(rgb, quad_px, geo, camera, min_blur_px=min_blur_px, segments=5, partial=True, trim=0.1,
                      in_view=in_view)


def _near_edge(quad_px: np.ndarray, shape, margin_px: float) -> bool:
    """Whether some corner of ``quad_px`` lies within ``margin_px`` of the image's edge (or outside)."""
    return bool(np.any(quad_px < margin_px) or np.any(quad_px[:, 0] > shape[1] - 1 - margin_px)
                or np.any(quad_px[:, 1] > shape[0] - 1 - margin_px))


def _bands_px(quad_px: np.ndarray, geo: PadGeometry) -> np.ndarray:
    """(4, 2) where the border's solid band and its checker end, px inward of each side of ``quad_px``
    (at that side's scale)."""
    lengths = np.linalg.norm(np.roll(quad_px, -1, axis=0) - quad_px, axis=1)
    return np.outer(lengths / geo.side_m, [geo.border.solid_band_m, geo.border_m])


def _smear_near(rgb: np.ndarray, quad_px: np.ndarray, geo: PadGeometry, camera: Camera | None,
                margin_px: float) -> tuple:
    """``(linear crop, its origin, smear px, (2,) smear px per pair)``: the neighbourhood of
    ``quad_px`` (``margin_px`` around it, or as far as the smear is read where it runs on past its
    first window: :data:`SMEAR_REACH_PX`) in linear light, and how far motion smears the white
    field's edge there in luma (0 when no side can be read), over all sides and across each pair of
    opposite sides (sides 0 and 2, 1 and 3; NaN for a pair with neither side read).  Luma, not colour: JPEG's chroma is smeared linearly in the encoded
    values, not in light, while its luma stays sharp; only motion smears both.

    Motion smears the two sides of a parallel pair alike (one blur kernel, seen edge-on the same way
    from both), so the smear is the larger over the two pairs of the pair's mean reading (a side's
    alone where the other is not read).  A wide reading on one side, or on two adjacent ones, is
    mostly the pad's own structure: on sharp 25-35 px pads under JPEG or glare the field's edge
    merges with the checker's and read 5-6 px on one side (blur 0-0.6 px), the most over the sides,
    which took the outline to the centroid placement meant for motion and gave it the smear's
    noise.  (The pair's smaller reading is too strict: on a 36 px pad under 9 px of blur one side
    of the smeared pair read 4.4 px, the other 7.9.)"""
    def read(margin, widen):
        crop, lo = _window(rgb, quad_px, margin)
        lin = srgb_to_linear(crop)
        q = quad_px - lo
        return lin, lo, step_blur(np.ascontiguousarray(lin @ _LUMA), q, _bands_px(q, geo)[:, 1], _shifted(camera, *lo),
                                  reach_px=SMEAR_REACH_PX, widen=widen)

    lin, lo, s = read(margin_px, 0)
    if np.isinf(s).any():  # a rise runs on past the window (rare: a smear wider than the border): wider
        lin, lo, s = read(max(margin_px, SMEAR_REACH_PX * 2 ** SMEAR_WIDEN + 3.0), SMEAR_WIDEN)
    s = np.where(np.isinf(s), np.nan, s)
    pairs = np.where(np.isnan(s[:2]), s[2:], np.where(np.isnan(s[2:]), s[:2], 0.5 * (s[:2] + s[2:])))
    return lin, lo, float(np.nanmax(np.append(pairs, 0.0))), pairs


def _too_smeared(rgb: np.ndarray, quad_px: np.ndarray, geo: PadGeometry, camera: Camera | None,
                 limit_px: float = SMEARED_PX) -> bool:
    """Whether motion smears the field's edge past ``limit_px`` around ``quad_px`` (the outline of a
    partly seen pad cannot then be placed: its sides' centroids need the whole border)."""
    return _smear_near(rgb, quad_px, geo, camera, 12.0)[2] > limit_px


def _through_quad(quad_px: np.ndarray, geo: PadGeometry, camera: Camera | None, pts_xy: np.ndarray,
                  square: np.ndarray | None = None):
    """``(N, 2)`` pixels of pad-plane points ``pts_xy`` (metres, pad frame) where the homography that
    takes the pad's outer corners (or the points ``square``, (4+, 2) pad frame: with more than four,
    their least-squares homography), in order, onto ``quad_px`` puts them, the lens included;
    ``None`` when the quad has a corner the lens cannot undistort."""
    und = camera.undistort_pixels(quad_px) if camera is not None and camera.has_distortion else quad_px
    if not np.isfinite(und).all():
        return None
    src = geo.outer_corners[:, :2] if square is None else np.asarray(square)[:, :2]
    if len(src) > 4:
        H = cv2.findHomography(np.asarray(src, np.float64), np.asarray(und, np.float64), 0)[0]
        if H is None:
            return None
    else:
        H = cv2.getPerspectiveTransform(src.astype(np.float32), np.asarray(und, np.float32))
    px = cv2.perspectiveTransform(np.asarray(pts_xy, np.float64).reshape(1, -1, 2), H)[0]
    if camera is not None and camera.has_distortion:
        from .features import _distort_px

        px = _distort_px(camera, px)
    return px



def _outer_of_field(field_px: np.ndarray, geo: PadGeometry, camera: Camera | None):
    """The pad's outer corners where the white field's corners ``field_px`` put them (its homography,
    the lens included), or ``None`` (:func:`_through_quad`)."""
    return _through_quad(field_px, geo, camera, geo.outer_corners[:, :2], square=geo.field_corners)

def _colour_direction(colour_rgb, dtype=np.float64) -> np.ndarray:
    """(3,) weights whose dot product with an RGB is the colour's own chroma (for the magenta border
    about ``(R + B) / 2 - G``): the colour less its grey, scaled to a largest weight of 1."""
    c = np.asarray(colour_rgb, dtype)
    return (c - c.mean()) / (np.abs(c - c.mean()).max() + 1e-6)


BAND_STRETCH_MIN_PX = 11.0  # px a side's stretch spans at the least (:func:`_band_missing`)


def _band_missing(rgb: np.ndarray, quad_px: np.ndarray, geo: PadGeometry, camera: Camera | None,
                  segments: int = 3, per: int = 6, visible=None) -> bool:
    """Whether a stretch of some side of ``quad_px`` lacks the border's solid band just inside it.

    Sides fitted to the wrong edge (the platform's rim beside the pad, where JPEG's half-resolution
    chroma has swelled the colour mask over it) are straight and fit with sub-pixel residuals, yet
    put a corner several pixels out: the pose is then off by 10 % of the height and nothing else
    objects.  Through the quad's homography, the border colour's chroma (``(R + B) / 2 - G`` over
    the brightness, for the magenta border) is read half a band inside and half a band outside each
    side, over ``segments`` stretches between the corner squares, fewer where a side is short: each
    at least :data:`BAND_STRETCH_MIN_PX` long.  (JPEG keeps chroma in 8 x 8 blocks at half
    resolution, 16 px: a 3-4 px stretch of a 17-21 px pad reads about one block's colour, and on
    unseen29's far frames under JPEG 50 the labelled outline itself failed the check in 53 of 75;
    in 8 with 11 px stretches, one per side below 22 px, while the quad shifted by 3 px still
    fails in all 75 and one side moved 3 px out in 64.  With 16 px stretches, one per side up to
    32 px, a 23 px pad's fit 3 px off along part of a side passed: bench_v2's v2_wide_jpeg55, 3
    frames.)  A stretch fails when its
    contrast is under a quarter of the median stretch's both raw and over the brightness (and under
    0.03 there): a shadow across the pad lowers the first but not the second; a box over a corner
    both."""
    segments = int(np.clip(_mean_side(quad_px) // BAND_STRETCH_MIN_PX, 1, segments))
    got = _band_stretches(rgb, quad_px, geo, camera, segments, per, visible)
    if got is None:
        return False
    rel, contrast, seen = got
    if not seen.any():
        return False
    med = float(np.median(rel[seen]))  # (stretches out of the image tell nothing)
    if med <= 0:
        return False  # no band anywhere: not this test's to say
    # in a shadow the band's chroma over brightness holds; behind a box, beside a rim, it does not
    floor = max(0.03, 0.25 * float(np.median(contrast[seen])))
    return bool(np.any(seen & (rel < 0.25 * med) & (contrast < floor)))


def _corner_missing(rgb: np.ndarray, quad_px: np.ndarray, geo: PadGeometry, camera: Camera | None,
                    visible=None) -> bool:
    """Whether the border's solid band is missing just past some corner square of ``quad_px`` (on
    both sides beside it), where the other corners show it.  A corner hidden by a box, whose hull
    put the quad's corner tens of pixels off, passed the sides' band check (its sides' stretches
    lie mostly on the band); the squares beside a corner do not.  Read as the band check reads
    chroma (over brightness, so shadows pass); corners out of view tell nothing."""
    s, b, w = geo.side_m / 2.0, geo.border_m, geo.border.solid_band_m
    sq = geo.outer_corners[:, :2]
    cen = sq.mean(axis=0)
    t = b + np.linspace(0.1, 0.9, 4) * b
    pts = []
    for j in range(4):
        ex, ey = np.sign(cen - sq[j]) * [1.0, 0.0], np.sign(cen - sq[j]) * [0.0, 1.0]
        pts += [sq[j] + t[:, None] * ex + 0.5 * w * ey, sq[j] + t[:, None] * ey + 0.5 * w * ex]
    px = _through_quad(quad_px, geo, camera, np.concatenate(pts))
    if px is None:
        return False
    v = sample_at(rgb, px)
    seen = _seen(px, rgb.shape, visible).reshape(4, -1).all(axis=1)
    chroma = ((v @ _colour_direction(geo.border.color_rgb)) / np.maximum(v.sum(axis=1), 30.0)).reshape(4, -1).mean(axis=1)
    if seen.sum() < 2:
        return False
    med = float(np.median(chroma[seen]))
    return bool(med > 0 and np.any(seen & (chroma < 0.25 * med)))


def _band_stretches(rgb: np.ndarray, quad_px: np.ndarray, geo: PadGeometry, camera: Camera | None,
                    segments: int = 3, per: int = 6, visible=None, min_share: float = 0.5):
    """``(rel, contrast, seen)``, each ``(4, segments)``, or ``None``: the border colour's chroma
    half a band inside less half a band outside each stretch of each side of ``quad_px`` (raw, and
    over the brightness), and whether the stretch is in view (at least ``min_share`` of it;
    :func:`_band_missing`)."""
    s, b, w = geo.side_m / 2.0, geo.border_m, geo.border.solid_band_m
    sq = geo.outer_corners[:, :2]
    t = np.linspace(-s + b, s - b, segments * per)
    pts = []
    for j in range(4):
        a, c = sq[j], sq[(j + 1) % 4]
        d = (c - a) / np.linalg.norm(c - a)
        n = np.array([-d[1], d[0]])
        n = n if n @ -(a + c) > 0 else -n  # inward
        base = (a + c) / 2 + t[:, None] * d
        pts += [base + 0.5 * w * n, base - 0.5 * w * n]
    px = _through_quad(quad_px, geo, camera, np.concatenate(pts))
    if px is None:
        return None
    v = sample_at(rgb, px)
    seen = _seen(px, rgb.shape, visible).reshape(4, 2, segments, per).all(axis=1).mean(axis=2) >= min_share  # (4, segments)
    ch = (v @ _colour_direction(geo.border.color_rgb)).reshape(4, 2, segments, per)
    norm = (ch / np.maximum(v.sum(axis=1), 30.0).reshape(4, 2, segments, per)).mean(axis=3)
    raw = ch.mean(axis=3)
    return raw[:, 0] - raw[:, 1], norm[:, 0] - norm[:, 1], seen


FIELD_SAYS_SWOLLEN_RMS_PX = 0.6
# the field's sides are refitted from where the last fit ended, up to this many times: the fit's
# window is the checker's width (+-1 px on a 20 px pad), and a side started 2-3 px off (a swollen
# outline's prediction) ends between where it started and the field's edge.  With one fit, the
# worst field corner on 20-25 px JPEG'd pads lay 4.6 % of the field's side off in the median, 8 %
# or more on 23 of 84 found (a 120 degree fisheye scene at JPEG 40 and jpeg_twins' JPEG tier);
# with three, 3.7 % and 7 of 84 (25-35 px: 2.9 -> 2.3 %, 9 -> 4 of 84; 35-80 px: 1.7 -> 1.6 %).
# Whether the field is used is still decided by the first fit (:func:`_field_fit`)
FIELD_FIT_ROUNDS = 3
# the white field, fitted cleanly on luma, lies inside the outline by the border's width: found further
# out than the outline puts it by more than this (px, or share of the side), outline and field contradict
# each other and the outline is not posed.  unseen45 (a glossy pad on a grey deck under a high sun,
# JPEG 65, a fisheye): the magenta chroma bled 2-4 px into the deck and the field's fit found the
# glare-bright border's outer edge, cleanly, 2.2-4.0 px out: those outlines read the pad 7.6 and 9.9 %
# too large.  Over 1,000 other outline poses of four hard scenes none lay over 1 px out; a dark
# patch of the border's hue beside a clean 45 px pad, 1.6 px (test_a_dark_patch_of_the_border_hue_...)
FIELD_OUTSIDE_PX = 2.0
FIELD_OUTSIDE_SHARE = 0.05
LOOSE_FIELD_SURER = 3.0


def _field_quad(rgb: np.ndarray, quad_px: np.ndarray, geo: PadGeometry, camera: Camera | None,
                move_px: float = 0.7, max_rms_px: float = 0.35) -> np.ndarray | None:
    """The white field's corners fitted on luma, where the outline's colour edges cannot be trusted.

    JPEG and H.264 keep chroma at half resolution and quantise it hard: the border's colour edges
    smear over pixels (the outline's corners came out ~1 px off in the median, 3-4 px at p90, on
    JPEG 55-70 frames) while luma stays sharp.  The border is magenta of middle luma, so its outer
    edge is faint in luma; its inner edge, checker against the white field, is strong.  So the field
    square is predicted through the outline's homography and refined on luma.  Its corners are
    returned, to be used instead, when outline and field disagree beyond what a clean frame shows
    (a corner more than ``move_px`` from the prediction; the field edge is ~0.3 px less clean than
    the outer one), the field's lines fit well (``max_rms_px``) and the field came out smaller than
    predicted, as when smeared colour swells the outline (a hard shadow across the pad moves it
    the other way).  On throw-away measurements over 1,080 found outlines (the conditions suite and
    a pitched JPEG-70 scene): the largest corner error's median 1.68 -> 0.62 px, p90 3.71 -> 2.92 px
    on the JPEG frames; never used on the others.

    Returns ``(corners or None, swollen past, the field's fit or None, outside px, noise px)``: the
    second says the field fitted well but lies further inside than a corner's move may mend (the
    outline is then suspect: :func:`_field_rescue`), the third is the field fitted, used or not, the
    fourth how far its furthest corner lies outside the prediction (0 when inside, or with no clean
    fit), the fifth the noise its corners carry beyond a found corner's (a loose fit's scatter)."""
    side_px = _mean_side(quad_px)
    # a field fitted less cleanly still says whether the outline swelled past it (a dark patch of
    # the border's hue beside the pad: its lines fit to 0.42 px, and the swollen outline went on)
    limit = max(3.0, 0.1 * side_px)

    def used(move, swollen):  # the field's corners replace the outline's
        return swollen and move_px < move <= limit

    got = _field_fit(rgb, quad_px, geo, camera, max(5.0, 0.25 * side_px), max_rms_px,
                     rounds=FIELD_FIT_ROUNDS, loose_rms_px=FIELD_SAYS_SWOLLEN_RMS_PX, refit_when=used)
    if got is None:
        return None, False, None, 0.0, 0.0
    field, move, swollen, rms, guess = got
    far = bool(swollen and move > limit)
    if rms > max_rms_px:
        # too loose a fit to place the pad by, but it still says how far the colour swelled: more
        # than a corner's share the height may be off by is refused as far (the synthetic bleed of
        # test_a_pads_colour_bled_into_a_grey_deck: 3.2-3.5 px at 40-55 px, the pad 6-9 % large)
        swelled = far or bool(swollen and move > max(FIELD_OUTSIDE_PX, FIELD_OUTSIDE_SHARE * side_px))
        if swollen and not swelled and move > max(move_px, LOOSE_FIELD_SURER * rms):
            # loose as its fit is, the field on luma is surer than a colour outline swollen this far
            # past it (more than LOOSE_FIELD_SURER of its lines' scatter): its corners, with that
            # scatter as their noise.  (unseen64, a 0.6 m pad on a grey platform under a high sun,
            # JPEG 60: at 13.5 m the outline's corners lay 2.4-2.8 px out on a 37 px pad, the loose
            # field 1.8 px inside it, and the outline was posed 10.5 % of the height low, "ok")
            return field, False, field, 0.0, rms
        return None, swelled, None, 0.0, 0.0
    centre = guess.mean(axis=0)
    outside = float(np.max(np.linalg.norm(field - centre, axis=1) - np.linalg.norm(guess - centre, axis=1)))
    return (field if used(move, swollen) else None), far, field, max(outside, 0.0), 0.0


def _field_fit(rgb: np.ndarray, quad_px: np.ndarray, geo: PadGeometry, camera: Camera | None, reach_px: float,
               max_rms_px: float = 0.35, rounds: int = 1, loose_rms_px: float = 0.0, refit_when=None):
    """``(field corners, largest move from the prediction px, swollen, line rms px, the predicted
    corners)`` or ``None`` (its lines fit worse than ``max(max_rms_px, loose_rms_px)``; the
    linear-light fit is preferred where it fits within ``max_rms_px``): the white
    field's square fitted on luma from where the outline ``quad_px`` predicts it, each side first
    moved to the nearest strong rise into the white within ``reach_px`` inward, then fitted up to
    ``rounds`` times, each from the last (only when ``refit_when(move, swollen)``, if given: the
    first fit says both); ``swollen`` when the field came out smaller than predicted
    (:func:`_field_quad`)."""
    guess = _through_quad(quad_px, geo, camera, geo.field_corners[:, :2])
    if guess is None:
        return None
    side_px = _mean_side(quad_px)
    checker_px = side_px * (geo.border_m - geo.border.solid_band_m) / geo.side_m
    gray8 = cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2GRAY)
    gray = gray8.astype(np.float32)
    # the swollen outline puts the guess pixels outside the field, beyond the fit's narrow window
    # (it must stay inside the checker): each side starts at the nearest strong rise into the white
    # (the border's width: its outer edge rises into it, and may lie nearer than the field's edge)
    start = _moved_sides(guess, rise_offsets(gray, guess, camera, hi=reach_px,
                                             apart_px=side_px * geo.border_m / geo.side_m))
    half = float(np.clip(0.45 * checker_px, 1.0, 2.5))
    fitted, rms = refine_quad(gray, start, half_width=half, camera=camera)
    if fitted is None:
        return None
    # how far the field lies from where the outline put it, and whether inside, from the first fit:
    # the refits place the corners, and on a clean 12-15 px pad, whose checker is a pixel wide,
    # they wander a few tenths of a pixel further (the outline taken as swollen where it was right)
    move = float(np.max(np.linalg.norm(fitted - guess, axis=1)))
    centre = guess.mean(axis=0)
    out = (guess - centre) / np.maximum(np.linalg.norm(guess - centre, axis=1), 1e-9)[:, None]
    swollen = float(np.mean(np.sum((fitted - guess) * out, axis=1))) < 0.1  # the field smaller than the outline says
    if refit_when is None or refit_when(move, swollen):  # (not for a field that will not be used: per frame)
        for _ in range(rounds - 1):  # from where the last fit ended: a start far off biases the narrow window
            again, rms_again = refine_quad(gray, fitted, half_width=half, camera=camera)
            if again is None:
                break
            start, fitted, rms, shift = fitted, again, rms_again, float(np.abs(again - fitted).max())
            if shift < 0.05:
                break
    if rms > max(max_rms_px, loose_rms_px):
        return None
    # placed in linear light: blur mixes light, and the white field's 50 % crossing in sRGB lies on
    # the dark side of the edge (the field came out 0.3 px too large on JPEG 55 behind a 100 degree
    # lens, 0.8 % of the side, and the height 1.2 % low)
    linear, rms_l = refine_quad(srgb_to_linear(gray8), start, half_width=half, camera=camera)
    if linear is not None and rms_l <= max_rms_px:
        return linear, move, swollen, rms_l, guess
    return fitted, move, swollen, rms, guess


# thresholds between the crop's darkest and its brightest: the field is bright against its ring, not
# against the frame (on snow the ground is as white: a 0.2-0.8 span above the median found no field there)
GREY_LEVELS = (0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8)
GREY_MIN_FILL = 0.75      # a field's blob fills this much of its hull's quad (the markers are holes: not counted)
GREY_MAX_CANDIDATES = 60  # the largest blobs of that shape, at most, are read against the design
# A grey frame has no colour to tell the pad from the ground by: its whole printed design must say it
# (name_by_design's own bars were set over colour-found outlines, which already are the pad's colour).
# Over the 3,842 bright quads of 24 px and more that the `mono` suite's and two unseen grey scenes'
# Approaching frames gave (every second frame), ground and decoys more than a side from the pad
# correlated up to 0.76, in one naming by up to 0.010 more than in the next; the pad's own quads
# 0.72-0.99 where right, leading by 0.044 at least (0.070 at 25-30 px); a misshapen piece of the pad
# (unseen71, a corner a fifth of its side off) 0.83 leading by 0.074, which the posed quad's own check
# refuses unless the fit mends it.  Under GREY_MIN_SIDE_PX the design is a bright square in a dark
# ring, which ground makes too (blobs of it under 16 px reached 0.92 leading by 0.154): such pads are
# left to come nearer.
GREY_MIN_SIDE_PX = 24.0   # the outer square's least mean side (px)
GREY_MIN_NCC = 0.8
GREY_MIN_LEAD = 0.08
# The lead is the design's asymmetric part (what a quarter turn changes: the three finder markers, the
# texture) diluted by its symmetric part (the white field in its dark ring), whose contrast a dim or
# soft view keeps while its markers fade: a 39-56 px paper pad on a platform in a grey frame read 0.93-0.95,
# leading by 0.058-0.074, and was lost for 24 frames (fuzz seed 127).  That part alone (the samples less
# their mean over the four quarter turns, the design's likewise) names it undiluted: over every bright
# quad of seven random grey scenes (scratch/s71/asym_all.py, every second frame) the pad's own, read at
# GREY_MIN_NCC, correlated 0.51 or more in 95 % (median 0.73); quads of the pad misplaced by 12-27 % of
# its side 0.47 at most, leading by 0.61; ground and decoys 0.25.  A quad that reads at GREY_MIN_NCC, is
# named alike by both and whose asymmetric part correlates this much, leading the next naming's by as
# much again, reads as the pad where its lead alone falls short
GREY_MIN_ASYM_NCC = 0.55
GREY_MIN_ASYM_LEAD = 0.4
# A blob's hull is a field's outline to a pixel or two, and a 24-35 px pad read through it a pixel off
# correlates less: fuzz seeds 127, 153 and 172 (grey, 0.4-0.7 px modules) found the field's blob in 70
# cold frames at 8-11 m, read 0.92-0.95 plain, named alike, the asymmetric part 0.47-0.55 leading by 0.5
# and more, and were lost.  A blob that reads so at this lower bar is fitted (the field's sides on luma,
# the border's profile) and read again where the fit puts it, at the full bars: what is posed reads as
# the design as before (a piece of the pad misplaced 12-27 % of its side read 0.47 at most: fitted, it
# is the pad, or fails the full bars)
GREY_NEAR_ASYM_NCC = 0.4
GREY_BLOB_READS = ("field", "pad")  # what each bright blob is read as: the white field, the whole pad (find_grey_outline)


def is_grey(rgb: np.ndarray, step: int = 7, tol: int = 2) -> bool:
    """Whether an RGB frame is a monochrome camera's (R = G = B, within ``tol`` levels, on every
    ``step``-th pixel): DESIGN.md's frames are RGB, and a grey camera's are written so."""
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        return False
    s = rgb[::step, ::step].astype(np.int16)
    return bool(np.abs(s[..., 0] - s[..., 1]).max() <= tol and np.abs(s[..., 2] - s[..., 1]).max() <= tol)


def find_grey_outline(rgb: np.ndarray, gray: np.ndarray, geo: PadGeometry, camera: Camera | None, roi,
                      design: PadDesign) -> tuple:
    """``(OutlineQuad | None, reason)``: the pad's outline in a monochrome camera's frame, where the
    border's colour is a grey like the ground's (magenta reads as mid grey) and cannot be segmented.

    The white field stands out instead: the brightest large area in view, a convex quadrilateral
    that the border's darker ring keeps apart from a bright ground.  Bright blobs are thresholded
    at :data:`GREY_LEVELS` between the crop's darks and its highlights; each quad-shaped one, taken
    as the field, puts the outer square where its homography says, and is the pad only if the image
    sampled through it correlates with the pad's printed design, in one naming clearly better than
    the others (:func:`name_by_design`, at :data:`GREY_MIN_NCC` and :data:`GREY_MIN_LEAD`: a white
    square or a finder square alone is symmetric under a quarter turn, and correlates alike in every
    naming), and is :data:`GREY_MIN_SIDE_PX` across at least.  Each blob is read as the whole pad too
    (:data:`GREY_BLOB_READS`), at the full bars only: a border bright in luma is as bright as the
    field.  The field's sides are then fitted on luma (:func:`_field_fit`), and placed by the border's
    whole profile across each side; the field's corners (``field_px``) are what is posed.  Where they
    do not fit, or do not read as the design where they fit, the blob's square is returned, to be
    posed only where the design's fit places it (:func:`_grey_blob_only`)."""
    g, x0, y0 = _crop(gray, roi)
    if min(g.shape[:2]) < 8:
        return None, "image too small"
    scale = 2 if min(g.shape[:2]) >= 1600 else 1  # (4K: the blobs on a copy at half size; fitted at full)
    small = g if scale == 1 else cv2.resize(g, (g.shape[1] // 2, g.shape[0] // 2), interpolation=cv2.INTER_AREA)
    # the field may be a ten-thousandth of the frame, its ring too: the darkest and brightest 3x3 means
    lo, hi = (float(v) for v in cv2.minMaxLoc(cv2.blur(small, (3, 3)))[:2])
    if hi - lo < 20:
        return None, "no bright field in a grey frame"
    cands, keys = [], set()
    min_area = (GREY_MIN_SIDE_PX * geo.field_side_m / geo.side_m / scale) ** 2
    for f in GREY_LEVELS:
        mask = (small > lo + f * (hi - lo)).astype(np.uint8)
        # each blob on its own (a field on snow is an island inside its ring, inside the ground's blob: its
        # own component), traced in its own box and only where it may be a field: textured ground breaks
        # into tens of thousands of specks at some level, and the ground's blob holds as many holes
        # (traced whole, a 1080p frame took 0.6-0.75 s).  Pixels, not the outline's area, are counted
        # first: a field's markers and texture are holes in it, a third of it at most.
        n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
        for i in np.flatnonzero(stats[:, cv2.CC_STAT_AREA] >= 0.25 * min_area):
            x, y, w, h = (int(v) for v in stats[i, :4])
            if i == 0 or w * h < min_area:  # (label 0: what is under the threshold)
                continue
            blob = cv2.copyMakeBorder((labels[y:y + h, x:x + w] == i).astype(np.uint8), 1, 1, 1, 1, cv2.BORDER_CONSTANT)
            c = max(cv2.findContours(blob, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)[0], key=cv2.contourArea) + [x - 1, y - 1]
            area = cv2.contourArea(c)
            if area < min_area:
                continue
            quad = _hull_quad(cv2.convexHull(c))
            if not _quad_shaped(quad) or area < GREY_MIN_FILL * abs(_signed_area(quad)):
                continue
            quad = quad if _signed_area(quad) > 0 else quad[::-1]
            quad = (quad + 0.5) * scale - 0.5 + [x0, y0]
            key = tuple(np.round(np.r_[quad.mean(axis=0), _mean_side(quad)] / 3.0).astype(int))
            if key not in keys:
                keys.add(key)
                cands.append((area, quad))
    if not cands:
        return None, f"no field-shaped bright quadrilateral in a grey frame (a pad {GREY_MIN_SIDE_PX:g} px across at least)"
    cands.sort(key=lambda a: -a[0])
    best, near = None, []
    # each blob is read as the field and as the whole pad: a border bright in luma (cyan, or magenta under a
    # high sun) is as bright as the field, and the field's blob is the pad's.  As the whole pad, only at the
    # full bars: grey ground's blobs, read twice as often, reached the faint one
    # (test_a_grey_pad_too_small_to_show_its_design_and_grey_ground_are_never_posed)
    for outer, whole in ((o, w) for _, field in cands[:GREY_MAX_CANDIDATES]
                         for o, w in ((_outer_of_field(field, geo, camera), False), (field, True))
                         if ("pad" if w else "field") in GREY_BLOB_READS):
        if outer is None or not np.isfinite(outer).all():
            continue
        if _mean_side(outer) < GREY_MIN_SIDE_PX:
            continue
        level, ncc = _design_read(gray, outer, geo, camera, design)
        if whole and level != READS:
            level = 0
        if level and (best is None or (level, ncc) > best[:2]):
            best = (level, ncc, outer)
        elif ncc >= DESIGN_MIN_NCC:
            near.append((ncc, outer, whole))
    # none reads: a blob's hull a few px off the field (its corners rounded, a bright stain run into its
    # ring) samples the design askew; the field's sides fitted from there and read again (the most
    # alike first), a whole pad's own sides against the ground (a 70 px pad's blob 1.4 px off read 0.78,
    # the labelled square 0.94).  The bars are the same
    for _, outer, whole in sorted(near, key=lambda a: -a[0])[:GREY_REFIT_CANDIDATES] if best is None else ():
        got = _grey_field_fitted(rgb, outer, geo, camera) if not whole else _grey_sides_fitted(gray, outer, camera)
        if got is not None:
            level, ncc = _design_read(gray, got[0], geo, camera, design)
            if level and (level == READS or not whole) and (best is None or (level, ncc) > best[:2]):
                best = (level, ncc, got[0])
    if best is None:
        return None, f"no bright quadrilateral in a grey frame reads as the pad's design ({len(cands)} looked at)"
    got = _grey_field_fitted(rgb, best[2], geo, camera)
    if got is None:
        return _grey_blob_only(best, "its field's sides do not fit")
    # (the fits read the pad's neighbourhood only, as _field_agrees: a whole frame's grey and light cost ms)
    gray_w, lo = _window(gray, best[2], int(np.ceil(0.3 * _mean_side(best[2]) + 8)))
    cam_w = _shifted(camera, *lo)
    outer, field, rms = got
    # A step fit of the field's edge alone is biased by the bands beside it: the checker, then the solid
    # band, a pixel or two each (on the `mono` suite's renders the field came out 0.4-0.7 % small, the
    # height as much high: +0.3 to +1.5 % in the median by dataset).  The border's whole profile, its
    # three steps at their known places, fitted from there as on the colour channel
    # (:func:`banded_edge_offsets`; either polarity: the border's grey may be darker than the ground or
    # lighter), in display values as a sharp frame's pixels average its edges, in light where motion
    # smears them (:data:`LIGHT_FIT_SMEAR_PX`): the height's median within -0.4 to +0.3 %
    smear = _smear_near(rgb, outer, geo, camera, 12.0)[2]
    chan = srgb_to_linear(gray_w) if smear > LIGHT_FIT_SMEAR_PX else gray_w
    e = banded_edge_offsets(chan, outer - lo, _bands_px(outer, geo), cam_w, rising=False)
    e = np.where(np.isfinite(e) & (np.abs(e) < 1.0), e, 0.0)
    if np.any(e):
        outer = _moved_sides(outer, e)
        field = _through_quad(outer, geo, camera, geo.field_corners[:, :2])
        if field is None or not np.isfinite(field).all():
            return _grey_blob_only(best, "its field's sides do not fit")
    # what is posed must read as the design too: a blob that was a misshapen piece of the pad (a corner a
    # fifth of the side off: 0.83, leading by 0.074 on unseen71) is refused if the fit does not mend it.
    # One read at the lower bar (GREY_NEAR_ASYM_NCC) is read so here, and at the full bars where the pad's
    # design fit puts it (the localizer's: a 24-35 px field fitted on luma came out 1-2 % of its side large,
    # reading lower than where the pad is)
    level = _design_read(gray, outer, geo, camera, design)[0]
    if not (level == READS or (best[0] == READS_FAINTLY and level == READS_FAINTLY)):
        return _grey_blob_only(best, "not where its field's sides fit")
    return OutlineQuad(outer, np.zeros((2, 4)), _mean_side(outer), rms, field_px=field,
                       read_after_fit=level != READS), "ok"


READS, READS_FAINTLY = 2, 1  # :func:`_design_read`'s levels (0: it does not read as the design)
GREY_REFIT_CANDIDATES = 3  # where no blob reads as the design, so many of the most alike are read again, fitted
GREY_SIDES_MAX_RMS_PX = 0.6  # a whole pad's sides fit its blob's neighbourhood this well (px; its ground is textured)


def _grey_blob_only(best: tuple, why: str) -> tuple:
    """``(OutlineQuad, "ok")``: the outer square of a grey frame's bright blob that reads as the pad's
    design (``best``: level, correlation, quad), where its white field's sides do not fit (``why``),
    its corners the blob's alone (``hull_only``): the localizer takes it only where the design's fit
    places it, and only where the image there reads as the design (``read_after_fit``).  A small
    pad's field need not stand out by its edges: fzu164's 0.6 m pad under a midday sun, a grey
    camera behind a barrel lens, 34-65 px, its border's checker as bright as the field around
    its squares: the blob's square read as the design 1-4 px from the labelled corners (0.82-0.90;
    at the labels 0.93-0.95), the field's sides fitted 5-14 px off or not at all, and the pad was lost
    from 7 m to 3.7 m."""
    return OutlineQuad(best[2], np.zeros((2, 4)), _mean_side(best[2]), float("inf"), read_after_fit=True,
                       hull_only=f"the pad's design is seen in a grey frame, but {why}: its corners a blob's"), "ok"


def _grey_sides_fitted(gray: np.ndarray, outer: np.ndarray, camera: Camera | None):
    """``(outer,)``: a blob read as the whole pad, its sides fitted on luma where they meet the ground
    (:func:`refine_quad` in the pad's neighbourhood), or ``None`` where they do not fit."""
    side_px = _mean_side(outer)
    g, lo = _window(gray, outer, int(np.ceil(0.3 * side_px + 8)))
    fitted, rms = refine_quad(g, outer - lo, half_width=float(np.clip(0.05 * side_px, 1.5, 3.0)), camera=_shifted(camera, *lo))
    if fitted is None or rms > GREY_SIDES_MAX_RMS_PX:
        return None
    return (fitted + lo,)


def _grey_field_fitted(rgb: np.ndarray, outer: np.ndarray, geo: PadGeometry, camera: Camera | None):
    """``(outer, field, line rms)``: the white field's sides fitted on luma from where the outer square
    ``outer`` puts them (:func:`_field_fit`, in the pad's neighbourhood only), and the outer square
    where the fitted field puts it; ``None`` where they do not fit."""
    side_px = _mean_side(outer)
    rgb_w, lo = _window(rgb, outer, int(np.ceil(0.3 * side_px + 8)))
    got = _field_fit(rgb_w, outer - lo, geo, _shifted(camera, *lo), max(3.0, 0.15 * side_px), rounds=FIELD_FIT_ROUNDS)
    if got is None:
        return None
    field = got[0] + lo
    fitted = _outer_of_field(field, geo, camera)
    if fitted is None or not np.isfinite(fitted).all():
        return None
    return fitted, field, got[3]


def _design_read(gray: np.ndarray, outer: np.ndarray, geo: PadGeometry, camera: Camera | None,
                 design: PadDesign) -> tuple:
    """``(level, best correlation)``: how the grey image through the outer square ``outer`` reads as the
    pad's design.  :data:`READS`: at :data:`GREY_MIN_NCC`, leading the next naming by :data:`GREY_MIN_LEAD`,
    or where that lead falls short, named alike by the design's asymmetric part correlating
    :data:`GREY_MIN_ASYM_NCC` and leading by :data:`GREY_MIN_ASYM_LEAD`; :data:`READS_FAINTLY`: so, but
    that part correlating only :data:`GREY_NEAR_ASYM_NCC`; else 0.  Also where the lead falls short of
    :data:`DESIGN_MIN_LEAD`, so that :func:`name_by_design` names nothing: a far pad with fine texture
    (an even grey at a sample per pixel) reads alike under every quarter turn but its markers (a 1.6 m
    pad with 0.2 m markers at 27-30 px: 0.98 against 0.94-0.95, its asymmetric part 0.77 against
    -0.25), and was lost."""
    k, scores = name_by_design(gray, outer, geo, camera, design)
    o = np.sort(scores)
    if o[-1] < GREY_MIN_NCC:
        return 0, float(o[-1])
    if k is not None and o[-1] - o[-2] >= GREY_MIN_LEAD:
        return READS, float(o[-1])
    # the plain naming's lead short of GREY_MIN_LEAD, or even of DESIGN_MIN_LEAD (k None): what a
    # quarter turn changes decides
    a = asymmetric_design_scores(gray, outer, geo, camera, design)
    if a is None:
        return 0, float(o[-1])
    ao = np.sort(a)
    if int(np.argmax(a)) != int(np.argmax(scores)) or ao[-1] - ao[-2] < GREY_MIN_ASYM_LEAD:
        return 0, float(o[-1])
    return (READS if ao[-1] >= GREY_MIN_ASYM_NCC else READS_FAINTLY if ao[-1] >= GREY_NEAR_ASYM_NCC else 0), float(o[-1])


def _field_agrees(rgb: np.ndarray, quad_px: np.ndarray, geo: PadGeometry, camera: Camera | None) -> bool:
    """Whether the white field, fitted on luma in the outline's window from where ``quad_px`` puts
    it, is found there: its four sides fit (a hidden part of the field breaks a side) and no corner
    lies further than a corner may move."""
    side_px = _mean_side(quad_px)
    crop, lo = _window(rgb, quad_px, int(np.ceil(0.3 * side_px + 8)))
    got = _field_fit(crop, quad_px - lo, geo, _shifted(camera, *lo), max(5.0, 0.25 * side_px))
    return got is not None and got[1] <= max(3.0, 0.1 * side_px)


FIELD_CONFIRMS_PX, FIELD_CONFIRMS_SHARE = 1.0, 0.025  # the field's outer square where the colour's quad is (_field_rescue)


def _field_rescue(rgb: np.ndarray, quad_px: np.ndarray, geo: PadGeometry, camera: Camera | None) -> tuple | None:
    """``(outer quad, field quad, washed)`` or ``None``: the outline read from the white field's luma edges
    where its colour swelled past the pad so far that the border's band check failed (``rgb`` the
    outline's fit window, ``camera`` shifted to it: a whole 1080p frame costs milliseconds).

    JPEG's half-resolution chroma smears the magenta border onto a light platform or pavement
    beside it; on a 25-60 px pad the colour hull and the sides fitted to it then lie 5-10 px out on
    one or two sides (a corner 10-30 % of the side off), and the band check refuses the pad (most
    of the refusals of pad-visible, unblurred JPEG frames).  Luma keeps the field's edge (white
    against the checker) sharp: it is fitted from the swollen prediction with a reach of a quarter
    of the side (refitted from where each fit ended: the worst field corner's median error on such pads
    of the conditions suite 2.4 % of the side with one fit, 1.5 % with three, as the field's
    usual fit does at those sizes), and the
    outer square put where the field's homography puts it.  That quad must
    then pass the band checks the colour's did not, or lie where the colour's sides put the pad.

    The band check stands in for a second look at where the sides are; the field's luma edges are
    one, independent of the colour.  A glossy pad's glare can wash a stretch of its band to the
    ground's grey (fz216: a blue band on snow under a high sun, its chroma there 0.06 of the rest):
    the band is missing there for the labelled outline too, and every view of that pad was refused
    from 11 m down.  Where the field's outer square and the colour's quad agree within
    :data:`FIELD_CONFIRMS_SHARE` of the side (at least :data:`FIELD_CONFIRMS_PX`), the sides are where
    both put them, whatever washed the band (``washed``: then the pad is not what its design draws,
    and its design is not fitted to it); a side fitted to a wrong edge lies 3-10 px from the
    field's (the rescue's own case, and then the field's quad must show the band)."""
    side_px = _mean_side(quad_px)
    got = _field_fit(rgb, quad_px, geo, camera, max(5.0, 0.25 * side_px), rounds=FIELD_FIT_ROUNDS)
    if got is None:
        return None
    field = got[0]
    outer = _outer_of_field(field, geo, camera)
    if outer is None or _corner_missing(rgb, outer, geo, camera):
        return None
    missing = _band_missing(rgb, outer, geo, camera)
    if float(np.max(np.linalg.norm(outer - quad_px, axis=1))) <= max(FIELD_CONFIRMS_PX, FIELD_CONFIRMS_SHARE * side_px):
        return outer, field, missing  # both readings put the sides there
    if not got[2] or missing:  # (a swollen colour's field must show the band)
        return None
    return outer, field, False


def name_outline(found: OutlineQuad, pad_geometry: PadGeometry, yaw_hint_corner0: np.ndarray | None = None,
                 hint_from: str = "previous", use_cue: bool = True) -> tuple:
    """``(Detection | None, reason)``: the corners of ``found`` named TL, TR, BR, BL by the cue corner
    (bottom-right on hvloc's pads), or, when it cannot be read (or ``use_cue`` is off: its reading
    was refused), by ``yaw_hint_corner0``: the predicted TL pixel (2,), or the predicted pixels of
    all four corners (4, 2), TL first (``hint_from`` says where the prediction came from).

    Four predicted corners name the outline by its shape: the naming whose corners, taken about
    their centre, lie nearest the prediction's about its own.  A prediction shifted by more than
    half the pad's side (an old or slightly wrong pose over a 25 px pad far away, where 0.5 m is
    20 px) then still names it; the nearest corner to a shifted TL pixel is another corner."""
    refined = found.quad_px
    info_yellow = "colour {}, brightness {}".format(*([round(float(y), 2) for y in row] for row in found.cue))
    order = None
    k, how = cue_naming(found, pad_geometry) if use_cue else (None, "")
    if k is not None:
        order = [(k + j) % 4 for j in range(4)]
    elif yaw_hint_corner0 is not None:
        hint = np.asarray(yaw_hint_corner0, np.float64)
        if hint.shape == (4, 2):
            k = int(np.argmin([np.linalg.norm((np.roll(refined, -j, axis=0) - refined.mean(axis=0))
                                              - (hint - hint.mean(axis=0))) for j in range(4)]))
        else:
            k = int(np.argmin(np.linalg.norm(refined - hint, axis=1)))
        order = [k, (k + 1) % 4, (k + 2) % 4, (k + 3) % 4]
        how = hint_from
    if order is None:
        return None, f"pad found but its yaw cue is unreadable ({info_yellow}) and there is no prior"
    info = {"yaw_from": how, "side_px": found.side_px, "line_rms": found.line_rms}
    if found.read_after_fit:
        info["read_after_fit"] = True
    if found.hull_only:
        info["hull_only"] = found.hull_only
    if found.washed:
        info["washed"] = True
    if found.edge_fitted:  # (the localizer checks the smear its IMU predicts against what an edge fit holds to)
        info["edge_fit_smear_px"] = round(float(found.smear_px), 2)
    if found.smear_px > SMEARED_PX or found.sigma_per_smear == EDGE_SIGMA_PER_SMEAR:
        # placed by the border's centroid in linear light, which a tone curve not known exactly
        # (a camera's is not sRGB) moves by a share of the smear: ~0.5 px outward at 5-12 px of smear
        # on the conditions suite's gusty descent (the four corners' own 0.3 px made such poses'
        # covariances 3-5x too tight); by its fitted profile, less (:func:`_deblurred`); by an edge
        # fit under smear, more (:data:`EDGE_SIGMA_PER_SMEAR`)
        info["px_sigma_blur"] = round(found.sigma_per_smear * found.smear_px, 3)
    if found.sigma_scale is not None:  # a pad cut by the image's edge: its hidden corner is less sure
        info.update(corners_seen=int(np.sum(found.sigma_scale == 1.0)),
                    px_sigma_scale=[round(float(v), 3) for v in found.sigma_scale[order]])
    if found.field_px is not None:  # the colour edges are smeared: the field's luma edges instead
        if found.field_sigma_px > 0:
            info["px_sigma_field"] = round(float(found.field_sigma_px), 3)
        return Detection(pad_geometry.field_corners, found.field_px[order], "outline", {**info, "corners": "field"}), "ok"
    refined = refined[order]
    pts = pad_geometry.outer_corners
    return Detection(pts, refined, "outline", info), "ok"


def cue_naming(found: OutlineQuad, pad_geometry: PadGeometry) -> tuple:
    """``(k, how)``: image corner ``k`` of ``found`` is the pad's TL corner as its yaw cue names it
    (:func:`_cue_corner_seen`: ``how`` says by what), or ``(None, "")`` where the cue is unreadable.
    The same index as :func:`name_by_design`'s."""
    k, how = _cue_corner_seen(found.cue)
    return (None, "") if k is None else ((k - _cue_corner(pad_geometry)) % 4, how)


class PadDesign:
    """The pad's printed design (``pad.png``) in grey, drawn at a given number of samples across
    (:meth:`at`), for :func:`name_by_design`."""

    def __init__(self, texture_rgb: np.ndarray):
        self.gray = cv2.cvtColor(np.ascontiguousarray(texture_rgb), cv2.COLOR_RGB2GRAY)
        self._at, self._turned = {}, {}

    def at(self, n: int) -> np.ndarray:
        """(n, n) float grey: each sample the mean of its cell (the image's pixel), a little blurred
        as a lens and a codec blur it."""
        d = self._at.get(n)
        if d is None:
            d = cv2.resize(self.gray, (n, n), interpolation=cv2.INTER_AREA).astype(np.float64)
            d = self._at[n] = cv2.GaussianBlur(d, (0, 0), 0.6)
        return d

    def turned(self, n: int, relative: bool = False) -> np.ndarray:
        """:meth:`at` less its mean over the four quarter turns (:func:`_asymmetric`): what a turn changes;
        ``relative``: of the design read relative to its local brightness (:func:`_relative`)."""
        d = self._turned.get((n, relative))
        if d is None:
            d = self._turned[(n, relative)] = _asymmetric(_relative(self.at(n)) if relative else self.at(n))
        return d


@functools.lru_cache(maxsize=64)
def _design_cells(side_m: float, n: int) -> np.ndarray:
    """``(n * n, 2)`` pad-plane centres of the design's cells drawn ``n`` across (:meth:`PadDesign.at`),
    row by row: row i is y = s/2 - (i + 0.5) s/n, column j x = (j + 0.5) s/n - s/2 (read-only)."""
    c = (np.arange(n) + 0.5) / n * side_m - side_m / 2
    X, Y = np.meshgrid(c, -c)
    cells = np.column_stack([X.ravel(), Y.ravel()])
    cells.setflags(write=False)
    return cells


DESIGN_MIN_NCC = 0.6    # the naming's correlation with the design (over ground, quads reach 0.58 at most)
DESIGN_MIN_LEAD = 0.04  # ... and its lead over the next naming's
_DESIGN_TURN = -1       # np.rot90's direction that takes naming 0's samples to naming k's


def _design_samples(gray: np.ndarray, quad_px: np.ndarray, geo: PadGeometry, camera: Camera | None) -> tuple | None:
    """``(v, seen, n)``: the image sampled at the design's ``n`` x ``n`` cells (:func:`_design_cells`,
    a cell per pixel across the pad, 12-64) as the quad's own order names them, row by row, and which
    of them lie in the image; ``None`` for a quad not finite or not in front of the camera.  The grid
    is the same under a quarter turn, so naming k compares it with the design turned k quarters."""
    quad_px = np.asarray(quad_px, np.float64)
    if not np.isfinite(quad_px).all():
        return None
    side_px = float(np.mean(np.linalg.norm(quad_px - np.roll(quad_px, 1, axis=0), axis=1)))
    n = int(np.clip(round(side_px), 12, 64)) if math.isfinite(side_px) else 64
    px = _through_quad(quad_px, geo, camera, _design_cells(geo.side_m, n))
    if px is None:
        return None
    v = sample_at(gray, px)
    return v, _seen(px, gray.shape), n


def _relative(a: np.ndarray) -> np.ndarray:
    """An (n, n) grid of grey over its own local mean (a Gaussian of a tenth of the side): brightness
    relative to the pad's neighbourhood, as a glossy pad's sheen and its stains, which vary over a fifth
    of the side and more, scale the design's contrast where they lie."""
    return a / np.maximum(cv2.GaussianBlur(a, (0, 0), a.shape[0] / 10.0), 1.0)


def _asymmetric(a: np.ndarray) -> np.ndarray:
    """An (n, n) grid less its mean over the four quarter turns: what a quarter turn changes."""
    return a - (a + np.rot90(a, 1) + np.rot90(a, 2) + np.rot90(a, 3)) / 4.0


def asymmetric_design_scores(gray: np.ndarray, quad_px: np.ndarray, geo: PadGeometry, camera: Camera | None,
                             design: PadDesign) -> np.ndarray | None:
    """(4,) the correlation, per naming as :func:`name_by_design`'s, of the image's part through
    ``quad_px`` that a quarter turn changes with the design's (:data:`GREY_MIN_ASYM_NCC`): the finder
    markers and the texture without the field and ring that every naming shares.  ``None`` where
    any of the pad lies outside the image (the turns would compare it with nothing).

    Each naming's is the better of two reads: of the grey as sampled, and of the grey relative to its
    local brightness (:func:`_relative`, the design's alike).  A glossy, stained pad's sheen scales the
    markers' contrast where it lies: through the labelled outline of the fuzz's glossy grey scenes
    (fz349, fz363, fz382, fz387; 26-140 px) the plain read came to 0.55 in 27-82 % of views by scene,
    the better of the two in 36-94 %; on five other grey scenes both in every view.  The relative read
    alone loses small pads, whose markers are a few pixels (a tenth of the side is their size: fz127,
    fz153 fell 1.0 -> 0.85-0.8).  Outlines misplaced by 8-25 % of the side, scaled 0.85-1.15 or with a
    corner a fifth off (1,280 of them) and named alike read 0.44 at most either way, ground 0.31
    (scratch/asymhp.py)."""
    got = _design_samples(gray, quad_px, geo, camera)
    if got is None or not got[1].all():
        return None
    v, _, n = got
    v = v.reshape(n, n)
    scores = np.full(4, -1.0)
    for relative in (False, True):
        va, da = _asymmetric(_relative(v) if relative else v).ravel(), design.turned(n, relative)
        scores = np.maximum(scores, [_ncc(va, np.rot90(da, _DESIGN_TURN * k).ravel()) for k in range(4)])
    return scores


def name_by_design(gray: np.ndarray, quad_px: np.ndarray, geo: PadGeometry, camera: Camera | None,
                   design: PadDesign) -> tuple:
    """``(k | None, scores)``: image corner ``k`` of ``quad_px`` is the pad's TL corner, read from the
    pad's whole printed design; ``scores`` (4,) the correlation of each naming.

    Far away the yaw cue is a square of 3 or 4 pixels whose colour JPEG smears, and glare or a dark
    platform beside it can hide its brightness too.  The design as a whole is not symmetric under
    a quarter turn: three finder markers in three of the field's corners and none in the fourth,
    the cue, the texture's blobs.  At 25 px across, the markers are dark blots that still show
    which corner is empty.  The image is sampled through the quad's homography (the lens included)
    at one point per pixel across the pad, for each of the four namings, and correlated with the
    design drawn at that scale; the best naming wins when it correlates at least
    :data:`DESIGN_MIN_NCC` and leads the next by :data:`DESIGN_MIN_LEAD`.  Over ~1,300 outlines
    found in scenes of every condition the generator makes (1-2 m pads at 25-500 px, JPEG, glare,
    fisheye), the best naming was the right one in every view; a wrong one correlates 0.6-0.85
    where the right one reaches 0.8-0.99."""
    scores = np.full(4, -1.0)
    got = _design_samples(gray, quad_px, geo, camera)
    if got is None:
        return None, scores
    v, seen, n = got
    if seen.mean() < 0.6:  # mostly outside the image: too little of the design to tell
        return None, scores
    v = v[seen]
    for k in range(4):
        scores[k] = _ncc(v, np.rot90(design.at(n), _DESIGN_TURN * k).ravel()[seen])
    o = np.sort(scores)
    if o[-1] < DESIGN_MIN_NCC or o[-1] - o[-2] < DESIGN_MIN_LEAD:
        return None, scores
    return int(np.argmax(scores)), scores


# glare's chroma: a glossy pad under a high sun mirrors the sky's white light over its colour, which
# keeps the colour's chroma and raises its value: unseen61's magenta border at noon read sRGB
# (236, 207, 229), chroma 0.08-0.14 of its value, where the shadow's bar is 0.15.  Bright pixels only
# (value 128 and more): in the dark a few levels of noise are that much of the value.  Tried only
# where the shadow's bar finds no ring: with it first, a milder glare's lobe over the pad's rim
# swelled a ring the bar of 0.15 reads exactly (test_outline_is_found_under_glare.., 2.1 px)
GLARE_MIN_CHROMA = 0.07
GLARE_MIN_VALUE = 128


def _colour_evidence(rgb: np.ndarray, hsv: np.ndarray, rng, colour_rgb, min_chroma: float = 0.15,
                     bright_chroma: float | None = None) -> np.ndarray:
    """Pixels whose chromaticity relative to their own brightness says ``colour_rgb``, lit or not.

    In a hard shadow the pad is lit by the sky alone: darker and much less saturated (the border is
    sRGB (67, 51, 64) where it is (230, 40, 200) in the sun), below the segmentation range ``rng``.
    Kept: the colour's hue (+-2x the range's half-width), chroma along the colour's direction (for
    the magenta border about ``(R + B) / 2 - G``) at least ``min_chroma`` of the pixel's value
    (``bright_chroma`` where the value is :data:`GLARE_MIN_VALUE` or more: a glare-washed pad), and
    a value of at least 16.  All in uint8 OpenCV passes (it runs on every Approaching frame)."""
    lo_h, hi_h = float(rng.lo[0]), float(rng.hi[0])
    half = ((hi_h - lo_h) % 180.0) / 2.0
    wide = type(rng)(np.array([(lo_h - half) % 180.0, 0, 16]), np.array([(hi_h + half) % 180.0, 255, 255]),
                     hue_wraps=bool((lo_h - half) % 180.0 > (hi_h + half) % 180.0))
    hue_ok = _hsv_mask(hsv, wide)
    d = _colour_direction(colour_rgb, np.float32)
    chroma = cv2.transform(np.ascontiguousarray(rgb), d[None, :].astype(np.float32))  # uint8, negatives at 0
    value = np.ascontiguousarray(hsv[..., 2])
    need = cv2.multiply(value, min_chroma, dtype=cv2.CV_8U)
    if bright_chroma is not None:
        need = np.where(value >= GLARE_MIN_VALUE, cv2.multiply(value, bright_chroma, dtype=cv2.CV_8U), need)
    ev = cv2.bitwise_and(hue_ok, cv2.compare(chroma.reshape(need.shape), need, cv2.CMP_GE))
    # lone specks of it (sensor noise on grey ground) are no shadowed pad: 2x2 opening
    return cv2.morphologyEx(ev, cv2.MORPH_OPEN, np.ones((2, 2), np.uint8))


def _around(mask: np.ndarray) -> tuple | None:
    """``(x0, y0, x1, y1)``: the box of the mask's blobs (specks opened away), grown on every side by
    twice its size (a lit corner of a mostly shadowed pad) or a tenth of the image, clipped to the
    image; ``None`` when there is no blob."""
    core = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((2, 2), np.uint8))
    if not cv2.countNonZero(core):
        return None
    x, y, w, h = cv2.boundingRect(core)
    H, W = mask.shape
    m = max(2 * max(w, h), min(H, W) // 10)
    return max(x - m, 0), max(y - m, 0), min(x + w + m, W), min(y + h + m, H)


def _shadowed_too(rgb: np.ndarray, hsv: np.ndarray, strong: np.ndarray, rng, colour_rgb) -> np.ndarray:
    """A colour mask grown into its shadowed parts (hysteresis, as Canny does for edges): the
    :func:`_colour_evidence` pixels connected to ``strong``."""
    weak = _colour_evidence(rgb, hsv, rng, colour_rgb) | strong
    n, lab = cv2.connectedComponents(weak, connectivity=8)
    if n <= 1:
        return strong
    keep = np.zeros(n, np.uint8)
    keep[lab[strong > 0]] = 255  # every component holding a strong pixel
    keep[0] = 0
    return keep[lab]


def _border_channel(rgb: np.ndarray) -> np.ndarray:
    """(R + B) / 2 - G: high on the magenta border, low on natural ground.  Linear in the colours,
    so a blurred edge crosses its half level where the edge is (a chroma such as max - min is not
    linear, and put the outline ~0.3 px inside the pad).  The yellow cue corner is dark here; its
    sides are trimmed by :func:`refine_quad` and rejected as outliers."""
    f = rgb.astype(np.float32)
    return 0.5 * (f[..., 0] + f[..., 2]) - f[..., 1]


def _mask_share(mask: np.ndarray, quad: np.ndarray) -> float:
    """Share of the quad's pixels that are set in ``mask``."""
    x, y, w, h = cv2.boundingRect(quad.astype(np.float32))
    x, y = max(x, 0), max(y, 0)
    sub = mask[y:y + h, x:x + w]
    if sub.size == 0:
        return 0.0
    poly = np.zeros_like(sub)
    cv2.fillConvexPoly(poly, np.round(quad - [x, y]).astype(np.int32), 255)
    n = cv2.countNonZero(poly)
    return float(cv2.countNonZero(sub & poly)) / max(n, 1)


# ----------------------------------------------------------------------------- Adjustment

# a markers pose needs this many of a set's nested squares refined per marker found (on average):
# the squares that failed moved over half a module from where the markers' outer corners put them
# (blur, JPEG, a marker cut by the image's edge), and the few left pose a pad at 0.4 m from one
# 4-corner square 3.6 degrees off the IMU, 10 % of the height sideways
MIN_SQUARES_PER_MARKER = 2
# a square whose corners lie this share of a module off the other squares' homography, together, slipped (_slipped_squares_out)
SLIPPED_SQUARE_MODULES = 0.5


NO_LAYOUT = "no marker layout"


def nests_found(reason: str) -> int | None:
    """How many finder nests :func:`detect_markers` found (the most of its binarizations) where it
    says they form no marker layout; ``None`` for any other reason."""
    head, _, tail = reason.partition(" finder nests, ")
    return int(head) if tail.startswith(NO_LAYOUT) and head.isdigit() else None


def detect_markers(gray: np.ndarray, pad_geometry: PadGeometry, camera: Camera | None = None, roi=None,
                   method: str = "otsu", rgb: np.ndarray | None = None, up_C: np.ndarray | None = None,
                   prior: np.ndarray | None = None, design: PadDesign | None = None) -> tuple:
    """Finder markers -> all nested-square corners, plus the pad's outer corners when the whole
    outline is in view and ``rgb`` is given (they double the baseline, which pins the tilt).
    With ``prior`` (a recent ``T_P_C``), two markers of a set, the third out of view or unreadable,
    are named by where the prior puts the set's markers (:func:`_pair_by_prior`); without one, with
    ``design``, by the pad's printed design around them (:func:`_pair_by_design`; the IMU's ``up_C``
    makes the view head-on, else it is taken for a nadir camera's).
    Returns ``(Detection | None, reason)``."""
    img, x0, y0 = _crop(gray, roi)
    if img.shape[0] < 16 or img.shape[1] < 16:
        return None, "image too small"
    triples, nests, all_nests = [], [], []
    # the configured binarization first; the other one when it fails (shadows across a marker
    # defeat a global Otsu threshold, a local one copes)
    for m in (method, "adaptive" if method == "otsu" else "otsu"):
        nests = mk.find_finder_nests(mk.binarize_dark(img, m))
        all_nests.append(nests)
        triples = mk.find_marker_triples(nests, rectify=_head_on(camera, up_C, x0, y0)) if len(nests) >= 3 else []
        if triples:
            break
    sets = {}
    for m in pad_geometry.markers_in(kind="finder"):
        sets.setdefault(m.set, {})[m.name] = m
    lin = None  # the crop in light, made once a marker set is named: its squares' corners are placed there
    if not triples:
        by = "prior" if prior is not None else "design" if design is not None else None
        tried = []
        for cand in all_nests if by is not None and camera is not None else []:
            centres = sorted((round(float(n.center_px[0]), 1), round(float(n.center_px[1]), 1)) for n in cand)
            if centres in tried:  # both binarizations found the same nests: the same answer
                continue
            tried.append(centres)
            if by == "prior":
                named, extra = _pair_by_prior(cand, sets, camera, prior, x0, y0), {}
            else:
                named = _pair_by_design(img.astype(np.float32), cand, sets, pad_geometry, camera, up_C, design, x0, y0)
                named, extra = (named[:3], named[3]) if named is not None else (None, {})
            if named is not None:
                set_name, quads, module_px = named
                lin = srgb_to_linear(img) if lin is None else lin
                got = _marker_corners(lin, sets[set_name], quads, module_px, camera, x0, y0)
                if got is not None and len(got[0]) >= MIN_SQUARES_PER_MARKER * len(quads):
                    pts_P, px, _ = got
                    return Detection(np.concatenate(pts_P), np.concatenate(px), "markers",
                                     {"sets": [set_name], "named_by": by, "markers_seen": sorted(quads), **extra}), "ok"
        return None, f"{max(len(n) for n in all_nests)} finder nests, {NO_LAYOUT}"
    expect = {s: ms["Top"].size_m / (2 * abs(ms["Top"].center[0])) for s, ms in sets.items() if "Top" in ms}
    pts_P, px = [], []
    used, few = [], ""
    for t in triples:
        ratio = t.spacing_ratio
        set_name = min(expect, key=lambda s: abs(math.log(ratio / expect[s])))
        if abs(math.log(ratio / expect[set_name])) > 0.5 or set_name in used:
            continue
        ms = sets[set_name]
        quads = {}
        for name, nest in t.by_name.items():
            quad = _contour_quad(nest.outline)
            if quad is None:
                break
            quads[name] = _order_like(quad, ms[name].outer_corners[:, :2], t)
        if len(quads) != 3:
            continue
        module_px = math.sqrt(np.mean([n.area_px for n in t.by_name.values()])) / 7.0
        lin = srgb_to_linear(img) if lin is None else lin
        got = _marker_corners(lin, ms, quads, module_px, camera, x0, y0)
        if got is None or len(got[0]) < MIN_SQUARES_PER_MARKER * len(quads):
            few = f"{0 if got is None else len(got[0])} of {sum(len(ms[n].squares) for n in quads)} squares"
            continue
        pts_P += got[0]
        px += got[1]
        used.append(set_name)
        if rgb is not None and set_name == "corner":
            outer = _refine_outline_from(rgb, pad_geometry, got[2], x0, y0, camera)
            if outer is not None:
                pts_P.append(pad_geometry.outer_corners)
                px.append(outer)
    if not pts_P:
        return None, f"markers found but too few of their squares refined ({few})" if few else \
            "markers found but no corner refined"
    return Detection(np.concatenate(pts_P), np.concatenate(px), "markers", {"sets": used}), "ok"


def _marker_corners(g: np.ndarray, ms: dict, quads: dict, module_px: float, camera: Camera | None, x0: int, y0: int):
    """``(pad points, pixels, predict)`` or ``None``: the nested squares' corners of the markers
    ``quads`` names (their outer corners in the image (crop), ordered as the marker's), predicted
    by the homography of those outer corners and refined on ``g`` (the crop, float32: in light); a
    corner whose refinement moved it further than half a module is left out.  ``predict``: pad-plane
    ``(N, 2)`` metres -> the crop's pixels, through the lens, by the homography of the refined corners
    (of the outer ones where fewer than two squares refined)."""
    src = [ms[name].outer_corners[:, :2] for name in quads]
    cam = _shifted(camera, x0, y0)
    lens = cam is not None and cam.has_distortion
    dst = np.concatenate(list(quads.values()))
    # the homography holds on the ideal pinhole's pixels, not the lens's: under a wide lens a
    # marker near the image's edge, seen obliquely, had its inner squares predicted 4-14 px off
    # (further than the refinement reaches, which then settled on the wrong edge)
    ideal = cam.undistort_pixels(dst) if lens else dst
    if not np.isfinite(ideal).all():  # (a fisheye's corner at 90 degrees or more from its axis)
        return None
    H, _ = cv2.findHomography(np.concatenate(src), ideal, 0)
    if H is None:
        return None

    def through(H):  # pad-plane (N, 2) metres -> the crop's pixels by the homography H, through the lens
        def f(xy):
            ideal = cv2.perspectiveTransform(np.asarray(xy, np.float64).reshape(-1, 1, 2), H)[:, 0, :]
            return cam.distort_pixels(ideal) if lens else ideal
        return f

    hw = float(np.clip(0.45 * module_px, 0.8, 3.0))
    squares = [sq.corners for name in ("Top", "Right", "Bottom") if name in quads for sq in ms[name].squares]
    guesses = np.stack([through(H)(P[:, :2]) for P in squares])
    refined, _ = refine_quads(g, guesses, hw, camera=cam)
    pts_P, px = [], []
    for P, guess, ref in zip(squares, guesses, refined):
        if not np.isfinite(ref).all() or np.max(np.linalg.norm(ref - guess, axis=1)) > max(1.5, 0.5 * module_px):
            continue
        pts_P.append(P)
        px.append(ref + [x0, y0])
    # the refined squares in the ideal pinhole's pixels of the crop, where one homography holds them all
    ideal_px = [cam.undistort_pixels(q - [x0, y0]) if lens else q - [x0, y0] for q in px]
    if len(pts_P) >= 4:
        keep = _slipped_squares_out(pts_P, ideal_px, module_px)
        pts_P, px, ideal_px = ([v for v, k in zip(vs, keep) if k] for vs in (pts_P, px, ideal_px))

    def predict(xy):
        # what lies beyond the markers (the pad's outer corners) is predicted by the refined
        # corners, not the contours' pixel-level quads: from those, a 200 px pad's far corner was
        # predicted 1-2 px off on views mixed in display values, 2-4.6 px on views summed in light
        # (its refinement's reach, 2 % of the side), from these 0.1-0.2 px.  (Fitted when asked:
        # only the markers pose that joins the outer corners asks.)
        if len(pts_P) >= 2:
            Hr, _ = cv2.findHomography(np.concatenate(pts_P)[:, :2], np.concatenate(ideal_px), 0)
            if Hr is not None and np.isfinite(Hr).all():
                return through(Hr)(xy)
        return through(H)(xy)

    return pts_P, px, predict


def _slipped_squares_out(pts_P: list, px: list, module_px: float) -> list:
    """``[bool]``: which of a marker set's refined squares (pad points ``pts_P``, ideal pixels ``px``,
    one ``(4, ...)`` array each) to keep.  A square whose contour or prediction was a module off (a
    dirt splotch joined to its dark ring, glare eating into it) is refined onto the next ring's edges:
    its four corners lie a module off together, within the half module a refinement may move a
    corner, and the homography of the set still fits them by tilting the pad (fz537 at 1.4 m: one outer
    square 5.6-6.3 px off with 5.7 px modules, the pad's outer corners it predicted 7-9 px off, the
    pose 5 degrees off at RMS 0.45 px).  Each square is held against the homography of the others: the
    one lying furthest off, by its corners' mean, over :data:`SLIPPED_SQUARE_MODULES` of a module (and
    1.5 px), is left out, and the rest held again, while four squares or more are left."""
    keep = [True] * len(pts_P)
    while sum(keep) > 4:
        worst, off = None, max(1.5, SLIPPED_SQUARE_MODULES * module_px)
        for i in (j for j, k in enumerate(keep) if k):
            others = [j for j, k in enumerate(keep) if k and j != i]
            H, _ = cv2.findHomography(np.concatenate([pts_P[j][:, :2] for j in others]),
                                      np.concatenate([px[j] for j in others]), 0)
            if H is None or not np.isfinite(H).all():
                return keep
            at = cv2.perspectiveTransform(np.asarray(pts_P[i][:, :2], np.float64).reshape(-1, 1, 2), H)[:, 0, :]
            d = float(np.linalg.norm(np.mean(px[i] - at, axis=0)))
            if d > off:
                worst, off = i, d
        if worst is None:
            break
        keep[worst] = False
    return keep


def _pair_by_prior(nests: list, sets: dict, camera: Camera, prior: np.ndarray, x0: int, y0: int):
    """``(set name, {marker name: outer corners in the crop, ordered as the marker's}, module px)`` of
    two markers of one set that two of ``nests`` are, as a recent pose ``prior`` names them; or
    ``None``.

    Three markers name themselves by their right-angle triangle; two do not (any two of Top, Right,
    Bottom, either way round).  The prior says where the set's markers should lie; since it, the
    drone has moved (the image shifts) and turned a little.  Two nests are two markers when the
    similarity that takes the prior's two centres onto them turns by under 25 degrees, scales by
    0.7-1.4 and shifts by under the markers' spacing, and their sizes agree with the prior's within
    2x: a diagonal pair is 1.41x an adjacent one, another adjacent pair is turned 90 degrees, a
    reversed one 180.  Exactly one such reading must exist.  Each nest's corners are ordered as the
    prior's corners of its marker, carried by that similarity.  The pose it gives is judged as
    every marker pose is (gates against the IMU and the prior)."""
    cands = sorted(nests, key=lambda n: -n.area_px)[:4]
    found = []
    for set_name, ms in sets.items():
        names = [n for n in ("Top", "Right", "Bottom") if n in ms]
        if len(names) < 3:
            continue
        centres = camera.project_from(prior, np.array([ms[n].center for n in names])) - [x0, y0]
        corners = {n: camera.project_from(prior, ms[n].outer_corners) - [x0, y0] for n in names}
        if not np.isfinite(centres).all() or not all(np.isfinite(c).all() for c in corners.values()):
            continue
        spacing = min(np.linalg.norm(centres[i] - centres[j]) for i in range(3) for j in range(i + 1, 3))
        for i, j in itertools.combinations(range(len(cands)), 2):
            na, nb = cands[i], cands[j]
            for a, b in itertools.permutations(range(3), 2):
                vp, vo = centres[b] - centres[a], nb.center_px - na.center_px
                scale = np.linalg.norm(vo) / max(np.linalg.norm(vp), 1e-9)
                turn = math.atan2(vp[0] * vo[1] - vp[1] * vo[0], vp @ vo)
                if not (abs(turn) < math.radians(25) and 0.7 < scale < 1.4
                        and np.linalg.norm(na.center_px - centres[a]) < spacing):
                    continue
                areas = [abs(_signed_area(corners[names[k]])) * scale**2 for k in (a, b)]
                if not all(0.5 < n.area_px / max(ar, 1e-9) < 2.0 for n, ar in zip((na, nb), areas)):
                    continue
                c, sn = scale * math.cos(turn), scale * math.sin(turn)
                S = np.array([[c, -sn], [sn, c]])
                quads = {}
                for k, nest in ((a, na), (b, nb)):
                    quad = _contour_quad(nest.outline)
                    if quad is None:
                        break
                    quads[names[k]] = _nearest_order(quad, (corners[names[k]] - centres[a]) @ S.T + na.center_px)
                if len(quads) == 2:
                    found.append((set_name, quads, math.sqrt(np.mean([n.area_px for n in (na, nb)])) / 7.0))
    if len(found) != 1:
        return None
    return found[0]


_NADIR_UP = np.array([0.0, 0.0, -1.0])  # the up a camera looking straight down sees


def _nearest_order(quad: np.ndarray, want: np.ndarray, seen_as: np.ndarray | None = None) -> np.ndarray:
    """``quad``'s corners in the order (a roll, either way round) that puts them nearest ``want``'s;
    ``seen_as``: the same corners in the coordinates ``want`` is in (default: ``quad``'s own)."""
    seen = np.asarray(quad if seen_as is None else seen_as, np.float64)
    idx = _ORDERS  # (8, 4): each order's corner indices, the first nearest one wins
    k = int(np.argmin(np.linalg.norm(seen[idx] - np.asarray(want, np.float64), axis=2).sum(axis=1)))
    return np.asarray(quad)[idx[k]]


# the eight orders of a quad's corners: rolled by 0-3 (np.roll's direction), then reversed and rolled
_ORDERS = np.array([np.roll(np.arange(4), r) for r in range(4)] + [np.roll(np.arange(4)[::-1], r) for r in range(4)])


PAIR_DESIGN_MIN_NCC = 0.7    # the right naming's correlation with the design beyond the two markers
PAIR_DESIGN_MIN_LEAD = 0.15  # ... and its lead over every other naming's (on the same square: by what a turn changes)
PAIR_DESIGN_MIN_SEEN = 0.2   # the share of the pad's cells, beyond the two markers, in view
PAIR_SAME_SQUARE = 0.25      # readings whose pad centres lie closer than this share of its side put it on one square


def _pair_by_design(g: np.ndarray, nests: list, sets: dict, geo: PadGeometry, camera: Camera | None, up_C,
                    design: "PadDesign", x0: int, y0: int):
    """``(set name, {marker name: outer corners in the crop, ordered as the marker's}, module px,
    info)`` of two markers of one set that two of ``nests`` are, named by the pad's printed design
    where no recent pose names them (:func:`_pair_by_prior`); or ``None``.

    A cold start low over the pad (the outline cut by the image's edge, the third marker out of view
    or hidden) sees two nests.  Each reading of them (a set, two of its markers, either way round)
    puts the pad somewhere else around them: turned a quarter or a half, or on the nests' other
    side.  The IMU's gravity makes the view head-on, where a reading is a similarity: the nests'
    sizes must agree with their spacing as the reading's markers' do (a diagonal pair is 1.41x an
    adjacent one).  Each reading left is then placed by the homography of the two nests' corners,
    and the image, sampled where it puts the rest of the pad (the two markers' own squares left
    out: every reading puts a marker there), is correlated with the design drawn at that scale.
    The best reading is taken where it correlates at least :data:`PAIR_DESIGN_MIN_NCC`, leads every
    other by :data:`PAIR_DESIGN_MIN_LEAD`, and sees :data:`PAIR_DESIGN_MIN_SEEN` of the pad beyond
    the markers; a pair of lone finder squares on the ground correlates with nothing."""
    if camera is None or design is None:
        return None
    # without the IMU, the view taken for head-on (a nadir camera's, nearly): readings a tilt skews
    # are dropped by their sizes, or their design does not correlate
    rectify = _head_on(camera, up_C if up_C is not None else _NADIR_UP, x0, y0)
    cands = sorted(nests, key=lambda n: -n.area_px)[:4]
    readings = []
    for i, j in itertools.combinations(range(len(cands)), 2):
        na, nb = cands[i], cands[j]
        qa, qb = _contour_quad(na.outline), _contour_quad(nb.outline)
        ha, hb = rectify(qa), rectify(qb)
        if not (np.isfinite(ha).all() and np.isfinite(hb).all()):
            continue
        ca, cb = ha.mean(axis=0), hb.mean(axis=0)
        vo = cb - ca
        side_o = math.sqrt(0.5 * (abs(_signed_area(ha)) + abs(_signed_area(hb))))
        for set_name, ms in sets.items():
            names = [n for n in ("Top", "Right", "Bottom") if n in ms]
            for a, b in itertools.permutations(names, 2):
                flip = np.array([1.0, -1.0])  # pad (x, y) -> image-like (x, -y): seen from above, y is up
                vp = (ms[b].center[:2] - ms[a].center[:2]) * flip
                scale = np.linalg.norm(vo) / max(np.linalg.norm(vp), 1e-12)
                # the nests' size against their spacing, as the reading's markers' (a diagonal pair's
                # spacing is 1.41x an adjacent pair's)
                if not 0.75 < side_o / (scale * 0.5 * (ms[a].size_m + ms[b].size_m)) < 1.33:
                    continue
                turn = math.atan2(vp[0] * vo[1] - vp[1] * vo[0], vp @ vo)
                c, sn = scale * math.cos(turn), scale * math.sin(turn)
                S = np.array([[c, -sn], [sn, c]])
                quads = {}
                for name, q, hq, cq in ((a, qa, ha, ca), (b, qb, hb, cb)):
                    want = (ms[name].outer_corners[:, :2] - ms[name].center[:2]) * flip @ S.T + cq
                    quads[name] = _nearest_order(q, want, seen_as=hq)
                readings.append((set_name, quads, math.sqrt(0.5 * (na.area_px + nb.area_px)) / 7.0))
    if not readings:
        return None
    cam = _shifted(camera, x0, y0)
    s = geo.side_m
    scored = np.array([_reading_score(g, r, sets, geo, cam, design) for r in readings])  # (R, 4)
    ncc, turned, centres = scored[:, 0], scored[:, 1], scored[:, 2:]
    best = int(np.argmax(ncc))
    # readings that put the pad on the same square (a diagonal pair either way round, an adjacent
    # pair's quarter turns) sample the same pixels: what every turn of the design shares (the ring,
    # the white field, the texture's contrast) correlates alike in all of them.  They differ by what
    # a turn changes (the third marker, the texture's layout): compared on that part alone.  (Fuzz
    # seeds 131 and 161: a diagonal pair at 2-3 px modules, the right reading 0.87-0.92, the half
    # turn 0.80-0.86, refused by the plain lead; on the turned part 0.24-0.37 against -0.06-0.0.)
    quads = readings[best][1]
    side = float(np.mean([np.linalg.norm(q[0] - q[1]) for q in quads.values()])) * s \
        / sets[readings[best][0]][next(iter(quads))].size_m  # the pad's side, px
    others = np.arange(len(ncc)) != best
    same = others & (np.linalg.norm(centres - centres[best], axis=1) < PAIR_SAME_SQUARE * side)
    lead = float(ncc[best] - np.max(ncc[others & ~same], initial=-1.0))
    turn_lead = float(turned[best] - np.max(turned[same], initial=-1.0))
    if ncc[best] < PAIR_DESIGN_MIN_NCC or min(lead, turn_lead) < PAIR_DESIGN_MIN_LEAD:
        return None
    set_name, quads, module_px = readings[best]
    return set_name, quads, module_px, {"design_ncc": round(float(ncc[best]), 3), "design_lead": round(lead, 3),
                                        "design_turn_lead": round(turn_lead, 3)}


def _reading_score(g: np.ndarray, reading: tuple, sets: dict, geo: PadGeometry, cam, design: "PadDesign") -> tuple:
    """``(ncc, turned ncc, centre x, centre y)`` of a :func:`_pair_by_design` reading ``(set, quads,
    module px)``: the image beyond its two markers correlated with the design, and with the part of
    the design a quarter turn changes (:func:`_asymmetric`); the pad's centre where it puts it.
    -1 (and NaN) where it cannot be placed or too little of the pad is seen."""
    set_name, quads, module_px = reading
    ms, s = sets[set_name], geo.side_m
    n = int(np.clip(round(7.0 * module_px * s / ms[next(iter(quads))].size_m), 12, 64))  # the pad's side, px
    pts = _design_cells(s, n)
    px = _through_quad(np.concatenate(list(quads.values())), geo, cam, np.vstack([pts, [[0.0, 0.0]]]),
                       square=np.concatenate([ms[k].outer_corners for k in quads]))
    if px is None:
        return -1.0, -1.0, np.nan, np.nan
    px, centre = px[:-1], px[-1]
    beyond = np.ones(len(pts), bool)
    for name in quads:  # every reading puts a marker where the nests are: they tell nothing
        half = 0.5 * ms[name].size_m + s / n
        beyond &= np.abs(pts - ms[name].center[:2]).max(axis=1) > half
    seen = np.isfinite(px).all(axis=1) & _seen(px, g.shape) & beyond
    if seen.sum() < PAIR_DESIGN_MIN_SEEN * beyond.sum() or seen.sum() < 16:
        return -1.0, -1.0, centre[0], centre[1]
    v = sample_at(g, px[seen])
    return _ncc(v, design.at(n).ravel()[seen]), _ncc(v, design.turned(n).ravel()[seen]), centre[0], centre[1]


def _refine_outline_from(rgb, pad_geometry, predict, x0, y0, camera):
    """The pad's outer corners predicted by the markers (``predict``: pad-plane metres -> the
    crop's pixels, :func:`_marker_corners`) and refined on the border channel."""
    P = pad_geometry.outer_corners
    guess = predict(P[:, :2]) + [x0, y0]
    h, w = rgb.shape[:2]
    if guess.min() < 4 or guess[:, 0].max() > w - 5 or guess[:, 1].max() > h - 5:
        return None
    side_px = _mean_side(guess)
    hw = float(np.clip(side_px * pad_geometry.border.solid_band_m / pad_geometry.side_m * 0.9, 1.0, 3.0))
    f, (bx0, by0) = _window(rgb, guess, 6)
    chan = _border_channel(srgb_to_linear(f))
    ref, _ = refine_quad(chan, guess - [bx0, by0], half_width=hw, camera=_shifted(camera, bx0, by0))
    if ref is None:
        return None
    ref = ref + [bx0, by0]
    if np.max(np.linalg.norm(ref - guess, axis=1)) > max(2.0, 0.02 * side_px):
        return None
    return ref


def _head_on(camera: Camera | None, up_C: np.ndarray | None, x0: int, y0: int):
    """``f(px) -> (N, 2)``: pixels of the (cropped) image as a camera at the same place would see them
    looking straight down (undistorted, then turned by the least rotation that takes the IMU's up to
    -z); ``None`` without a camera or an IMU."""
    if camera is None or up_C is None:
        return None
    up = np.asarray(up_C, np.float64) / np.linalg.norm(up_C)
    down = np.array([0.0, 0.0, -1.0])
    axis = np.cross(up, down)  # rotation taking up to -z (so the optical axis to down)
    s, c = np.linalg.norm(axis), float(up @ down)
    R = so3_exp(axis / s * math.atan2(s, c)) if s > 1e-9 else (np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0]))

    def f(px):
        xy = camera.normalized_from_pixels(np.asarray(px, np.float64) + [x0, y0])
        r = np.column_stack([xy, np.ones(len(xy))]) @ R.T
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(r[:, 2:3] > 1e-6, r[:, :2] / r[:, 2:3], np.nan)
    return f


def _shifted(camera: Camera | None, x0: int, y0: int):
    if camera is None or not camera.has_distortion or (x0 == 0 and y0 == 0):
        return camera
    return camera.shifted(x0, y0)


def _contour_quad(contour: np.ndarray) -> np.ndarray:
    quad = _hull_quad(cv2.convexHull(contour))
    return quad if quad is not None else cv2.boxPoints(cv2.minAreaRect(contour)).astype(np.float64)


def _hull_quad(hull: np.ndarray) -> np.ndarray | None:
    """The quadrilateral a convex hull outlines, or ``None``.  The hull, simplified a little, loses
    its shortest side until four are left: each short side is a corner cut off (the cue square
    left out of the border mask, a corner in shadow or behind a box, the rounding of a blurred
    corner), put back where the two sides beside it meet.  A side whose neighbours do not meet
    beyond it (nearly parallel: a kink in a long side) is merged into them instead."""
    peri = cv2.arcLength(hull, True)
    poly = cv2.approxPolyDP(hull, max(0.01 * peri, 0.5), True)[:, 0, :].astype(np.float64)
    while len(poly) > 4:
        n = len(poly)
        lengths = np.linalg.norm(np.roll(poly, -1, axis=0) - poly, axis=1)
        i = int(np.argmin(lengths))  # the short side: poly[i] -> poly[i + 1]
        x = _meet(poly[(i - 1) % n], poly[i], poly[(i + 1) % n], poly[(i + 2) % n], lengths[i])
        if x is not None:
            poly[i] = x
        poly = np.delete(poly, (i + 1) % n, axis=0)
    return poly if len(poly) == 4 else None


def _meet(a0, a1, b0, b1, cut: float):
    """Where the line a0->a1 meets the line b0->b1 beyond a1 and before b0 (a corner that the side
    a1 -> b0, ``cut`` long, cut off), or ``None``."""
    da, db = a1 - a0, b1 - b0
    den = da[0] * db[1] - da[1] * db[0]
    if abs(den) < 1e-6 * np.linalg.norm(da) * np.linalg.norm(db) + 1e-12:
        return None
    s = ((b0[0] - a0[0]) * db[1] - (b0[1] - a0[1]) * db[0]) / den
    x = a0 + s * da
    # beyond the cut, about as far from it as the cut is long (0.5x when the corner is square)
    if s <= 1.0 or np.linalg.norm(x - 0.5 * (a1 + b0)) > 2.0 * cut + 2.0:
        return None
    return x


def _cue_scores(rgb: np.ndarray, quad_px: np.ndarray, pad_geometry: PadGeometry, camera: Camera | None,
                visible=None) -> np.ndarray:
    """(2, 4) how much the border square at each corner of ``quad_px`` holds the cue, read against
    the border squares beside it (which share its light): row 0 by colour, row 1 by brightness.

    Colour: 1 for a corner square of the cue's chromaticity next to border of the border's, 0
    where it looks like its neighbours.  Chromaticity (r, g, b over their sum) does not change in
    shadow or dim light, so the reading holds under a shadow edge, at dusk, on any ground (brown
    soil lies in a yellow cue's colour range, and it never enters the squares), and wherever the
    quad is right.

    Brightness: the log ratio of the square's linear luma to its neighbours', over the design's
    (the yellow cue is 2.3x as bright as the magenta border); 0 for all four when the design's two
    colours are too alike in brightness to tell.  JPEG and H.264 keep luma at full resolution
    and halve chroma, so on a far pad (a cue square of 3 to 4 pixels) brightness still shows the
    cue where colour is smeared into the ground.  A shadow edge between a square and its
    neighbours moves it; :func:`_cue_corner_seen` uses it only where colour agrees."""
    geo = pad_geometry
    outer = geo.outer_corners[:, :2]
    sq = geo.cue.corners[:, :2]
    c = _cue_corner(geo)
    w = float(np.sqrt(abs(_signed_area(sq))))
    # sample points (pad frame) inside the cue square and in the two border squares beside it
    g = np.linspace(0.2, 0.8, 4)
    uv = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    o, cen = outer[c], outer.mean(axis=0)
    ex, ey = np.sign(cen - o) * [1.0, 0.0], np.sign(cen - o) * [0.0, 1.0]  # from the corner inward, along each side
    own = o + w * (uv[:, :1] * ex + uv[:, 1:] * ey)
    pts = np.concatenate([own, own + w * ex, own + w * ey]) - cen
    # "image corner k is the cue's corner" for every k at once: the pad is square, so that is the
    # same points turned (k - c) quarter turns about its centre, seen through one homography
    # (image corner j = pad corner j)
    d0, d1 = outer[0] - cen, outer[1] - cen
    a = math.atan2(float(d0[0] * d1[1] - d0[1] * d1[0]), float(d0 @ d1))  # one quarter turn, corner j to j + 1
    turned = []
    for k in range(4):
        t = a * (k - c)
        R = np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])
        turned.append(pts @ R.T + cen)
    px = _through_quad(quad_px, geo, camera, np.concatenate(turned))
    if px is None:
        return np.zeros(4)
    vals = sample_at(rgb, px)
    inside = _seen(px, rgb.shape, visible).reshape(4, -1).all(axis=1)
    target = _chroma(geo.cue.color_rgb) - _chroma(geo.border.color_rgb)
    luma = srgb_to_linear(vals.round()) @ _LUMA
    design = math.log(_luma(geo.cue.color_rgb) / max(_luma(geo.border.color_rgb), 1e-3))
    m = len(own)
    out = np.zeros((2, 4))
    for k, (v, y) in enumerate(zip(vals.reshape(4, 3 * m, 3), luma.reshape(4, 3 * m))):
        if inside[k]:  # a corner outside the image tells nothing
            here, beside = _chroma(v[:m].mean(axis=0)), _chroma(v[m:].mean(axis=0))
            out[0, k] = max(0.0, float((here - beside) @ target / (target @ target)))
            if abs(design) >= _CUE_MIN_LOG_LUMA:
                out[1, k] = math.log(max(float(y[:m].mean()), 1e-3) / max(float(y[m:].mean()), 1e-3)) / design
    return out


_CUE_MIN_LOG_LUMA = 0.3  # a cue and border at most 1.35x apart in brightness: brightness tells nothing


def _luma(rgb) -> float:
    """Linear luma of an 8-bit sRGB colour."""
    return float(srgb_to_linear(np.asarray(rgb, np.uint8)) @ _LUMA)


def _standout(v: np.ndarray, floor: float = 0.2, ratio: float = 0.34) -> int | None:
    """Index of the one entry of ``v`` that stands out: at least ``floor``, and every other one
    under ``ratio`` of it; ``None`` when none does."""
    s = np.sort(v)
    return int(np.argmax(v)) if s[-1] >= floor and s[-2] < ratio * s[-1] else None


def _cue_corner_seen(cue: np.ndarray) -> tuple:
    """``(k, how)``: image corner ``k`` holds the cue, from :func:`_cue_scores`, or ``(None, "")``.
    Colour alone decides where one corner stands out in it.  Otherwise colour and brightness must
    point at the same corner: their geometric mean (brightness taken above the median corner's,
    since the squares beside a corner catch more of the white field than the corner does) must
    stand out.  Each alone misleads somewhere (colour on a far JPEG pad, brightness at a shadow
    edge); the two are read from different channels, and a corner both pick is the cue."""
    k = _standout(cue[0])
    if k is not None:
        return k, "cue"
    lum = cue[1] - np.median(cue[1])
    k = _standout(np.sqrt(np.clip(cue[0], 0.0, None) * np.clip(lum, 0.0, None)))
    return (k, "cue (colour and brightness)") if k is not None else (None, "")


def _cue_corner(pad_geometry: PadGeometry) -> int:
    """Index in ``outer_corners`` (TL, TR, BR, BL) of the corner holding the cue square."""
    g = pad_geometry
    return int(np.argmin(np.linalg.norm(g.outer_corners[:, :2] - g.cue.corners[:, :2].mean(axis=0), axis=1)))


def _chroma(rgb) -> np.ndarray:
    v = np.asarray(rgb, np.float64)
    return v / max(float(v.sum()), 1.0)


def _order_like(quad_px: np.ndarray, corners_P: np.ndarray, t: mk.MarkerTriple) -> np.ndarray:
    """Order an image quad like the pad corners, using the marker triple's image axes."""
    ex = t.right.center_px - t.top.center_px
    ey = t.top.center_px - t.bottom.center_px  # pad +y in the image
    ex /= max(np.linalg.norm(ex), 1e-9)
    ey /= max(np.linalg.norm(ey), 1e-9)
    c = quad_px.mean(axis=0)
    cp = corners_P.mean(axis=0)
    out = np.zeros_like(quad_px)
    used = set()
    for i, P in enumerate(corners_P):
        dirP = np.sign(P - cp)
        target = dirP[0] * ex + dirP[1] * ey
        scores = [float((q - c) @ target) if j not in used else -np.inf for j, q in enumerate(quad_px)]
        j = int(np.argmax(scores))
        used.add(j)
        out[i] = quad_px[j]
    return out


# ----------------------------------------------------------------------------- Touchdown

@dataclass
class Keyframe:
    gray: np.ndarray
    cam2pad: np.ndarray
    px: np.ndarray        # (N, 2) feature pixels in the keyframe
    pts_P: np.ndarray     # (N, 3) the same features on the pad plane
    anchored: bool        # made from a pad-anchored pose (markers/outline), not a chained one
    cov: np.ndarray | None = None  # the keyframe pose's 6x6 covariance: every pose tracked from it inherits it
    tag: object = None    # the frame it was made from, as :class:`ImageWork` names frames
    serial: int = 0       # which of its tracker's keyframes it is (1, 2, ...): poses of one serial share its error
    parent: int | None = None  # the serial of the keyframe whose tracked pose it was made from (a chained one), if any
    motion: object = None  # the hvloc.shutter.Twist the frame was exposed under, where known
    drawn: bool = False   # its pose was the smeared drawing's (hvloc.synthesis): a fallback, tried after the drawing
    # how far the IMU's gravity was off, at the least, where its anchoring pose's image fixed the
    # tilt (degrees; 0 where it could not tell): kept by the keyframes chained from it (FlowTracker.gravity_sigma)
    ahrs_off_deg: float = 0.0
    contrast: np.ndarray | None = None  # its image divided by its local mean (refined_on_keyframe), made when first asked


HARRIS_QUALITY = 0.005   # a corner's Harris response, at least this share of the strongest it is judged against
HARRIS_CELLS = 4         # where the frame's strongest are too few: more from this many cells a side of the mask's box ...
HARRIS_FLOOR = 1e-4      # ... each judged against its own strongest, in cells whose strongest is at least this share
                         # of the frame's (else flat: noise)
HARRIS_MARGIN_PX = 16    # the mask's box is read this far beyond it (a response and its suppression reach 4 px)


def harris_corners(gray: np.ndarray, max_corners: int = 150, mask: np.ndarray | None = None,
                   cells: int = HARRIS_CELLS) -> np.ndarray | None:
    """``(N, 2)`` pixels of a frame's Harris corners (where ``mask`` is set), or ``None``: its
    strongest, judged against the strongest response (OpenCV's quality level); where those are
    fewer than ``max_corners``, more from ``cells`` squared cells of the mask's box, each cell's
    judged against that cell's own strongest, taken from the cells in turn (strongest first in
    each, none within 8 px of a corner already taken).

    A corner's response grows with the fourth power of its contrast.  Judged against the whole
    frame's strongest, a frame mostly in the drone's shadow beside a strip of sunlit pad kept only
    the strip's corners: at 0.17 m over a moving deck the shadowed texture's strongest was 1/460 of
    the strip's, the quality level kept 16 corners, all on the strip, and three frames later the
    flow had none left (ten frames lost, the texture in view everywhere).  Only to fill: taken cell
    by cell always, the spread corners were a border's periodic checker in the cells along it, and
    under 41 px of smear Lucas-Kanade locked them a period off together (unseen47: a chain 41 mm off
    at 0.5 m, 19 false accepts)."""
    g = np.ascontiguousarray(gray)
    found, top = _strongest(g, max_corners, mask)
    if cells > 1 and 0 < len(found) < max_corners:
        more = _cell_corners(g, max_corners, mask, cells, top)
        if len(more) and len(found):
            near = np.min(np.linalg.norm(more[:, None, :] - found[None, :, :], axis=2), axis=1) < 8.0
            more = more[~near]
        found = np.concatenate([found, more[:max_corners - len(found)]])
    return found if len(found) else None


def _strongest(g: np.ndarray, max_corners: int, mask: np.ndarray | None) -> tuple:
    """``((N, 2) corners, the strongest's Harris response)`` of ``g`` where ``mask`` is set, judged
    against that strongest (OpenCV's quality level).

    Only the mask's box is read, with :data:`HARRIS_MARGIN_PX` around it: a corner's response and
    its neighbours' (the non-maximum suppression) are read within 4 px, so the corners are those
    of the whole frame (a 4K frame costs 150-190 ms whole; a pad region of a third of it 45-65 ms,
    of a twentieth 3-9 ms; the corners the same)."""
    x0, y0 = 0, 0
    if mask is not None:
        x, y, w, h = cv2.boundingRect(mask)
        if w == 0 or h == 0:
            return np.zeros((0, 2)), 0.0
        H, W = g.shape[:2]
        x0, y0 = max(x - HARRIS_MARGIN_PX, 0), max(y - HARRIS_MARGIN_PX, 0)
        x1, y1 = min(x + w + HARRIS_MARGIN_PX, W), min(y + h + HARRIS_MARGIN_PX, H)
        g, mask = np.ascontiguousarray(g[y0:y1, x0:x1]), np.ascontiguousarray(mask[y0:y1, x0:x1])
    pts, quality = cv2.goodFeaturesToTrackWithQuality(g, max_corners, HARRIS_QUALITY, 8, mask, blockSize=5,
                                                      useHarrisDetector=True, k=0.04)
    if pts is None or not len(pts):
        return np.zeros((0, 2)), 0.0
    return pts.reshape(-1, 2).astype(np.float64) + [x0, y0], float(np.max(quality))


def _cell_corners(g: np.ndarray, max_corners: int, mask: np.ndarray | None, cells: int, top: float) -> np.ndarray:
    """``(N, 2)``: :func:`harris_corners`' corners judged cell by cell (cells whose strongest is under
    :data:`HARRIS_FLOOR` of ``top``, the frame's, left out), taken from the cells in turn."""
    H, W = g.shape[:2]
    x, y, w, h = cv2.boundingRect(mask) if mask is not None else (0, 0, W, H)
    rows = np.linspace(y, y + h, cells + 1).astype(int)
    cols = np.linspace(x, x + w, cells + 1).astype(int)
    found, pad = [], HARRIS_MARGIN_PX  # (each cell read with the margin the response's window needs, as _strongest reads a mask's box)
    for y0, y1 in zip(rows[:-1], rows[1:]):
        for x0, x1 in zip(cols[:-1], cols[1:]):
            if y1 <= y0 or x1 <= x0:
                continue
            Y0, Y1, X0, X1 = max(y0 - pad, 0), min(y1 + pad, H), max(x0 - pad, 0), min(x1 + pad, W)
            m = np.zeros((Y1 - Y0, X1 - X0), np.uint8)
            m[y0 - Y0:y1 - Y0, x0 - X0:x1 - X0] = 255
            if mask is not None:
                m &= (mask[Y0:Y1, X0:X1] > 0).astype(np.uint8) * 255
            pts, cell_top = _strongest(np.ascontiguousarray(g[Y0:Y1, X0:X1]), max_corners, m)
            if len(pts) and cell_top >= HARRIS_FLOOR * top:
                found.append(pts + [X0, Y0])
    if not found:
        return np.zeros((0, 2))
    return np.array([f[k] for k in range(max(len(f) for f in found)) for f in found if k < len(f)])


def pad_region_mask(camera: Camera, cam2pad: np.ndarray, region_P: np.ndarray, shape, inset_px: float = 12.0,
                    step: int = 8) -> np.ndarray | None:
    """``uint8`` mask (255 inside) of the pixels that see the pad's region (the box of
    ``region_P``'s x, y on the pad plane) at least ``inset_px`` from its edge, or ``None`` when
    none does.  Each pixel's ray is met with the plane (lens and all) on a grid of ``step`` px, so
    a corner far out of view, which a distortion model cannot project, never folds back in."""
    H, W = shape[:2]
    u, v = np.meshgrid(np.arange(step / 2, W, step), np.arange(step / 2, H, step))
    P, ok = _on_pad_plane(camera, cam2pad, np.column_stack([u.ravel(), v.ravel()]))
    lo, hi = region_P[:, :2].min(axis=0), region_P[:, :2].max(axis=0)
    inset = inset_px * max(float(cam2pad[2, 3]), 1e-3) / camera.fx
    with np.errstate(invalid="ignore"):
        inside = ok & np.all((P[:, :2] >= lo + inset) & (P[:, :2] <= hi - inset), axis=1)
    if not inside.any():
        return None
    coarse = (inside.reshape(u.shape) * 255).astype(np.uint8)
    return cv2.resize(coarse, (W, H), interpolation=cv2.INTER_NEAREST)


def make_keyframe(gray: np.ndarray, cam2pad: np.ndarray, camera: Camera, anchored: bool,
                  max_corners: int = 150, mask: np.ndarray | None = None, cov: np.ndarray | None = None,
                  corners_px: np.ndarray | None = None, unroll=None) -> Keyframe | None:
    """Harris corners of a frame (``corners_px`` when already found), placed on the pad plane with
    the frame's pose; ``unroll(px, cam2pad, pts_P)``: their pixels as the rolling shutter's
    reference row would have seen them (:mod:`hvloc.shutter`), where the frame's rows differ in time."""
    px = harris_corners(gray, max_corners, mask) if corners_px is None else corners_px
    if px is None or len(px) < 8:
        return None
    P, ok = _on_pad_plane(camera, cam2pad, px)
    if unroll is not None:  # placed once as seen, to tell each point's depth; then as of the pose's time
        P, ok = _on_pad_plane(camera, cam2pad, np.where(ok[:, None], unroll(px, cam2pad, P), px))
    half = 10.0  # keep points on the pad plane near the pad (the tracker assumes one plane)
    ok &= (np.abs(P[:, 0]) < half) & (np.abs(P[:, 1]) < half)
    if ok.sum() < 8:
        return None
    P[:, 2] = 0.0
    return Keyframe(gray.copy(), cam2pad.copy(), px[ok], P[ok], anchored, cov)


def _on_pad_plane(camera: Camera, cam2pad: np.ndarray, px: np.ndarray) -> tuple:
    """``(P (N, 3), ok (N,))``: where the pixels' rays meet the pad's plane, and which do in front."""
    rays = np.column_stack([camera.normalized_from_pixels(px), np.ones(len(px))])  # camera frame
    R, t = cam2pad[:3, :3], cam2pad[:3, 3]
    d = rays @ R.T  # ray directions in P
    with np.errstate(divide="ignore", invalid="ignore"):
        s = -t[2] / d[:, 2]
    ok = np.isfinite(s) & (s > 0)
    return t + np.where(ok, s, 0.0)[:, None] * d, ok


LK_PARAMS = dict(winSize=(21, 21), maxLevel=3, criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01))


def track_to_keyframe(kf: Keyframe, prev_gray: np.ndarray, prev_px: np.ndarray, gray: np.ndarray, camera: Camera,
                      fb_max_px: float = 1.0, guess_px: np.ndarray | None = None) -> tuple:
    """Track keyframe features into ``gray`` (seen through ``camera``): frame-to-frame LK from
    ``prev_px`` with a forward-backward check, then refined against the keyframe itself
    (:func:`refined_on_keyframe`), which keeps the error from accumulating.  ``guess_px``:
    where the features are predicted in ``gray`` (after dropped frames the motion, and near the
    ground the change of scale, exceed what LK's pyramid follows): the previous frame is first
    warped by the homography that takes its features to their guesses; where the frame lies 16 px
    or more off that warp (:func:`guess_shift`), every guess is moved by the shift first.

    Returns ``(px (N, 2) with NaN where lost)``."""
    out = np.full_like(prev_px, np.nan)
    ok = np.isfinite(prev_px).all(axis=1)
    if ok.sum() < 4:
        return out
    p0 = prev_px[ok].astype(np.float32).reshape(-1, 1, 2)
    H, start = None, None
    if guess_px is not None:
        g = guess_px[ok]
        fin = np.isfinite(g).all(axis=1)
        if fin.sum() >= 8:
            H, _ = cv2.findHomography(p0[fin, 0].astype(np.float64), g[fin].astype(np.float64), 0)
        if H is not None:
            shift = guess_shift(prev_gray, gray, H)
            if shift is not None:
                g = g + shift
                H = np.array([[1.0, 0.0, shift[0]], [0.0, 1.0, shift[1]], [0.0, 0.0, 1.0]]) @ H
        if H is not None and not _reshapes_patches(H, p0[fin, 0].mean(axis=0)):
            # LK starts where the prediction puts each feature, on the frame as it is: the patches
            # keep their shape, and a warp's interpolation would soften them (bench_v1's field1080,
            # guesses 0.1-0.3 px off: touchdown 0.15 -> 0.25 mm median warped, 0.15 started so)
            start = np.where(fin[:, None], g, p0[:, 0]).astype(np.float32).reshape(-1, 1, 2)
            H = None
    src = prev_gray
    if H is not None:  # the previous frame warped to where the prediction puts it: LK then sees patches
        # of the right scale and turn, displaced by the prediction's error (the forward-backward
        # check then holds in the warped frame)
        src = cv2.warpPerspective(prev_gray, H, (gray.shape[1], gray.shape[0]), flags=cv2.INTER_LINEAR)
        p0 = cv2.perspectiveTransform(p0, H).astype(np.float32)
    # started at the guess, the backward check is started where the features were
    flags = 0 if start is None else cv2.OPTFLOW_USE_INITIAL_FLOW
    p1, st, _ = cv2.calcOpticalFlowPyrLK(src, gray, p0, None if start is None else start, flags=flags, **LK_PARAMS)
    if p1 is None:
        return out
    pb, stb, _ = cv2.calcOpticalFlowPyrLK(gray, src, p1, None if start is None else p0.copy(), flags=flags, **LK_PARAMS)
    fb = np.linalg.norm((pb - p0)[:, 0, :], axis=1)
    good = (st[:, 0] == 1) & (stb[:, 0] == 1) & (fb < fb_max_px)
    # refine against the keyframe (drift control)
    kf_px = kf.px[ok].astype(np.float32).reshape(-1, 1, 2)
    p2, st2 = refined_on_keyframe(kf, gray, kf_px, p1, good, camera)
    if p2 is not None:
        close = (st2[:, 0] == 1) & (np.linalg.norm((p2 - p1)[:, 0, :], axis=1) < 2.0)
        p1 = np.where(close[:, None, None], p2, p1)
        p1 = _reseeded_on_keyframe(kf, gray, kf_px, p1, good, close, camera)
    idx = np.nonzero(ok)[0]
    out[idx[good]] = p1[good, 0, :]
    return out


def _reseeded_on_keyframe(kf: Keyframe, gray: np.ndarray, kf_px: np.ndarray, p1: np.ndarray, good: np.ndarray,
                          refined: np.ndarray, camera: Camera) -> np.ndarray:
    """``p1`` (``(N, 1, 2)``), whose ``refined`` tracks the keyframe refined, with the other ``good``
    ones refined again from where the refined tracks' homography puts them.  A track the refinement
    would move 2 px or more is not moved (it may have found another feature), and frame-to-frame
    tracks that slipped together slip that far at the view's edge: fz445 at 1.5 m, after a frame
    untracked, 13 of 36 tracks ~1-2 px off together were kept so, and the 20 left after RANSAC, on half
    the pad, tilted the pose 5.3 degrees stating 1.2 (10.7 % of the height off), chained 25 frames.
    Started where the others put them they are refined as those were (tracks 0.5-3.4 px off together:
    all within 0.1 px)."""
    again = good & ~refined
    if not again.any() or refined.sum() < 8:
        return p1
    und, dis = _ideal_maps(camera)
    H, _ = cv2.findHomography(und(kf_px[refined, 0].astype(np.float64)), und(p1[refined, 0].astype(np.float64)),
                              cv2.RANSAC, 1.0)
    if H is None:
        return p1
    start = p1.copy()
    start[again, 0] = dis(cv2.perspectiveTransform(und(kf_px[again, 0].astype(np.float64)).reshape(-1, 1, 2),
                                                   H).reshape(-1, 2))
    p3, st3 = refined_on_keyframe(kf, gray, kf_px, start, good, camera)
    if p3 is None:
        return p1
    now = again & (st3[:, 0] == 1) & (np.linalg.norm((p3 - start)[:, 0, :], axis=1) < 2.0)
    return np.where(now[:, None, None], p3, p1)


LOCAL_MEAN_SIGMA_PX = 4.0  # the keyframe refinement compares the frames divided by their local mean (a Gaussian this wide)
WARP_GRID_PX = 8           # the keyframe is warped through a map computed every this many pixels (bilinear between)
REFINE_MARGIN_PX = 48      # the frame is read this far around its tracks (LK's window at pyramid level 1, and more)


def local_contrast(gray: np.ndarray, sigma: float = LOCAL_MEAN_SIGMA_PX) -> np.ndarray:
    """``gray`` divided by its local mean (a Gaussian of ``sigma`` px), 8-bit, the mean at 128: a
    shadow's edge, a cloud, the exposure scale brightness, which this divides out.  The mean is taken
    on the frame shrunk 4-fold (smooth at that scale: 4.3 instead of 9 ms at 1920x1080)."""
    f = gray.astype(np.float32) + 1.0
    h, w = f.shape[:2]
    if min(h, w) >= 32:
        small = cv2.resize(f, (w // 4, h // 4), interpolation=cv2.INTER_AREA)
        mean = cv2.resize(cv2.GaussianBlur(small, (0, 0), sigma / 4.0), (w, h), interpolation=cv2.INTER_LINEAR)
    else:
        mean = cv2.GaussianBlur(f, (0, 0), sigma)
    return cv2.divide(f, mean, scale=128.0, dtype=cv2.CV_8U)


def _ideal_maps(camera: Camera) -> tuple:
    """``(undistort, distort)``: pixels to the ideal pinhole's with the same K and back (the identity
    for a pinhole without distortion), where a homography between views holds."""
    if not camera.has_distortion:
        return (lambda q: q), (lambda q: q)
    return camera.undistort_pixels, camera.distort_pixels


def refined_on_keyframe(kf: Keyframe, gray: np.ndarray, kf_px: np.ndarray, p1: np.ndarray, good: np.ndarray,
                        camera: Camera) -> tuple:
    """``(p2, status)`` as ``cv2.calcOpticalFlowPyrLK`` gives them: the tracks ``p1`` (``(N, 1, 2)``
    float32 in ``gray``, ``good`` the ones to trust) refined by Lucas-Kanade against the keyframe (its
    features at ``kf_px``), which :func:`track_to_keyframe` does to keep the frame-to-frame error
    from accumulating.

    LK compares patches as they are, brightness constant: the keyframe is first warped to the frame
    by the tracks' homography (through the lens: the homography holds between ideal pixels), and
    both are divided by their local mean (:func:`local_contrast`).  Against the keyframe as it was,
    patches up to 15 % larger than its (a keyframe is renewed past that) and the drone's shadow
    edge crossing the view left tracks 0.4-0.9 px off together, smoothly, as a tilt would move them:
    the smoke deck's flow poses 4 mm off at 0.55 m stating 1.3.  Warped only, not divided, a shadow's
    edge still pulled them (the deck's poses beyond 3 sigma 3 -> 19 %); warped in distorted pixels, a
    k1 -0.25 lens's touchdown 0.4 -> 0.7 mm."""
    fin = good & np.isfinite(p1[:, 0]).all(axis=1)
    und, dis = _ideal_maps(camera)
    H = None
    if fin.sum() >= 8:
        H, _ = cv2.findHomography(und(kf_px[fin, 0].astype(np.float64)), und(p1[fin, 0].astype(np.float64)),
                                  cv2.RANSAC, 3.0)
    if H is None:  # too few to warp by: as it was
        p2, st2, _ = cv2.calcOpticalFlowPyrLK(kf.gray, gray, kf_px, p1.copy(), flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
                                              **{**LK_PARAMS, "maxLevel": 1})
        return p2, st2
    # the frame's part around the tracks, from a node of the lens's grid
    h, w = gray.shape[:2]
    s = WARP_GRID_PX
    lo = np.floor(p1[fin, 0].min(axis=0)).astype(int) - REFINE_MARGIN_PX
    hi = np.ceil(p1[fin, 0].max(axis=0)).astype(int) + REFINE_MARGIN_PX
    i0, j0 = max(int(lo[0]), 0) // s, max(int(lo[1]), 0) // s
    x0, y0, x1, y1 = i0 * s, j0 * s, min(int(hi[0]), w), min(int(hi[1]), h)
    if x1 - x0 < 16 or y1 - y0 < 16:
        return None, None
    nodes = ideal_grid(camera, s)[j0:-(-y1 // s) + 1, i0:-(-x1 // s) + 1]
    # each node's place in the keyframe, and every pixel's between the nodes bilinearly
    src = dis(cv2.perspectiveTransform(nodes.reshape(-1, 1, 2), np.linalg.inv(H)).reshape(-1, 2))
    up = np.float64([[1.0 / s, 0.0, 0.0], [0.0, 1.0 / s, 0.0]])
    mx, my = (cv2.warpAffine(src[:, i].reshape(nodes.shape[:2]).astype(np.float32), up, (x1 - x0, y1 - y0),
                             flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)
              for i in (0, 1))
    if kf.contrast is None:
        kf.contrast = local_contrast(kf.gray)
    warped = cv2.remap(kf.contrast, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    o = np.float32([x0, y0])
    w0 = dis(cv2.perspectiveTransform(und(kf_px[:, 0].astype(np.float64)).reshape(-1, 1, 2), H).reshape(-1, 2))
    p2, st2, _ = cv2.calcOpticalFlowPyrLK(warped, local_contrast(gray[y0:y1, x0:x1]),
                                          (w0 - o).astype(np.float32).reshape(-1, 1, 2), p1 - o,
                                          flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **{**LK_PARAMS, "maxLevel": 1})
    return (None, None) if p2 is None else (p2 + o, st2)


SHIFT_MIN_PX = 16.0       # a guess's residual shift smaller than this is left to Lucas-Kanade's pyramid
SHIFT_SIDE_PX = 256       # the phase correlation's images: the frames shrunk to about this many pixels a side
SHIFT_MIN_RESPONSE = 0.08  # its peak's share of the correlation, at least (a repeated pattern's peaks share it)


def guess_shift(prev_gray: np.ndarray, gray: np.ndarray, H: np.ndarray) -> np.ndarray | None:
    """The shift ``(dx, dy)`` (px) by which ``gray`` lies off the guess ``H`` (the homography that
    takes ``prev_gray`` to where the features are predicted in ``gray``), by phase correlation of the
    two frames shrunk to :data:`SHIFT_SIDE_PX`; ``None`` where it is under :data:`SHIFT_MIN_PX` or
    the correlation is not sure of it (:data:`SHIFT_MIN_RESPONSE`)."""
    h, w = gray.shape[:2]
    f = min(1.0, SHIFT_SIDE_PX / max(h, w))
    S = np.diag([f, f, 1.0])
    size = (max(int(round(w * f)), 16), max(int(round(h * f)), 16))
    a = cv2.warpPerspective(cv2.resize(prev_gray, size, interpolation=cv2.INTER_AREA), S @ H @ np.linalg.inv(S),
                            size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).astype(np.float32)
    b = cv2.resize(gray, size, interpolation=cv2.INTER_AREA).astype(np.float32)
    (dx, dy), response = cv2.phaseCorrelate(a, b, cv2.createHanningWindow(size, cv2.CV_32F))
    d = np.array([dx, dy]) / f
    if not (response >= SHIFT_MIN_RESPONSE and np.isfinite(d).all() and np.hypot(*d) >= SHIFT_MIN_PX):
        return None
    return d


RESHAPE_SCALE = 1.1       # a predicted warp that scales patches more than this, or ...
RESHAPE_TURN_DEG = 5.0    # ... turns them more, is applied to the previous frame before LK (track_to_keyframe)


def _reshapes_patches(H: np.ndarray, at: np.ndarray) -> bool:
    """Whether the homography ``H`` scales or turns the image about pixel ``at`` past what
    Lucas-Kanade's translational window follows (:data:`RESHAPE_SCALE`, :data:`RESHAPE_TURN_DEG`):
    a 0.6 s gap near the ground, not a frame's turn and descent."""
    x, y = float(at[0]), float(at[1])
    w = H[2, 0] * x + H[2, 1] * y + H[2, 2]
    if not abs(w) > 1e-12:
        return True
    u, v = (H[0, 0] * x + H[0, 1] * y + H[0, 2]) / w, (H[1, 0] * x + H[1, 1] * y + H[1, 2]) / w
    J = np.array([[H[0, 0] - u * H[2, 0], H[0, 1] - u * H[2, 1]], [H[1, 0] - v * H[2, 0], H[1, 1] - v * H[2, 1]]]) / w
    s = np.linalg.svd(J, compute_uv=False)
    turn = math.degrees(math.atan2(J[1, 0] - J[0, 1], J[0, 0] + J[1, 1]))
    return bool(s[0] > RESHAPE_SCALE or s[1] < 1 / RESHAPE_SCALE or abs(turn) > RESHAPE_TURN_DEG)


# a frame's tracks agreeing on a homography, at least: where Lucas-Kanade lost most of a keyframe's
# features (a zoom past its reach under 40 px of smear) the few that survive are those that slid
# along their smear alike, and a homography fits them (8-14 such tracks posed frames 20-95 mm off,
# stating a tenth of it; test_a_smeared_touchdown_is_never_posed_on_a_few_surviving_tracks)
FLOW_MIN_INLIERS = 20


FLOW_INLIER_SIGMAS = 3.0   # a track within this many of the tracks' own noise of their consensus is one of it ...
FLOW_INLIER_MAX_PX = 8.0   # ... up to this far: a track that slipped a checker cell (35-75 px) stays out ...
FLOW_INLIER_MIN_PX = 0.3   # ... and at least this far (Lucas-Kanade's precision on a sharp frame's patches)


def noise_inliers(src: np.ndarray, dst: np.ndarray, H: np.ndarray, inl: np.ndarray, min_thr: float,
                  max_thr: float) -> np.ndarray:
    """RANSAC's inliers ``inl`` of the homography ``H`` (``src`` -> ``dst``), taken again at the
    points' own noise: every point within :data:`FLOW_INLIER_SIGMAS` of it
    (:func:`hvloc.pose.robust_sigma` of the points within ``max_thr``), at least ``min_thr`` and at
    most ``max_thr`` off, the homography refitted on them (three rounds at most); RANSAC's as they
    are where that would leave fewer than half of them or :data:`FLOW_MIN_INLIERS`.

    A threshold under the noise keeps a chance subset, and the pose is wherever that subset agrees.
    unseen85's tracks at 0.25 m, into a frame smeared by a 25 ms exposure in a gust, scatter 2.4 px
    about their homography: RANSAC at 2 px kept 44-45 of 111 tracks, and two runs whose tracks
    differed by 0.1 px at most kept different ones, posed 0.5 and 5.9 mm off (1.5 mm stated).  All
    111 agree on a pose 0.4 mm off.  A threshold far over the noise keeps the tracks that slipped:
    the smoke deck's at 0.55 m, a few hundredths of a pixel off in the median, kept five 0.7-1.2 px
    off their consensus under RANSAC's 2 px, and those few tilted the pose 0.3 degrees (2.9 mm off,
    stating 1.3)."""
    fin = np.isfinite(dst).all(axis=1)
    least = max(FLOW_MIN_INLIERS, 0.5 * inl.sum())
    for _ in range(3):
        r = np.linalg.norm(cv2.perspectiveTransform(src[None].astype(np.float64), H)[0] - dst, axis=1)
        near = fin & (r <= max_thr)
        if near.sum() < 4:
            return inl
        thr = float(np.clip(FLOW_INLIER_SIGMAS * robust_sigma(r[near]), min_thr, max_thr))
        taken = fin & (r <= thr)
        if taken.sum() < least or np.array_equal(taken, inl):
            return inl
        inl = taken
        H2, _ = cv2.findHomography(src[inl].astype(np.float64), dst[inl].astype(np.float64), 0)
        if H2 is None:
            return inl
        H = H2
    return inl


def pose_from_tracks(camera: Camera, kf: Keyframe, px: np.ndarray, prev_cam2pad: np.ndarray | None,
                     up_C=None, ransac_px: float = 2.0, gravity_sigma_deg: float = 0.5) -> tuple:
    """RANSAC homography between the keyframe's pad points and their tracked pixels, then the
    planar pose on the inliers (``gravity_sigma_deg``: the AHRS's tilt error, which weighs ``up_C``).
    Where the tracks' tilt disagrees with gravity beyond what the two's noise allows, their noise
    is widened until it does not (:data:`hvloc.pose.TILT_CONSISTENT_CHI2`): tracks between frames
    smeared differently (a turn, a fast descent) are off together, smoothly, as a tilted plane's
    homography would move them (unseen55: 150 tracks tilted the pose 1.7-2.4 degrees at 1 m, their
    residuals 0.4-0.7 px, the pose stating a tenth of its 30 mm sideways error).
    Returns ``(PoseResult | None, inlier mask, reason)``."""
    ok = np.isfinite(px).all(axis=1)
    if ok.sum() < FLOW_MIN_INLIERS:
        return None, ok, f"{int(ok.sum())} tracks left (< {FLOW_MIN_INLIERS})"
    P = kf.pts_P[ok]
    xy = camera.normalized_from_pixels(px[ok])
    thr = ransac_px / camera.fx
    H, inl = cv2.findHomography(P[:, :2], xy, cv2.RANSAC, thr)
    if H is None:
        return None, ok, "no homography"
    inl = noise_inliers(P[:, :2], xy, H, inl[:, 0].astype(bool), FLOW_INLIER_MIN_PX / camera.fx,
                        FLOW_INLIER_MAX_PX / camera.fx)
    if inl.sum() < FLOW_MIN_INLIERS:
        return None, ok, f"{int(inl.sum())} homography inliers (< {FLOW_MIN_INLIERS})"
    mask = np.zeros(len(px), bool)
    mask[np.nonzero(ok)[0][inl]] = True
    res = tracks_pose(camera, P[inl], px[ok][inl], up_C, prev_cam2pad, gravity_sigma_deg)
    return res, mask, "ok" if res is not None else "pose failed"


def tracks_pose(camera: Camera, pts_P: np.ndarray, px: np.ndarray, up_C, prev_cam2pad, gravity_sigma_deg: float):
    """The planar pose of tracked pad points as the flow solves it (its noise widened where gravity
    contradicts its tilt): :func:`pose_from_tracks`'s and the localizer's spread solves' one solve."""
    from .pose import TILT_CONSISTENT_CHI2, solve_planar_pose

    return solve_planar_pose(camera, pts_P, px, up_C=up_C, prev_cam2pad=prev_cam2pad,
                             gravity_sigma_deg=gravity_sigma_deg, tilt_chi2=TILT_CONSISTENT_CHI2)


class FlowTracker:
    """Touchdown: features of a keyframe on the pad plane, tracked into every frame.

    ``anchor`` sets a keyframe from a pad-anchored pose (markers, outline); ``track`` estimates
    the pose of a new frame; ``accept`` tells the tracker the frame's pose was accepted, which
    advances the tracks and renews the keyframe (chained, unanchored) when the view has changed
    too much (scale, too few tracks).  Drift grows only at keyframe renewals.
    """

    def __init__(self, camera: Camera, reanchor_scale: float = 1.15, min_tracks: int = 30,
                 work: ImageWork | None = None, region_P: np.ndarray | None = None):
        self.camera = camera
        # the pad's outer corners: keyframe features come from the pad where enough of it is in view
        # (the ground may not be its plane: a raised pad, a deck), from anywhere else only otherwise
        self.region_P = None if region_P is None else np.asarray(region_P, np.float64)
        self.reanchor_scale = reanchor_scale
        self.min_tracks = min_tracks
        self.work = work if work is not None else ImageWork()
        self.unroll = None  # (px, cam2pad, pts_P) -> px at the rolling shutter's reference row (make_keyframe)
        self.keyframes = 0  # keyframes made so far (each one's serial)
        self.gravity_sigma_deg = 0.5  # the AHRS's tilt error, which weighs its gravity in the tracks' poses
        # whether a keyframe may take its corners from the whole frame where the pad gives too few: the
        # ground beside the pad is its plane only for a pad lying on still ground (a deck moving at 0.7
        # m/s, 0.4 m up, its pad a quarter in view at 1.8 m: a chain of the ground's corners drifted 35
        # mm a frame, four poses 19-28 cm off accepted, unseen58); the flow-only ablation needs it
        self.ground = True
        self.reset()

    def reset(self) -> None:
        self.kf: Keyframe | None = None
        self.prev_gray = None
        self.prev_tag = None
        self.tracks = None
        self.pending = None
        self.fitted = None
        self.frames_since_kf = 0

    @property
    def ready(self) -> bool:
        return self.kf is not None and self.prev_gray is not None

    def anchor(self, gray, cam2pad, anchored: bool = True, cov: np.ndarray | None = None, tag=None,
               ahrs_off_deg: float | None = None, chained: bool = False) -> bool:
        """A keyframe from ``gray`` (the current frame, ``tag`` naming it; by default the frame
        :class:`ImageWork` is at) and its pose; ``ahrs_off_deg``: how far that pose's image saw the
        IMU's gravity off (:attr:`gravity_sigma`), by default the keyframe's it renews (0 for none);
        ``chained``: the pose was tracked from the current keyframe (its error carried in ``cov``),
        which the new one names as its parent."""
        parent = self.kf.serial if chained and self.kf is not None else None
        tag = self.work.frame if tag is None else tag
        if ahrs_off_deg is None:
            ahrs_off_deg = 0.0 if self.kf is None else self.kf.ahrs_off_deg
        corners = None
        if self.region_P is not None:  # (the mask too is image work: localizers sharing it make it once)
            corners = self.work(lambda: ("harris_pad", tag, array_key(cam2pad)), self._pad_corners, gray, cam2pad)
            if corners is not None and len(corners) < (self.min_tracks if self.ground else FLOW_MIN_INLIERS):
                corners = None
        if corners is None:
            if not self.ground and self.region_P is not None:
                return False
            # the whole frame: there its strongest corners.  Beyond the pad the ground, boxes and rims
            # are not its plane, and spread evenly over them the corners were mostly theirs (bench_v1's
            # flow_only, anchored once at 20 m: false accepts 372 -> 1473 read cell by cell)
            corners = self.work(lambda: ("harris", tag), harris_corners, gray, cells=1)
        kf = make_keyframe(gray, cam2pad, self.camera, anchored=anchored, cov=cov, corners_px=corners,
                           unroll=self.unroll)
        if kf is None:
            return False
        kf.tag, kf.ahrs_off_deg, kf.parent = tag, float(ahrs_off_deg), parent
        self.keyframes += 1
        kf.serial = self.keyframes
        self.kf, self.tracks, self.prev_gray, self.prev_tag, self.frames_since_kf = kf, kf.px.copy(), kf.gray, tag, 0
        self.pending = None
        return True

    def _pad_corners(self, gray, cam2pad) -> np.ndarray | None:
        """Harris corners where the pad is seen (:func:`pad_region_mask`), or ``None``."""
        mask = pad_region_mask(self.camera, cam2pad, self.region_P, gray.shape)
        return None if mask is None else harris_corners(gray, 150, mask)

    @property
    def gravity_sigma(self) -> float:
        """The IMU gravity's tilt error (degrees) that its tracks' poses weigh it with, and judge their
        own tilt against (:func:`tracks_pose`): the AHRS's stated one, and as far as the keyframe's
        anchoring pose saw it off.  Tracks are right or wrong relative to their keyframe; judged
        against an AHRS 1.1 degrees off where it states 0.5, right ones were widened 22-fold and the
        pose went with the AHRS (unseen48 at 0.6 m, a 40 degree mount: the markers' keyframe 0.07
        degrees off, its tracks' pose 0.68, the height 0.2 -> 1.4 % high down to touchdown)."""
        return math.hypot(self.gravity_sigma_deg, self.kf.ahrs_off_deg if self.kf is not None else 0.0)

    def track(self, gray, prior_cam2pad=None, up_C=None, predicted_cam2pad=None):
        """``(PoseResult | None, n_inliers, reason)`` for ``gray``; ``predicted_cam2pad``: the pose
        expected in ``gray`` (given after a gap in time), from which each feature's pixel is guessed."""
        self.fitted = None
        if not self.ready:
            return None, 0, "no keyframe"
        w, kf = self.work, self.kf
        guess = None
        if predicted_cam2pad is not None:
            Pc = transform_points(invert(predicted_cam2pad), kf.pts_P)
            guess = np.where((Pc[:, 2:3] > 0.05), self.camera.project(Pc), np.nan)
        px = w(lambda: ("lk", kf.tag, array_key(kf.px), self.prev_tag, array_key(self.tracks), array_key(guess)),
               track_to_keyframe, kf, self.prev_gray, self.tracks, gray, self.camera, 1.0, guess)
        self.pending = (gray, px, w.frame)
        # the tracks as of the pose's row (:mod:`hvloc.shutter`), unrolled at the prior and then again at
        # this frame's own first pose: the shift scales with the inverse depth, and at 5 Hz in a fast
        # descent the prior is 15 % farther from the pad, every shift that much short (a chain of
        # keyframes drifted 12 mm sideways from 0.9 m down by it)
        res, inl, why, seen = self._posed_tracks(px, prior_cam2pad, prior_cam2pad, up_C)
        if res is not None and self.unroll is not None and prior_cam2pad is not None:
            again = self._posed_tracks(px, res.cam2pad, prior_cam2pad, up_C)
            if again[0] is not None:
                res, inl, why, seen = again
        self.fitted = None
        if res is not None:
            res = self.fitted_pose(res, kf.pts_P[inl], seen[inl])
        return res, int(inl.sum()), why

    def fitted_pose(self, res, pts_P, seen):
        """``res``, the pose the keyframe's points ``pts_P`` give at the pixels ``seen`` (unrolled
        where the shutter rolls), as the tracker states it: those are what it was fitted to
        (:attr:`fitted`), and the pad points were placed with the keyframe's pose, so its error is
        in every tracked pose (to first order, the keyframe and this frame look the same way: turn
        < 8 deg).  A copy: ``res`` may be shared image work."""
        self.fitted = (pts_P, seen)
        if res.cov is None or self.kf.cov is None:
            return res
        return replace(res, cov=res.cov + self.kf.cov)

    def _posed_tracks(self, px, at_cam2pad, prior_cam2pad, up_C) -> tuple:
        """``(PoseResult | None, inliers, reason, the pixels fitted)``: the keyframe's tracks ``px``
        unrolled (where the shutter rolls) with the camera at ``at_cam2pad``, and their pose; the
        prior only breaks IPPE's tie when there is no gravity (see solve_planar_pose)."""
        kf, seen = self.kf, px
        if self.unroll is not None and at_cam2pad is not None:
            fin = np.isfinite(px).all(axis=1)
            seen = px.copy()
            seen[fin] = self.unroll(px[fin], at_cam2pad, kf.pts_P[fin])
        g = self.gravity_sigma
        res, inl, why = self.work(lambda: ("tracks_pose", array_key(kf.pts_P), array_key(seen), array_key(up_C),
                                           array_key(prior_cam2pad) if up_C is None else None, g),
                                  pose_from_tracks, self.camera, kf, seen, prior_cam2pad, up_C, gravity_sigma_deg=g)
        return res, inl, why, seen

    def accept(self, cam2pad, rms_px: float = 0.0, cov: np.ndarray | None = None) -> None:
        """The last tracked frame's pose was accepted: advance, and renew the keyframe (from this
        frame and pose) while tracking is still good: when the scale or the heading has changed
        enough that LK against the keyframe degrades, tracks were lost, or the fit loosens."""
        if self.pending is None:
            return
        gray, px, tag = self.pending
        self.pending = None
        self.frames_since_kf += 1
        n_ok = int(np.isfinite(px).all(axis=1).sum())
        if n_ok < max(self.min_tracks, 0.6 * len(self.kf.px)) or not self.reaches(cam2pad) or rms_px > 0.5:
            if self.anchor(gray, cam2pad, anchored=False, cov=cov, tag=tag, chained=True):
                return
        self.tracks, self.prev_gray, self.prev_tag = px, gray, tag

    def reaches(self, cam2pad) -> bool:
        """Whether Lucas-Kanade against the keyframe still holds for a camera at ``cam2pad``: the
        scale and the heading changed less than a keyframe is renewed for."""
        if self.kf is None:
            return False
        scale = self.kf.cam2pad[2, 3] / max(cam2pad[2, 3], 1e-6)
        turn = rotation_angle(self.kf.cam2pad[:3, :3], cam2pad[:3, :3])
        return 1 / self.reanchor_scale < scale < self.reanchor_scale and turn <= math.radians(8.0)

    def skip(self) -> None:
        """The last tracked frame's pose was not accepted: keep its tracks (the next frame is
        closer to it than to the older one), keep the keyframe."""
        if self.pending is not None:
            self.prev_gray, self.tracks, self.prev_tag = self.pending
            self.pending = None


def project_roi(camera: Camera, cam2pad: np.ndarray, pts_P: np.ndarray, margin: float, min_size: int = 32):
    """Bounding box (x0, y0, x1, y1) of projected points with a relative margin, clipped to the
    image; ``None`` if nothing projects in front of the camera."""
    Pc = transform_points(invert(cam2pad), pts_P)
    if np.any(Pc[:, 2] <= 0.05):
        return None
    px = camera.project(Pc)
    lo, hi = px.min(axis=0), px.max(axis=0)
    size = hi - lo
    pad = size * margin + 8
    x0, y0 = np.floor(lo - pad).astype(int)
    x1, y1 = np.ceil(hi + pad).astype(int)
    x0, y0 = max(x0, 0), max(y0, 0)
    x1, y1 = min(x1, camera.width), min(y1, camera.height)
    if x1 - x0 < min_size or y1 - y0 < min_size:
        return None
    return (int(x0), int(y0), int(x1), int(y1))
