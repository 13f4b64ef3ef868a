"""Speed benchmarks: render frames/s and localizer ms/frame, each beside a reference measured in
the same run (this machine is shared and noisy: read the ratios).

    python -m benchmarks.speed [--out FILE.json] [--quick]

Render: sim800 and field1080 cameras, motion blur off and on, full image formation (no disk),
beside one ``cv2.warpPerspective`` of the pad texture at the same output resolution (the floor
for a planar scene; no lens remap, no supersampling).  Realism: the ``realism`` suite's tiers, every
realism feature on against off, the same descents.  Localizer: ms per frame per phase at 800x800 and 1920x1080 on one core (OpenCV and
torch limited to one thread), on views warped from the pad texture, beside a plain
``cv2.cvtColor`` + ``cv2.GaussianBlur`` of the same frame; and one refinement of the texture
against its smeared drawing, through a pinhole and through a barrel lens, beside the same.
"""
from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np


def _timeit(fn, n: int, warmup: int = 2) -> float:
    for _ in range(warmup):
        fn()
    t = time.perf_counter()
    for _ in range(n):
        fn()
    return (time.perf_counter() - t) / n


def render_speed(spec_path, blur: bool, n: int, blur_method: str = "velocity", subframes=5,
                 consecutive: bool = False) -> dict:
    """Frames/s of the real per-frame pipeline (raster with depth, visibility, flow, lens, blur, noise,
    tone curve, labels; no disk), its breakdown by stage, and the PNG encoding that a writer thread
    does beside it; against one ``cv2.warpPerspective`` of the pad texture at the output size.
    ``spec_path``: a spec YAML, or a ``DatasetSpec``.  Frames spread from 30 to 90 % of the descent
    (each at another height: what is made once per height is made for every one), or with
    ``consecutive`` the ``n`` frames from 40 % on, as a sequence renders them."""
    import cv2
    import yaml

    from hvloc.geometry import invert
    from render.dataset import encode_png
    from render.frames import SequenceRenderer
    from render.planar import warp_pad_view
    from render.spec import DatasetSpec

    d = spec_path.model_dump(mode="json") if isinstance(spec_path, DatasetSpec) else yaml.safe_load(Path(spec_path).read_text())
    deg = d.setdefault("degradations", {})
    deg.update(motion_blur=blur, blur_method=blur_method, blur_subframes=subframes)
    spec = DatasetSpec.model_validate(d)
    r = SequenceRenderer(spec, 0)
    if consecutive:
        start = int(0.4 * (len(r) - 1))
        frames = np.arange(start, min(start + n, len(r)))
        r.render(int(frames[0]) - 1)  # warm up on the frame before
    else:
        frames = np.linspace(0.3 * (len(r) - 1), 0.9 * (len(r) - 1), n).round().astype(int)
        r.render(int(frames[0]))  # warm up (shader compilation, first allocations)
    r.stage_seconds.clear()
    t = time.perf_counter()
    outs = [r.render(int(k)) for k in frames]
    t_frame = (time.perf_counter() - t) / n
    stages = {k: 1000 * v / n for k, v in r.stage_seconds.items()}
    t_png = _timeit(lambda: encode_png(outs[-1].rgb), 3, 1)
    cam2pad = r.cam2pad(int(frames[0]))
    levels = [r.pad.texture_rgb]
    pinhole = r.camera.without_distortion()  # the floor: one plain warpPerspective at the output size
    t_warp = _timeit(lambda: warp_pad_view(r.pad, pinhole, cam2pad, supersample=1, levels=levels, in_light=False), n)
    r.close()
    raster = stages.get("raster+readback", 0.0)
    del cv2, invert
    return {"spec": spec.name, "frames": "consecutive" if consecutive else "spread",
            "resolution": f"{r.camera.width}x{r.camera.height}", "supersample": spec.camera.supersample,
            "blur": blur_method if blur else "none", "samples": [o.labels["blur_subframes"] for o in outs],
            "fps": 1.0 / t_frame, "ms_per_frame": 1000 * t_frame, "stages_ms": stages,
            "non_raster_share": 1.0 - raster / (1000 * t_frame), "png_ms_writer_thread": 1000 * t_png,
            "ref_warp_ms": 1000 * t_warp, "ratio_to_warp": t_frame / t_warp}


def realism_speed(n: int, consecutive: bool = False) -> dict:
    """The cost of every realism feature: the ``realism`` suite's two tiers (the same descents, once
    plain and once with ground detail, a rolling shutter, vignetting, chromatic aberration, auto
    exposure, sharpening, a glossy dirty wrinkled pad and landing legs), motion blur on in both,
    timed alternately (three times each, the fastest run kept: the machine is shared); frames
    spread over the descent, or ``consecutive`` ones (:func:`render_speed`)."""
    from .suite import load_suite

    _, specs, _, _ = load_suite("realism")
    tiers = {s.name: s for s in specs if s.name in ("r_plain", "r_real")}
    runs = {"r_plain": [], "r_real": []}
    for _ in range(3):
        for name in runs:
            runs[name].append(render_speed(tiers[name], True, n, consecutive=consecutive))
    best = {k: min(v, key=lambda r: r["ms_per_frame"]) for k, v in runs.items()}
    p, r = best["r_plain"], best["r_real"]
    return {"frames": "consecutive" if consecutive else "spread", "plain": p, "real": r,
            "ratio": r["ms_per_frame"] / p["ms_per_frame"],
            "ratio_with_png": (r["ms_per_frame"] + r["png_ms_writer_thread"]) / (p["ms_per_frame"] + p["png_ms_writer_thread"])}


def localizer_speed(width: int, height: int, hfov_deg: float, n: int) -> list:
    import cv2

    from hvloc.config import LocalizerConfig
    from hvloc.geometry import Camera, so3_exp
    from hvloc.localizer import DEFAULT_T_B_C, HierarchicalLocalizer
    from pad_design import make_pad
    from render.planar import nadir_cam2pad, warp_pad_view

    pad = make_pad()
    cam = Camera.from_hfov(width, height, math.radians(hfov_deg))
    out = []
    # heights inside each phase for this camera: far (outline), middle (markers), low (flow)
    f = cam.fx
    h_far = min(20.0, pad.side_m * f / 30.0)
    for phase, h0, h1 in (("approaching", h_far, h_far * 0.9), ("adjustment", 2.5, 2.2), ("touchdown", 0.30, 0.26)):
        views = []
        for i in range(n + 3):
            s = i / (n + 2)
            T = nadir_cam2pad(0.05 + 0.02 * s, -0.03, h0 + (h1 - h0) * s, 0.3 + 0.05 * s)
            T[:3, :3] = T[:3, :3] @ so3_exp([0.02, -0.01, 0.0])
            views.append((warp_pad_view(pad, cam, T, (80, 110, 60)), T))
        loc = HierarchicalLocalizer(pad, cam, LocalizerConfig())
        if phase == "touchdown":  # anchor the tracker as the descent would have
            loc.flow.anchor(cv2.cvtColor(views[0][0], cv2.COLOR_RGB2GRAY), views[0][1])
            loc.phase = "touchdown"
            loc.config = LocalizerConfig(use_markers=False, use_outline=False)
            loc.last = None
        ms, methods, ok = [], [], 0
        for i, (img, T) in enumerate(views[1:]):
            up = (T[:3, :3] @ DEFAULT_T_B_C[:3, :3].T)
            e = loc.process(img, 0.02 * i, up)
            if phase == "touchdown" and loc.last is None and e.ok:
                loc.last = e
            if i >= 2:
                ms.append(e.ms)
                methods.append(e.method)
                ok += e.ok
        ref = _timeit(lambda: cv2.GaussianBlur(cv2.cvtColor(views[1][0], cv2.COLOR_RGB2GRAY), (5, 5), 0), n)
        out.append(_speed_row(width, height, phase, h0, ms, ok, methods, ref))
        if phase == "adjustment":  # the peer at the same poses, on its own pad
            from .peers import ArucoLocalizer

            apad = make_pad({"variant": "aruco"})
            peer = ArucoLocalizer(apad, cam)
            ms, methods, ok = [], [], 0
            for img in [warp_pad_view(apad, cam, T, (80, 110, 60)) for _, T in views[3:]]:
                e = peer.process(img, 0.0)
                ms.append(e.ms)
                methods.append(e.method)
                ok += e.ok
            out.append(_speed_row(width, height, "adjustment (aruco peer)", h0, ms, ok, methods, ref))
    return out


def _texture_pad():
    """The default pad printed at 1000 px/m, and its :class:`hvloc.texture.PadTexture`."""
    from hvloc.texture import PadTexture
    from pad_design import make_pad

    pad = make_pad(ppm=1000.0)
    return pad, PadTexture(pad)


def _texture_views(h: float):
    """``(name, camera, cam2pad)``: 1280x720 through a pinhole (90 degrees) and through a 100 degree
    barrel lens (k1 -0.22), ``h`` over the pad, a little off its centre, yawed and tilted."""
    from hvloc.geometry import Camera, so3_exp
    from render.planar import nadir_cam2pad

    for name, dist in (("pinhole 90 deg", (0, 0, 0, 0, 0)), ("barrel 100 deg", (-0.22, 0.04, 0, 0, 0))):
        cam = Camera.from_hfov(1280, 720, math.radians(90 if name.startswith("pinhole") else 100), dist=dist)
        G = nadir_cam2pad(0.05, -0.03, h, 0.3)
        G[:3, :3] = G[:3, :3] @ so3_exp([0.03, -0.02, 0.0])
        yield name, cam, G


def texture_smear_speed(n: int) -> list:
    """ms of one refinement of the texture against its drawing smeared by the frame's motion
    (``PadTexture.refined_under``: the drawing of 8 instants, drawn twice), at 1280x720 through a
    pinhole (90 degrees) and through a 100 degree barrel lens (k1 -0.22), 0.25 m over the default
    pad printed at 1000 px/m, 0.4 m/s across a 25 ms exposure (about 25 px of smear); beside a
    plain ``cv2.cvtColor`` + ``cv2.GaussianBlur`` of the same frame."""
    import cv2

    from hvloc.shutter import Twist
    from render.planar import warp_pad_view

    pad, tex = _texture_pad()
    out = []
    for name, cam, G in _texture_views(0.25):
        v, e = np.array([0.4, -0.1, -0.1]), 0.025
        views = []
        for s in np.linspace(-0.5, 0.5, 12):  # the exposure's instants, averaged
            T = G.copy()
            T[:3, 3] += s * e * v
            views.append(warp_pad_view(pad, cam, T, (80, 110, 60), supersample=1).astype(np.float32))
        gray = cv2.cvtColor(np.mean(views, axis=0).astype(np.uint8), cv2.COLOR_RGB2GRAY)
        found = tex.refined_under(gray, cam, G, Twist(v, None), e, 20.0)[0]
        ms = 1000 * _timeit(lambda: tex.refined_under(gray, cam, G, Twist(v, None), e, 20.0), n, warmup=1)
        ref = _timeit(lambda: cv2.GaussianBlur(cv2.cvtColor(np.mean(views[:1], axis=0).astype(np.uint8), cv2.COLOR_RGB2GRAY),
                                               (5, 5), 0), n)
        out.append({"camera": f"1280x720 {name}", "ms": ms, "refined": None if found is None else found.info["refined"],
                    "smeared_px": None if found is None else found.info["smeared_px"], "ref_gray_blur_ms": 1000 * ref,
                    "ratio_to_ref": ms / (1000 * ref)})
    return out


def texture_placed_speed(n: int) -> list:
    """ms of the texture placed at a pose known to a few pixels (``PadTexture.placed_at``: drawn
    there, its corners tracked into the frame, drawn again and tracked again: how a chained flow
    keyframe's first pose is anchored again), beside the texture found by ORB with no pose
    (``PadTexture.locate``), at 1280x720 through a pinhole (90 degrees) and through a 100 degree
    barrel lens (k1 -0.22), a sharp frame 0.4 m over the default pad printed at 1000 px/m, the pose
    it is placed at 2 mm and 0.2 degrees off; beside a plain ``cv2.cvtColor`` + ``cv2.GaussianBlur``."""
    import cv2

    from hvloc.geometry import so3_exp
    from render.planar import warp_pad_view

    pad, tex = _texture_pad()
    out = []
    for name, cam, G in _texture_views(0.4):
        T = G.copy()
        T[:3, 3] += [0.0015, -0.001, 0.001]
        T[:3, :3] = T[:3, :3] @ so3_exp(np.radians([0.2, 0.0, 0.0]))
        gray = cv2.cvtColor(warp_pad_view(pad, cam, G, (80, 110, 60)), cv2.COLOR_RGB2GRAY)
        placed = tex.placed_at(gray, cam, T, None, 0.0, 6.0)[0]
        found = tex.locate(gray, cam, 0.4)[0]
        ms = 1000 * _timeit(lambda: tex.placed_at(gray, cam, T, None, 0.0, 6.0), n, warmup=1)
        orb_ms = 1000 * _timeit(lambda: tex.locate(gray, cam, 0.4), n, warmup=1)
        ref = 1000 * _timeit(lambda: cv2.GaussianBlur(cv2.cvtColor(cv2.cvtColor(gray, cv2.COLOR_GRAY2RGB), cv2.COLOR_RGB2GRAY),
                                                      (5, 5), 0), n)
        out.append({"camera": f"1280x720 {name}", "placed_ms": ms, "placed": None if placed is None else placed.info["refined"],
                    "orb_ms": orb_ms, "orb_found": None if found is None else found.info.get("refined", len(found.px)),
                    "ref_gray_blur_ms": ref, "ratio_to_ref": ms / ref, "ratio_to_orb": ms / orb_ms})
    return out


def keyframe_refine_speed(n: int) -> list:
    """ms of the flow's refinement of its tracks against their keyframe (``refined_on_keyframe``: the
    keyframe warped to the frame by the tracks' homography through the lens, both divided by their
    local mean, one Lucas-Kanade pass), beside that pass on the keyframe as it is (how it was done
    before), at 1280x720 through a pinhole (90 degrees) and through a 100 degree barrel lens (k1
    -0.22): 150 tracks, the frame 0.40 m over the pad printed at 1000 px/m, the keyframe 0.44 m."""
    import cv2

    from hvloc.geometry import invert, so3_exp, transform_points
    from hvloc.phases import LK_PARAMS, make_keyframe, refined_on_keyframe
    from render.planar import warp_pad_view

    pad, _ = _texture_pad()
    out = []
    for name, cam, G in _texture_views(0.40):
        K = G.copy()
        K[:3, 3] += [0.004, -0.003, 0.04]
        K[:3, :3] = K[:3, :3] @ so3_exp(np.radians([0.5, -0.3, 2.0]))
        view = lambda T: cv2.cvtColor(warp_pad_view(pad, cam, T, (80, 110, 60)), cv2.COLOR_RGB2GRAY)
        kf, gray = make_keyframe(view(K), K, cam, anchored=True), view(G)
        truth = cam.project(transform_points(invert(G), kf.pts_P))
        p1 = (truth + 0.3).astype(np.float32).reshape(-1, 1, 2)
        kf_px = kf.px.astype(np.float32).reshape(-1, 1, 2)
        good = np.ones(len(kf_px), bool)
        p2 = refined_on_keyframe(kf, gray, kf_px, p1, good, cam)[0]
        q2 = cv2.calcOpticalFlowPyrLK(kf.gray, gray, kf_px, p1.copy(), flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
                                      **{**LK_PARAMS, "maxLevel": 1})[0]
        ms = 1000 * _timeit(lambda: refined_on_keyframe(kf, gray, kf_px, p1, good, cam), n)
        plain = 1000 * _timeit(lambda: cv2.calcOpticalFlowPyrLK(kf.gray, gray, kf_px, p1.copy(), flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
                                                                 **{**LK_PARAMS, "maxLevel": 1}), n)
        ref = 1000 * _timeit(lambda: cv2.GaussianBlur(cv2.cvtColor(cv2.cvtColor(gray, cv2.COLOR_GRAY2RGB), cv2.COLOR_RGB2GRAY),
                                                      (5, 5), 0), n)
        out.append({"camera": f"1280x720 {name}", "tracks": len(kf_px), "ms": ms, "plain_lk_ms": plain,
                    "median_err_px": float(np.median(np.linalg.norm(p2[:, 0] - truth, axis=1))),
                    "plain_median_err_px": float(np.median(np.linalg.norm(q2[:, 0] - truth, axis=1))),
                    "ref_gray_blur_ms": ref, "ratio_to_ref": ms / ref, "ratio_to_plain": ms / plain})
    return out


def _jpeg(rgb: np.ndarray, quality: int) -> np.ndarray:
    """``rgb`` through OpenCV's JPEG at ``quality`` (chroma at half resolution, 4:2:0)."""
    import cv2

    return np.ascontiguousarray(cv2.imdecode(cv2.imencode(".jpg", rgb[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, quality])[1],
                                             cv2.IMREAD_COLOR)[..., ::-1])


def _report(res: dict, key: str, rows: list, line) -> None:
    """``rows`` kept in ``res[key]``, each printed as ``line(row)`` says."""
    res[key] = rows
    for r in rows:
        print(line(r), flush=True)


def chroma_tell_speed(n: int) -> list:
    """ms of telling a frame's chroma halved (``hvloc.phases.chroma_halved``: the column parity of its
    sharp chroma steps, every other row; the outline's sides are placed in light where it is whole),
    on a view of the default pad 3 m up at 1280x720 and 1920x1080, as rendered and through JPEG 75;
    beside a plain ``cv2.cvtColor`` + ``cv2.GaussianBlur`` of the same frame."""
    import cv2

    from hvloc.geometry import Camera
    from hvloc.phases import chroma_halved
    from render.planar import nadir_cam2pad, warp_pad_view

    pad, _ = _texture_pad()
    out = []
    for w, h in ((1280, 720), (1920, 1080)):
        cam = Camera.from_hfov(w, h, math.radians(90))
        rgb = warp_pad_view(pad, cam, nadir_cam2pad(0.3, -0.2, 3.0, 0.4), (80, 110, 60))
        jpeg = _jpeg(rgb, 75)
        ms = 1000 * _timeit(lambda: chroma_halved(rgb), n)
        ref = 1000 * _timeit(lambda: cv2.GaussianBlur(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY), (5, 5), 0), n)
        out.append({"resolution": f"{w}x{h}", "ms": ms, "halved_as_rendered": chroma_halved(rgb),
                    "halved_jpeg75": chroma_halved(jpeg), "ref_gray_blur_ms": ref, "ratio_to_ref": ms / ref})
    return out


def design_fit_speed(n: int) -> list:
    """ms of fitting the default pad's drawn design to a view (``hvloc.texfit.fit_pose_to_design``,
    from the labelled pose moved 1 %) at 40, 90 and 130 px across, 1280x720 behind an 80 degree lens
    through JPEG 50 (pads over 64 px are fitted only where the chroma is halved), beside finding the
    outline in the same frame (``hvloc.phases.find_outline``); and the heights' error."""
    import cv2

    from hvloc.geometry import Camera
    from hvloc.phases import find_outline
    from hvloc.synthesis import PadSynthesis
    from hvloc.texfit import HALVED_MAX_SIDE_PX, fit_pose_to_design
    from render.planar import nadir_cam2pad, warp_pad_view

    pad, _ = _texture_pad()
    cam = Camera.from_hfov(1280, 720, math.radians(80))
    syn = PadSynthesis(pad)
    out = []
    for side in (40, 90, 130):
        h = pad.geometry.side_m * cam.fx / side
        G = nadir_cam2pad(0.3, -0.2, h, 0.4)
        rgb = warp_pad_view(pad, cam, G, (80, 110, 60))
        jpeg = _jpeg(rgb, 50)
        start = G.copy()
        start[:3, 3] *= 1.01
        fitted, _ = fit_pose_to_design(jpeg, cam, syn, start, max_side_px=HALVED_MAX_SIDE_PX)
        ms = 1000 * _timeit(lambda: fit_pose_to_design(jpeg, cam, syn, start, max_side_px=HALVED_MAX_SIDE_PX), n)
        ref = 1000 * _timeit(lambda: find_outline(jpeg, pad.geometry, cam, halved=True), n)
        out.append({"side_px": side, "ms": ms, "ref_outline_ms": ref, "ratio_to_ref": ms / ref,
                    "height_err_pct": None if fitted is None else 100 * (fitted[2, 3] - h) / h})
    return out


def _speed_row(width, height, phase, h, ms, ok, methods, ref) -> dict:
    return {"resolution": f"{width}x{height}", "phase": phase, "height_m": round(h, 2),
            "ms_p50": float(np.percentile(ms, 50)), "ms_p95": float(np.percentile(ms, 95)),
            "ok": f"{ok}/{len(ms)}", "methods": sorted(set(methods)), "ref_gray_blur_ms": 1000 * ref,
            "ratio_to_ref": float(np.percentile(ms, 50)) / (1000 * ref)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.speed", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="out/speed.json", help="where the numbers are written as JSON")
    p.add_argument("--quick", action="store_true", help="fewer frames (a smoke run)")
    p.add_argument("--skip-render", action="store_true", help="localizer speed only")
    a = p.parse_args(argv)
    import cv2
    import torch

    cv2.setNumThreads(1)
    torch.set_num_threads(1)
    from benchmarks.suite import REPO, provenance

    n = 5 if a.quick else 20
    res = {"provenance": provenance(), "threads": 1, "render": [], "localizer": []}
    if not a.skip_render:
        from render.gl import choose_platform

        res["gl_platform"] = choose_platform()[0]
        print(f"GL platform: {res['gl_platform']}")
        for spec in ("sim800", "field1080"):
            for blur, method in ((False, "velocity"), (True, "velocity"), (True, "subframes")):
                if method == "subframes" and a.quick:
                    continue
                r = render_speed(str(REPO / "data_specs" / f"{spec}.yaml"), blur, max(3, n // 2), method)
                res["render"].append(r)
                st = "  ".join(f"{k} {v:.1f}" for k, v in r["stages_ms"].items())
                print(f"render {r['spec']:10s} {r['resolution']:>9s} ss{r['supersample']} blur {r['blur']:9s} "
                      f"samples {min(r['samples'])}-{max(r['samples'])}: {r['fps']:6.2f} frames/s "
                      f"({r['ms_per_frame']:6.1f} ms; not raster {100 * r['non_raster_share']:.0f} %; png "
                      f"{r['png_ms_writer_thread']:.0f} ms on the writer thread)  warpPerspective {r['ref_warp_ms']:5.2f} ms "
                      f"ratio {r['ratio_to_warp']:6.1f}x\n    ms: {st}", flush=True)
        res["realism"] = []
        for consecutive, k in ((False, max(3, n // 2)), (True, max(6, n))):
            rs = realism_speed(k, consecutive)
            res["realism"].append(rs)
            print(f"realism ({k} {rs['frames']} frames): every feature on {rs['real']['ms_per_frame']:.1f} ms/frame, off "
                  f"{rs['plain']['ms_per_frame']:.1f} ms/frame ({rs['real']['resolution']}, motion blur on): ratio "
                  f"{rs['ratio']:.2f}x (target <= 1.5x); with the PNG encoding {rs['ratio_with_png']:.2f}x\n    on: "
                  + "  ".join(f"{k} {v:.1f}" for k, v in rs["real"]["stages_ms"].items())
                  + "\n    off: " + "  ".join(f"{k} {v:.1f}" for k, v in rs["plain"]["stages_ms"].items()), flush=True)
    for w, h, fov in ((800, 800, 60.0), (1920, 1080, 94.0)):
        for r in localizer_speed(w, h, fov, n):
            res["localizer"].append(r)
            print(f"localize {r['resolution']:>9s} {r['phase']:23s} (h {r['height_m']:5.2f} m, {','.join(r['methods'])}, "
                  f"ok {r['ok']}): p50 {r['ms_p50']:6.2f} ms  p95 {r['ms_p95']:6.2f} ms  "
                  f"gray+blur {r['ref_gray_blur_ms']:5.2f} ms  ratio {r['ratio_to_ref']:5.1f}x", flush=True)
    _report(res, "texture_smear", texture_smear_speed(max(3, n // 4)), lambda r: (
        f"texture refined under {r['smeared_px']} px of smear, {r['camera']:24s} ({r['refined']} corners): "
        f"{r['ms']:6.1f} ms  gray+blur {r['ref_gray_blur_ms']:5.2f} ms  ratio {r['ratio_to_ref']:5.1f}x"))
    _report(res, "texture_placed", texture_placed_speed(max(3, n // 4)), lambda r: (
        f"texture placed at a pose, {r['camera']:24s} ({r['placed']} corners): {r['placed_ms']:6.1f} ms  found by ORB "
        f"({r['orb_found']} corners) {r['orb_ms']:6.1f} ms  gray+blur {r['ref_gray_blur_ms']:5.2f} ms  ratio "
        f"{r['ratio_to_ref']:5.1f}x (to ORB's {r['ratio_to_orb']:.2f}x)"))
    _report(res, "keyframe_refine", keyframe_refine_speed(n), lambda r: (
        f"tracks refined on their keyframe, {r['camera']:24s} ({r['tracks']} tracks, {r['median_err_px']:.3f} px off "
        f"in the median): {r['ms']:6.2f} ms  on the keyframe as it is {r['plain_lk_ms']:5.2f} ms "
        f"({r['plain_median_err_px']:.3f} px off)  gray+blur "
        f"{r['ref_gray_blur_ms']:5.2f} ms  ratio {r['ratio_to_ref']:5.1f}x (to the plain pass {r['ratio_to_plain']:.1f}x)"))
    _report(res, "chroma_tell", chroma_tell_speed(n), lambda r: (
        f"chroma told halved or whole, {r['resolution']:>9s} (as rendered: {r['halved_as_rendered']}, JPEG 75: "
        f"{r['halved_jpeg75']}): {r['ms']:6.2f} ms  gray+blur {r['ref_gray_blur_ms']:5.2f} ms  ratio "
        f"{r['ratio_to_ref']:5.1f}x"))
    _report(res, "design_fit", design_fit_speed(n), lambda r: (
        f"design fitted to a {r['side_px']:3d} px pad, 1280x720 JPEG 50 "
        f"({'failed' if r['height_err_pct'] is None else format(r['height_err_pct'], '+.2f') + ' % of the height'}): "
        f"{r['ms']:6.1f} ms  outline found {r['ref_outline_ms']:5.1f} ms  ratio {r['ratio_to_ref']:5.1f}x"))
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=1) + "\n")
    print(f"written {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
