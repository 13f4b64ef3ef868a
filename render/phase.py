"""What the camera sees of the pad, and the ground-truth landing phase (what a perfect detector
could see in the frame), from the labelled pose and the renderer's own depth.

Visibility means *seen*: a pad point is visible when it projects inside the image and nothing
in the scene lies in front of it (its depth in the rendered depth buffer is not nearer than the
point itself).  Without a depth buffer the facts are geometric (in the image, in front).

Rule (per frame, never from a localizer):

* ``adjustment`` while all three corner markers are wholly visible and their modules are at least
  ``min_module_px`` pixels (so a marker detector can resolve them); a pad without corner markers
  (the apriltag variant) is judged by where the paper pad of the same spec has them, so that one
  descent has one phase whatever pad it is rendered with;
* else ``approaching`` while the whole pad outline is visible;
* else ``touchdown`` once the camera is low enough that the pad no longer fits in the image
  (height below ``side * f / min(W, H)``): the flow tracker's range;
* else ``approaching`` (the pad is partly out of view, or partly hidden, at range).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hvloc.geometry import Camera, invert, transform_points
from pad_design.geometry import MARKER_NAMES, PadGeometry

PHASES = ("approaching", "adjustment", "touchdown")
EDGE_SAMPLES = 8     # points per side of the outline, between its corners
INTERIOR_GRID = 9    # the pad's area is sampled on a grid this many points across
MARKER_GRID = 3      # and each marker's on this grid, plus its corners
MOTION_GRID = 17     # the pad's image motion (blur_px) is read on a grid this many points across


def pad_image_motion_px(camera: Camera, cam2pad_a: np.ndarray, cam2pad_b: np.ndarray, half_side_m: float,
                        seen_from=()) -> float:
    """The largest image motion (px, through the lens) of the pad's points between the views
    ``cam2pad_a`` and ``cam2pad_b`` (``T_P_C``), over those in the image in both and from every pose
    of ``seen_from``: a :data:`MOTION_GRID` square grid over the pad, its corners included.  NaN when
    none is.  Points out of view count for nothing: a corner near the camera's plane projects
    thousands of pixels away, and moves as far (a fisheye pitched 25 degrees at 0.3 m: 10^3-10^5 px
    read on the corners through an ideal pinhole, where the pad in view moved 20-30 px)."""
    g = np.linspace(-half_side_m, half_side_m, MOTION_GRID)
    gx, gy = np.meshgrid(g, g)
    P = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    ends = [camera.project_from(T, P) for T in (cam2pad_a, cam2pad_b)]
    ok = np.ones(len(P), bool)
    for px in ends + [camera.project_from(T, P) for T in seen_from]:
        ok &= np.isfinite(px).all(axis=1) & camera.in_image(px)
    if not ok.any():
        return float("nan")
    return float(np.linalg.norm(ends[1][ok] - ends[0][ok], axis=1).max())


@dataclass(frozen=True)
class PadSamples:
    """Points on the pad (pad frame, metres) whose visibility is tested."""

    corners: np.ndarray    # (4, 3)
    outline: np.ndarray    # (4 + 4 * EDGE_SAMPLES, 3)
    interior: np.ndarray   # (INTERIOR_GRID**2, 3)
    markers: dict          # name -> (4 + MARKER_GRID**2, 3), corner set

    @classmethod
    def of(cls, geometry: PadGeometry) -> "PadSamples":
        c = geometry.outer_corners
        s = np.linspace(0.0, 1.0, EDGE_SAMPLES + 2)[1:-1, None]
        edges = [c[i] + s * (c[(i + 1) % 4] - c[i]) for i in range(4)]
        h = geometry.half_side_m * (1 - 1e-6)
        g = np.linspace(-h, h, INTERIOR_GRID)
        gx, gy = np.meshgrid(g, g)
        interior = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
        markers = {}
        for m in phase_markers(geometry):
            a = m.size_m / 2 * (1 - 1e-6)
            t = np.linspace(-a, a, MARKER_GRID)
            mx, my = np.meshgrid(t, t)
            inner = np.column_stack([mx.ravel(), my.ravel(), np.zeros(mx.size)]) + m.center
            markers[m.name] = np.concatenate([m.outer_corners, inner])
        return cls(c, np.concatenate([c] + edges), interior, markers)


def depth_occlusion(render_camera: Camera, z_render: np.ndarray, cam2pad: np.ndarray):
    """``occluded(points_P (N, 3)) -> (N,) bool``: True where the rendered depth at a pad point's
    pixel (of the undistorted render camera) is nearer than the point by more than the depth
    buffer's resolution allows.  Points outside the render are not occluded (the image test
    decides those)."""
    pad2cam = invert(cam2pad)
    H, W = z_render.shape

    def occluded(points_P):
        Pc = transform_points(pad2cam, points_P)
        px = render_camera.project(Pc)
        out = np.zeros(len(Pc), bool)
        ok = np.isfinite(px).all(axis=1) & (Pc[:, 2] > 0)
        u = np.round(px[ok, 0]).astype(np.int64)
        v = np.round(px[ok, 1]).astype(np.int64)
        inside = (u >= 0) & (u < W) & (v >= 0) & (v < H)
        idx = np.nonzero(ok)[0][inside]
        z = Pc[idx, 2]
        out[idx] = z_render[v[inside], u[inside]] < z - (0.01 + 0.002 * z)
        return out

    return occluded


def phase_markers(geometry: PadGeometry) -> tuple:
    """The corner markers the phase rule looks at: the pad's own, or, on a pad without them, the
    paper pad's of the same spec (module size and place)."""
    own = geometry.markers_in("corner")
    if own:
        return own
    from pad_design.layout import build_geometry
    from pad_design.spec import PadSpec

    spec = {k: v for k, v in geometry.spec.items() if not k.startswith("artwork_")}
    return build_geometry(PadSpec.model_validate({**spec, "variant": "paper"})).markers_in("corner")


def view_facts(camera: Camera, cam2pad: np.ndarray, geometry: PadGeometry, occluded=None,
               samples: PadSamples | None = None) -> dict:
    """Visibility facts of one pose: the outer corners' pixels and visibility, the whole pad's,
    each corner marker's, the share of the pad's area in view, the smallest visible module."""
    samples = samples or PadSamples.of(geometry)
    pad2cam = invert(cam2pad)

    def seen(P):
        Pc = transform_points(pad2cam, P)
        px = camera.project(Pc)
        vis = (Pc[:, 2] > 0) & camera.in_image(px)
        if occluded is not None and vis.any():
            vis &= ~occluded(P)
        return vis, px

    corner_vis, corners_px = seen(samples.corners)
    outline_vis, _ = seen(samples.outline)
    inner_vis, _ = seen(samples.interior)
    marker_vis = {}
    module_px = np.inf
    for m in phase_markers(geometry):
        vis, _ = seen(samples.markers[m.name])
        marker_vis[m.name] = bool(vis.all())
        if marker_vis[m.name]:
            mp = camera.project(transform_points(pad2cam, m.outer_corners))
            sides = np.linalg.norm(np.roll(mp, -1, axis=0) - mp, axis=1)
            module_px = min(module_px, float(sides.min()) / m.modules_across)
    return {"corners_px": corners_px, "corner_visible": corner_vis,
            "pad_fully_visible": bool(outline_vis.all() and inner_vis.all()),
            "pad_visible_fraction": float(inner_vis.mean()),
            "marker_visible": {n: marker_vis.get(n, False) for n in MARKER_NAMES},
            "markers_visible": int(sum(marker_vis.values())),
            "module_px": float(module_px) if np.isfinite(module_px) else 0.0}


def phase_gt(camera: Camera, cam2pad: np.ndarray, geometry: PadGeometry, min_module_px: float, facts=None) -> str:
    f = facts or view_facts(camera, cam2pad, geometry)
    if f["markers_visible"] == 3 and f["module_px"] >= min_module_px:
        return "adjustment"
    if f["pad_fully_visible"]:
        return "approaching"
    fit_height = geometry.side_m * min(camera.fx, camera.fy) / min(camera.width, camera.height)
    if cam2pad[2, 3] < fit_height:
        return "touchdown"
    return "approaching"
