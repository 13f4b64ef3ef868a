"""Ground-truth landing phase: what a perfect detector could see in the frame.

Rule (per frame, from the labelled pose alone, never from a localizer):

* ``adjustment`` while all three corner finder markers are fully in the image and their
  modules are at least ``min_module_px`` pixels (so a marker detector can resolve them);
* else ``approaching`` while the whole pad outline is in the image;
* else ``touchdown`` once the camera is low enough that the pad no longer fits in the image
  (height below ``side * f / min(W, H)``): the flow tracker's range;
* else ``approaching`` (the pad is partly out of view at range: nothing sees it well).
"""
from __future__ import annotations

import numpy as np

from hvloc.geometry import Camera, invert, transform_points

PHASES = ("approaching", "adjustment", "touchdown")


def view_facts(camera: Camera, cam2pad: np.ndarray, pad_geometry: dict) -> dict:
    """Visibility facts of one pose: pad outline, markers, module size in pixels."""
    pad2cam = invert(cam2pad)
    outer = np.asarray(pad_geometry["outer_corners"], float)
    Pc = transform_points(pad2cam, outer)
    px = camera.project(Pc)
    pad_visible = bool(np.all(Pc[:, 2] > 0) and np.all(camera.in_image(px)))
    markers_visible = 0
    module_px = np.inf
    for m in pad_geometry["markers"]:
        if m["set"] != "corner":
            continue
        sq = np.asarray(m["squares"][0]["corners"], float)
        mc = transform_points(pad2cam, sq)
        mp = camera.project(mc)
        if np.all(mc[:, 2] > 0) and np.all(camera.in_image(mp)):
            markers_visible += 1
            sides = np.linalg.norm(np.roll(mp, -1, axis=0) - mp, axis=1)
            module_px = min(module_px, float(sides.min()) / (7.0 if m["kind"] == "finder" else 6.0))
    return {"corners_px": px, "pad_fully_visible": pad_visible, "markers_visible": markers_visible,
            "module_px": float(module_px) if np.isfinite(module_px) else 0.0}


def phase_gt(camera: Camera, cam2pad: np.ndarray, pad_geometry: dict, min_module_px: float, facts=None) -> str:
    f = facts or view_facts(camera, cam2pad, pad_geometry)
    if f["markers_visible"] == 3 and f["module_px"] >= min_module_px:
        return "adjustment"
    if f["pad_fully_visible"]:
        return "approaching"
    fit_height = pad_geometry["side_m"] * min(camera.fx, camera.fy) / min(camera.width, camera.height)
    if cam2pad[2, 3] < fit_height:
        return "touchdown"
    return "approaching"
