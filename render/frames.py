"""Render one sequence frame by frame as named layers (the dataset writer decides what goes to disk).

``SequenceRenderer(spec, index).render(k) -> FrameLayers``:

* ``rgb``       ``(H, W, 3)`` uint8: the camera's image (OpenCV pixel convention).
* ``depth_m``   ``(H, W)`` float32: depth along the optical axis at each pixel centre at the frame
  time, metres; ``inf`` where nothing is (the sky).
* ``motion_px`` ``(H, W, 2)`` float32: each pixel's image motion from the shutter's opening to
  its closing (``None`` when the frame has no motion blur).
* ``labels``    ``{column: value}``: the frame's row of ``frames.csv`` (:data:`render.dataset.FRAME_COLUMNS`).
* ``airframe_mask`` ``(H, W)`` bool: where the camera sees the drone's own legs, arms or propeller discs (``None``: none).

Each frame is rasterised once with its depth at the frame time; the depth gives the labels'
occlusion (what the camera really sees) and each pixel's image motion, from which the motion
blur is made (:mod:`render.motion`).  ``degradations.blur_method: subframes`` renders one image
per sample time instead (the exact reference).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import cv2
import numpy as np

from hvloc.geometry import continuous_quaternions, invert, tum_from_transform

from . import motion as mo
from .phase import PadSamples, depth_occlusion, pad_image_motion_px, phase_gt, view_facts
from .imaging import SRGB_TO_LINEAR
from .plan import camera_from_spec, mount_from_spec, pad_for, plan_sequence
from .spec import DatasetSpec


@dataclass
class FrameLayers:
    index: int
    t: float
    rgb: np.ndarray
    depth_m: np.ndarray
    motion_px: np.ndarray | None
    labels: dict
    airframe_mask: np.ndarray | None = None


PAD_WINDOW_SAMPLES = 64  # points along each side of the pad whose images bound its window (pad_window)


def pad_window(camera, cam2pad: np.ndarray, corners_P: np.ndarray) -> tuple:
    """``(r0, r1, c0, c1)``: the rows and columns of the image the pad (``corners_P``, its outline in
    its frame) may show in.  Bounded by the images of points
    along its sides, not of its corners alone: through a barrel lens a side near the image's edge
    bows out past its corners' box (its sliver got no glare, relief shading or deck light).  The
    whole image where any of them falls outside it or behind the camera: a lens model folds points
    far out of view back in, and a corner near the camera's plane projects past any integer."""
    H, W = camera.height, camera.width
    t = np.linspace(0.0, 1.0, PAD_WINDOW_SAMPLES, endpoint=False)[:, None, None]
    c = np.asarray(corners_P, np.float64)
    px = camera.project_from(cam2pad, (c + t * (np.roll(c, -1, axis=0) - c)).reshape(-1, 3))
    if not (np.isfinite(px).all() and camera.in_image(px).all()):
        return 0, H, 0, W
    (c0, r0), (c1, r1) = np.floor(px.min(axis=0)).astype(int) - 2, np.ceil(px.max(axis=0)).astype(int) + 3
    return max(r0, 0), min(r1, H), max(c0, 0), min(c1, W)  # (all in view: never empty)


class SequenceRenderer:
    """The scene, camera and image formation of one sequence; :meth:`render` makes frame ``k``.

    Creating one makes this process keep the memory it frees (:func:`render.memory.keep_freed_memory`):
    each frame reuses the last one's pages instead of faulting fresh ones in."""

    def __init__(self, spec: DatasetSpec, index: int, texture_png=None):
        from .imaging import ImageFormation
        from .memory import keep_freed_memory
        from .scene import PAD_THICKNESS_M, LandingScene

        keep_freed_memory()
        self.spec = spec
        self.plan = plan = plan_sequence(spec, index)
        self.pad = pad = pad_for(spec, texture_png)
        self.camera = camera = camera_from_spec(spec.camera)
        self.T_B_C = mount_from_spec(spec.camera.mount)
        self.times = plan.frame_times
        self.exposure = float(spec.camera.exposure_s)
        d = spec.degradations
        self.blur = bool(d.motion_blur and self.exposure > 0)
        # rolling shutter: row r is exposed at t + (r - middle row) * line time
        self.line_s = float(spec.camera.rolling_shutter_line_s)
        self.ref_row = (spec.camera.height - 1) / 2.0
        self.row_dt = (np.arange(spec.camera.height) - self.ref_row) * self.line_s
        self.floor = 1 if d.blur_subframes == "auto" else int(d.blur_subframes)
        self.method = d.blur_method
        self.imaging = ImageFormation(camera, spec.camera.supersample, plan.imaging, 1.0, plan.seed)
        from .textures import dirty_texture

        a = spec.airframe
        self.legs = []
        for i in range(a.legs):
            az = np.radians(a.leg_azimuth_deg + 360.0 * i / a.legs)
            xy = a.leg_spread_m * np.array([np.cos(az), np.sin(az)])
            self.legs.append(((xy[0], xy[1], -a.leg_length_m), (xy[0], xy[1], 0.0), a.leg_diameter_m, a.leg_color))
        self.props = []  # (centre xyz in the body frame, radius m) of each propeller's disc
        for i in range(a.arms):  # the arms join the legs: tubes rigid with the body
            az = np.radians(a.arm_azimuth_deg + 360.0 * i / a.arms)
            u = np.array([np.cos(az), np.sin(az)])
            tip = a.arm_length_m * u
            self.legs.append(((0.3 * tip[0], 0.3 * tip[1], a.arm_z_m), (tip[0], tip[1], a.arm_z_m), a.arm_diameter_m,
                              a.arm_color))
            if a.prop_diameter_m > 0 and a.prop_alpha > 0:
                self.props.append((np.array([tip[0], tip[1], a.arm_z_m + a.prop_z_m]), a.prop_diameter_m / 2))
        self.material = plan.material
        # how far a moving deck's box reaches below the ground (it must never lift off as the deck moves)
        self.deck_drop_m = spec.platform.max_edge_drop_m() + 0.05 if spec.platform.deck_moves() else 0.0
        self._deck_tilts = spec.platform.deck_tilts()
        self.scene = LandingScene(pad, plan.scene_draw, spec.platform.height_m, spec.platform.size_m,
                                  self.imaging.render_camera, pad.spec.border_color,
                                  np.random.default_rng(plan.seed ^ 0x5EED), shadows=spec.environment.shadows,
                                  znear=min(0.05, 0.5 * spec.trajectory.touchdown_height_m),
                                  pad_texture=dirty_texture(pad.texture_rgb, self.material["dirt"],
                                                            self.material["dirt_seed"]),
                                  legs=self.legs, pad_relief=self.material.get("relief"),
                                  deck_drop_m=self.deck_drop_m,
                                  deck_turns=spec.platform.deck_turns(), light=spec.camera.mix_in_light)
        self.samples = PadSamples.of(pad.geometry)
        self.relief_px: list = []  # per frame: how far the features' images on the relief lie from the labels'
        self.stage_seconds: dict = {}  # time spent per stage of render(), summed over frames
        traj = plan.trajectory
        self.body2world = traj.body_poses(self.times)
        self.pad2world = traj.pad_poses(self.times)
        state = traj.state(self.times)
        self.body_vel = state.vel_W
        self.pad_vel = traj.pad_velocities(self.times)
        self.platform_moves = traj.pad_moves
        self.rays = mo.pixel_rays(camera)
        self.flow = mo.FlowField(camera, rays=self.rays) if (self.blur or self.line_s > 0) else None
        self.ground = None
        if spec.environment.ground_detail:
            from .ground import GroundDetail

            draw = plan.scene_draw
            # on a platform the pad is not on the ground (the platform's base is: its sides must
            # not take the ground's detail where they meet it)
            size = spec.platform.size_m if spec.platform.height_m > 0 else pad.side_m + 0.02
            flat = [(0.0, 0.0, 0.0, size, size, True)]
            flat += [(x, y, yaw, sx, sy, False) for x, y, yaw, sx, sy in draw.decoy_patches]
            flat += [(x, y, yaw, size, size, False) for x, y, yaw, size, _, _ in draw.decoy_markers]
            self.ground = GroundDetail(draw.ground, plan.seed, camera, *self.rays, flat)
        # what moves with the platform, in the pad frame: its top and sides, the pad (and its margin)
        half = max(pad.side_m / 2, spec.platform.size_m / 2 if spec.platform.height_m > 0 else 0.0) + 1e-3
        self._moving_half = half
        # (a deck's box reaches below the ground by its travel: its sides rise into view as it heaves)
        self._moving_floor = -(spec.platform.height_m + PAD_THICKNESS_M + self.deck_drop_m) + 1e-3
        # quaternions keep one hemisphere from row to row
        self._quats = continuous_quaternions([tum_from_transform(self.cam2pad(k))[3:] for k in range(len(self.times))])
        self._body_quats = continuous_quaternions([tum_from_transform(T)[3:] for T in self.body2world])
        self.exposure_gain = self._auto_exposure(spec.camera.auto_exposure_lag_s)
        self.prop_alpha = self._prop_alpha(a.prop_alpha) if self.props else None
        if self.prop_alpha is not None:  # the discs' box: they are a sliver at the image's edge, composited there alone
            rows, cols = np.nonzero(self.prop_alpha.any(axis=1))[0], np.nonzero(self.prop_alpha.any(axis=0))[0]
            self.prop_box = np.s_[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
        self.prop_linear = None
        if self.prop_alpha is not None:  # the blades' underside: lit by the sky alone (the sun is above them)
            lin = (np.asarray(a.prop_color, np.float64) / 255.0) ** 2.2
            self.prop_linear = (lin * float(self.scene.relative_light(np.array([[0.0, 0.0, -1.0]]))[0])).astype(np.float32)
        self.airframe_mask = self._airframe_mask() if self.legs else None
        if self.prop_alpha is not None:
            seen = self.prop_alpha > 0.02
            self.airframe_mask = seen if self.airframe_mask is None else self.airframe_mask | seen
            if not self.airframe_mask.any():
                self.airframe_mask = None

    # ------------------------------------------------------------------ poses
    def __len__(self) -> int:
        return len(self.times)

    def cam2pad(self, k: int) -> np.ndarray:
        """``T_P_C`` at frame ``k``'s time."""
        return invert(self.pad2world[k]) @ self.body2world[k] @ self.T_B_C

    def _poses_at(self, t) -> tuple:
        traj = self.plan.trajectory
        return traj.body_poses(t), traj.pad_poses(t)

    # ------------------------------------------------------------------ one frame
    def render(self, k: int) -> FrameLayers:
        """Frame ``k`` of the sequence."""
        return self.render_at(k, float(self.times[k]), self.body2world[k], self.pad2world[k])

    def render_at(self, k: int, t: float, T_W_B: np.ndarray, T_W_P: np.ndarray) -> FrameLayers:
        """The scene seen from body pose ``T_W_B`` with the pad at ``T_W_P`` at time ``t`` (``k``
        seeds the frame's noise and names its row).  Motion blur follows the sequence's trajectory
        around ``t``; labels other than the pose and visibility assume frame ``k``."""
        clock = self.stage_seconds
        t0 = time.perf_counter()
        cam2world = T_W_B @ self.T_B_C
        cam2pad = invert(T_W_P) @ cam2world
        self.scene.set_platform(T_W_P)
        self.scene.set_drone(T_W_B)
        self._pad2world_now = T_W_P
        rgb_r, z_r = self.scene.render_with_depth(cam2world)
        t1 = time.perf_counter()
        facts = view_facts(self.camera, cam2pad, self.pad.geometry,
                           self._occlusion(z_r, cam2pad), self.samples)
        depth = self.imaging.depth_to_pixels(z_r)
        n, flows, half = 1, None, self.exposure / 2
        if self.flow is not None:
            half = float(np.abs(self.row_dt).max()) + (self.exposure / 2 if self.blur else 0.0)  # the path's ends
            flows, longest = self._flows(depth, cam2world, cam2pad, T_W_P, t, half)
            if self.blur:  # over the exposure alone (not the readout)
                n = mo.samples_needed(longest * self.exposure / (2 * half), self.floor)
        t2 = time.perf_counter()
        if n > 1 and self.method == "subframes":
            linear = self._subframes(t, n)
            t3 = t4 = time.perf_counter()
        else:
            linear = self.imaging.linear(rgb_r)
            self._surface_light(linear, depth, cam2world, T_W_P, cam2pad)
            t3 = time.perf_counter()
            if self.line_s > 0:
                linear = mo.velocity_blur(linear, flows[0], flows[1], n, self.flow.base, self.row_dt / half,
                                          (self.exposure if self.blur else 0.0) / half)
            elif n > 1:
                linear = mo.velocity_blur(linear, flows[0], flows[1], n, self.flow.base)
            t4 = time.perf_counter()
        if self.prop_alpha is not None:  # the propellers spin with the camera: over the exposure's blur, not in it
            box = self.prop_box
            a = np.where(depth[box] > self.prop_depth[box], self.prop_alpha[box], np.float32(0.0))[..., None]
            linear[box] = linear[box] * (1.0 - a) + a * self.prop_linear  # (not over an arm: the depth test)
        rgb = self.imaging.finish(linear, k, float(self.exposure_gain[k]) if k < len(self.exposure_gain) else 1.0)
        t5 = time.perf_counter()
        labels = self._labels(k, t, cam2pad, facts, n, T_W_B, T_W_P)
        if self.material.get("relief") is not None:
            self.relief_px.append(self._relief_offset_px(cam2pad))
        t6 = time.perf_counter()
        for name, dt in (("raster+readback", t1 - t0), ("visibility+flow", t2 - t1), ("lens+linear", t3 - t2),
                         ("blur", t4 - t3), ("noise+tone", t5 - t4), ("labels", t6 - t5)):
            clock[name] = clock.get(name, 0.0) + dt
        return FrameLayers(k, t, rgb, depth, None if flows is None else flows[1] - flows[0], labels,
                           self.airframe_mask)

    def _classify(self, cam2pad):
        """Which points (camera frame, frame time) move with the platform (1), are rigid with the
        camera (2: the airframe) or still in the world (0)."""
        R, tr = cam2pad[:3, :3], cam2pad[:3, 3]
        half, floor = self._moving_half, self._moving_floor
        T_C_B = invert(self.T_B_C)
        legs = [(T_C_B[:3, :3] @ np.array(b) + T_C_B[:3, 3], T_C_B[:3, :3] @ np.array(t) + T_C_B[:3, 3], d / 2 + 0.01)
                for b, t, d, _ in self.legs]
        legs_reach = max((max(a[2], b[2]) + r for a, b, r in legs), default=0.0)

        def classify(points_C):
            cls = np.zeros(len(points_C), np.int8)
            if self.platform_moves:
                P = points_C @ R.T + tr
                cls[(np.abs(P[:, 0]) <= half) & (np.abs(P[:, 1]) <= half) & (P[:, 2] > floor)] = mo.MOVING
            if legs:  # within a leg's radius of its axis (only points as near as the legs reach can be)
                idx = np.flatnonzero(points_C[:, 2] <= legs_reach)
                Q = points_C[idx]
                for a, b, r in legs:
                    ab = b - a
                    s = np.clip((Q - a) @ ab / (ab @ ab), 0.0, 1.0)
                    cls[idx[np.linalg.norm(Q - (a + s[:, None] * ab), axis=1) <= r]] = mo.ATTACHED
            return cls

        return classify

    def _prop_alpha(self, alpha: float) -> np.ndarray | None:
        """``(H, W)`` float32: how much of each pixel's light the spinning propellers take (their
        discs are rigid with the camera: one image per sequence), anti-aliased over a pixel at the
        discs' rims; ``None`` when no disc is in view."""
        T_C_B = invert(self.T_B_C)
        xn, yn = self.rays
        out = np.zeros(xn.shape, np.float32)
        self.prop_depth = np.full(xn.shape, np.inf, np.float32)  # the nearest disc's depth where one is seen
        up_C = T_C_B[:3, 2]  # the discs' normal (body z) in the camera frame
        for centre_B, radius in self.props:
            c = T_C_B[:3, :3] @ centre_B + T_C_B[:3, 3]
            # the ray (xn, yn, 1) * s meets the disc's plane where (ray * s - c) . up = 0
            denom = xn * up_C[0] + yn * up_C[1] + up_C[2]
            with np.errstate(divide="ignore", invalid="ignore"):
                s = (c @ up_C) / denom
            ok = np.isfinite(s) & (s > 1e-3)
            if not ok.any():
                continue
            d = np.sqrt((xn * s - c[0]) ** 2 + (yn * s - c[1]) ** 2 + (s - c[2]) ** 2)
            # a pixel's footprint on the disc's plane (the ray's length over f, over the incidence's
            # cosine), to soften the rim over one pixel
            ray = np.sqrt(xn * xn + yn * yn + 1.0)
            foot = s * ray / (float(min(self.camera.fx, self.camera.fy)) * np.maximum(np.abs(denom) / ray, 0.05))
            cover = np.where(ok, np.clip((radius - d) / np.maximum(foot, 1e-9) + 0.5, 0.0, 1.0), 0.0).astype(np.float32)
            self.prop_depth = np.where(cover > 0, np.minimum(self.prop_depth, s), self.prop_depth).astype(np.float32)
            out = np.maximum(out, cover)
        return (out * np.float32(alpha)) if out.any() else None

    def _airframe_mask(self) -> np.ndarray:
        """``(H, W)`` bool: where the camera sees its own airframe (rigid with it: one per sequence)."""
        self.scene.airframe_only(True)
        try:
            cam2world = self.body2world[0] @ self.T_B_C
            self.scene.set_drone(self.body2world[0])
            _, z = self.scene.render_with_depth(cam2world)
        finally:
            self.scene.airframe_only(False)
        return np.isfinite(self.imaging.depth_to_pixels(z))

    def _occlusion(self, z_render: np.ndarray, cam2pad: np.ndarray):
        """What hides a pad point: the depth test of :func:`depth_occlusion`, at the point's place
        on the wrinkled surface where the pad has relief (its own bulges do not hide it)."""
        occluded = depth_occlusion(self.imaging.render_camera, z_render, cam2pad)
        relief = self.material.get("relief")
        return occluded if relief is None else (lambda pts: occluded(relief.on_surface(pts)))

    def _relief_offset_px(self, cam2pad: np.ndarray) -> float:
        """The largest distance (px, NaN when none is in view) between a labelled feature's image on
        the ideal plane (the outer corners, every marker's corners) and on the wrinkled surface."""
        pts = np.concatenate([self.samples.corners] + [m[:4] for m in self.samples.markers.values()])
        flat = self.camera.project_from(cam2pad, pts)
        real = self.camera.project_from(cam2pad, self.material["relief"].on_surface(pts))
        seen = self.camera.in_image(flat) & self.camera.in_image(real)
        return float(np.max(np.linalg.norm(real[seen] - flat[seen], axis=1))) if seen.any() else float("nan")

    def relief_report(self) -> dict | None:
        """meta.json's ``pad_relief``: the relief drawn, what the labels follow, and how far it moves
        the features' images from them over the sequence (None for a flat pad)."""
        relief = self.material.get("relief")
        if relief is None:
            return None
        d = np.array([v for v in self.relief_px if np.isfinite(v)])
        stats = {"median": float(np.median(d)), "p95": float(np.percentile(d, 95)), "max": float(d.max())} if len(d) \
            else None
        return {"labels": "the pad's ideal plane (z = 0 of the pad frame): the relief is not in the labels",
                **relief.to_dict(), "label_offset_px": stats,
                "label_offset_note": "per frame, the largest image distance of a feature (outer corners, marker "
                                     "corners) on the surface from its label on the plane; over the frames"}

    def _pad_pixels(self, depth: np.ndarray, cam2pad: np.ndarray):
        """``(rows, cols, P, on)``: the window of the image around the pad, its pixels' points in the
        pad frame (from the depth) and which of them lie on the pad; ``None`` when none do."""
        r0, r1, c0, c1 = pad_window(self.camera, cam2pad, self.pad.outer_corners_P)
        xn, yn = self.rays[0][r0:r1, c0:c1], self.rays[1][r0:r1, c0:c1]
        z = depth[r0:r1, c0:c1]
        zc = np.where(np.isfinite(z), z, 0.0).astype(np.float32)
        P = cv2.transform(cv2.merge([xn * zc, yn * zc, zc]), cam2pad[:3, :].astype(np.float32))
        h = self.pad.side_m / 2
        top = self.scene.relief_top_m
        on = (np.abs(P[..., 0]) <= h) & (np.abs(P[..., 1]) <= h) & (P[..., 2] > -0.003) & (P[..., 2] < top + 0.003) & (zc > 0)
        return (slice(r0, r1), slice(c0, c1), P, on) if on.any() else None

    def _pad_cover(self, rows, cols, P: np.ndarray, on: np.ndarray, cam2pad: np.ndarray) -> np.ndarray:
        """``(h, w)`` float32 over the pad's window (:meth:`_pad_pixels`): how much of each pixel the
        pad covers, as the rasteriser's multisampling mixed its colour.

        ``on`` comes from the depth at the pixel's centre, one sample: all or nothing.  Light added
        by it stopped at pixel centres, so the pixels the pad's edge crosses (their colour part
        pad, part what lies beyond) got all of the pad's glare or none of it: a glaring pad had a
        saturated, unlit ring a pixel wide around it, and a sharper edge than its colour's.  There
        the share is the edge's: its distance from where the pixel's ray meets the surface (at the
        relief's height at the edge), over the distance a pixel spans across the edge.  Pixels
        where something stands in front of the pad keep ``on`` (it is that thing's edge)."""
        cover = on.astype(np.float32)
        u8 = on.astype(np.uint8)
        k = np.ones((3, 3), np.uint8)
        r, c = np.nonzero(cv2.dilate(u8, k) != cv2.erode(u8, k))
        top = self.scene.relief_top_m
        keep = P[r, c, 2] < top + 0.003  # on the pad or beyond its edge, not over it
        r, c = r[keep], c[keep]
        if not len(r):
            return cover
        R, C = r + rows.start, c + cols.start
        H, W = on.shape[0] + rows.start, on.shape[1] + cols.start  # (the window's far rows and columns)
        xn, yn = self.rays
        relief = self.material.get("relief")
        h = self.pad.side_m / 2
        Rm, o = cam2pad[:3, :3], cam2pad[:3, 3]

        def outside_m(rr, cc):  # how far outside the pad's edge each pixel's ray meets its surface
            d = np.column_stack([xn[rr, cc], yn[rr, cc], np.ones(len(rr))]) @ Rm.T
            z = np.zeros(len(rr))
            with np.errstate(divide="ignore", invalid="ignore"):
                for _ in range(1 if relief is None else 2):
                    s = (z - o[2]) / d[:, 2]
                    X = o[:2] + s[:, None] * d[:, :2]
                    if relief is not None:
                        z = relief.height(np.nan_to_num(X))
            return np.max(np.abs(X), axis=1) - h, s > 0

        d0, ahead = outside_m(R, C)
        cx = np.where(C + 1 < W, C + 1, C - 1)
        ry = np.where(R + 1 < H, R + 1, R - 1)
        per_px = np.hypot(outside_m(R, cx)[0] - d0, outside_m(ry, C)[0] - d0)
        with np.errstate(divide="ignore", invalid="ignore"):
            share = np.clip(0.5 - d0 / per_px, 0.0, 1.0)
        ok = ahead & np.isfinite(share)
        cover[r[ok], c[ok]] = share[ok]
        return cover

    def _surface_light(self, linear: np.ndarray, depth: np.ndarray, cam2world: np.ndarray, T_W_P: np.ndarray,
                       cam2pad: np.ndarray) -> None:
        """What a flat-shaded render of the ground and the pad leaves out, into ``linear`` in place:
        the ground's fine detail (an albedo factor) and the pad's own light (a factor and the glare
        added), the two factors multiplied in at once (each is 1 where the other is not)."""
        g = self.ground.factor(depth, cam2world, T_W_P) if self.ground is not None else None
        light = self._pad_light(depth, cam2pad)
        rows, cols, f, lobe = light if light is not None else (None, None, None, None)
        if g is not None:
            if f is not None:
                g[rows, cols] *= f
            cv2.multiply(linear, cv2.merge([g, g, g]), dst=linear)
        elif f is not None:
            linear[rows, cols] *= f[..., None]
        if lobe is not None:
            linear[rows, cols] += lobe[..., None]

    def _pad_light(self, depth: np.ndarray, cam2pad: np.ndarray):
        """The light a flat-shaded render leaves out on the pad, in linear light, over the window of
        rows and columns it shows in: a wrinkled pad's facets lit as they face the sun (a factor),
        and the sun's specular glare on a glossy pad (Blinn-Phong, about each facet's normal:
        glints run along the wrinkles; added); both only where the sun reaches the pad (not in the
        drone's shadow or a box's).  ``(rows, cols, factor or None, glare or None)``, or ``None``
        when there is nothing to add."""
        relief, gloss = self.material.get("relief"), self.material["gloss"]
        turns = self.scene.deck_turns  # the pad's frame is turned from the world's: normals, sun, shadows
        tilts = self._deck_tilts       # ... and from the sun: a flat pad's light changes (a yaw alone does not)
        if relief is None and not gloss > 0 and not tilts:
            return None
        got = self._pad_pixels(depth, cam2pad)
        if got is None:
            return None
        rows, cols, P, on = got
        cover = self._pad_cover(rows, cols, P, on, cam2pad)
        # whole-window arrays, multiplied by 1 and added 0 off the pad (boolean gathers and scatters
        # over a pad that fills the view cost more than the light itself)
        vis = None  # the sun's visibility pixel by pixel (a shadow's edge is sharp), once for both
        T_W_P = self._pad2world_now
        R_W_P = T_W_P[:3, :3]
        if self.scene.shadows and self.scene.pad_may_be_shaded(T_W_P[:2, 3], self.pad.side_m / math.sqrt(2.0) + 0.01):
            if turns:  # the drone's shadow lies in the deck's plane: the window's points in the pad's frame
                vis = self.scene.pad_sun_visibility_on_deck(np.ascontiguousarray(P[..., :2]))
            else:  # the window's points in the world (x, y): one OpenCV pass, not numpy's strided copy
                to_world = np.array([[1, 0, 0, T_W_P[0, 3]], [0, 1, 0, T_W_P[1, 3]]], np.float32)
                vis = self.scene.pad_sun_visibility(cv2.transform(P, to_world).reshape(-1, 2))
            vis = vis.reshape(on.shape)
        normals = f = lobe = None
        if relief is not None:
            # the facets' light varies over a wrinkle (>= 3 cm): evaluated on every 4th pixel, interpolated
            normals = relief.normal(P[::4, ::4, :2].reshape(-1, 2).astype(np.float64))
            f = self.scene.relative_light(normals @ R_W_P.T if turns else normals).reshape(P[::4, ::4].shape[:2])
            f = cv2.resize(f.astype(np.float32), (f.shape[1] * 4, f.shape[0] * 4), interpolation=cv2.INTER_LINEAR)
            f = f[:on.shape[0], :on.shape[1]]
        elif tilts:  # a flat pad on a tilted deck: one factor over it
            f = np.full(on.shape, float(self.scene.relative_light(R_W_P[:, 2][None, :])[0]), np.float32)
        if f is not None:
            if vis is not None:
                f = vis * f + (np.float32(1.0) - vis)
            f -= np.float32(1.0)
            f *= cover
            f += np.float32(1.0)
        if gloss > 0:
            # the lobe varies slowly over a flat pad: evaluated on every 8th pixel, interpolated between;
            # on a wrinkled one it follows the facets' normals, on the relief's grid
            step = 8 if normals is None else 4
            Q = P[::step, ::step].reshape(-1, 3).astype(np.float64)
            view = cam2pad[:3, 3][None, :] - Q  # toward the camera, pad frame
            view /= np.maximum(np.linalg.norm(view, axis=1, keepdims=True), 1e-9)
            sun_P = self.plan.scene_draw.sun_dir_W @ R_W_P if turns else self.plan.scene_draw.sun_dir_W
            half_v = view + sun_P[None, :]
            half_v /= np.maximum(np.linalg.norm(half_v, axis=1, keepdims=True), 1e-9)
            cos_nh = half_v[:, 2] if normals is None else np.sum(half_v * normals, axis=1)
            r = max(self.material["gloss_roughness"], 0.02)
            lobe = (np.clip(cos_nh, 0.0, 1.0) ** (2.0 / r**2 - 2.0)).reshape(P[::step, ::step].shape[:2]).astype(np.float32)
            lobe = cv2.resize(lobe, (lobe.shape[1] * step, lobe.shape[0] * step), interpolation=cv2.INTER_LINEAR)
            lobe = lobe[:on.shape[0], :on.shape[1]] * (cover * np.float32(gloss))
            if vis is not None:
                lobe *= vis
        return rows, cols, f, lobe

    def _flows(self, depth, cam2world, cam2pad, T_W_P, t, half: float) -> tuple:
        """``((2, H, W, 2), longest path px)``: every pixel's image motion to ``t - half`` and
        ``t + half`` (the shutter's opening and closing; with a rolling shutter, of the first
        and last rows)."""
        tau = np.array([-half, half])
        B, P = self._poses_at(t + tau)
        motion = mo.relative_motion(cam2world, B @ self.T_B_C, T_W_P, P, tau)
        return self.flow.flows(depth, self._classify(cam2pad), motion)

    def _auto_exposure(self, lag_s) -> np.ndarray:
        """Per-frame multiplier of the exposure gain: 1 without auto exposure; with it, the gain
        that keeps the image's mean brightness where plain ground puts it, followed with a
        first-order lag of ``lag_s``.  The brightness is predicted from the labels (the share of
        the view the pad covers, the pad's and the ground's mean albedo), so every frame's value
        is known before any is rendered."""
        n = len(self.times)
        if lag_s is None:
            return np.ones(n)
        from .textures import GROUND_COLOURS

        ground = float(np.mean((np.asarray(GROUND_COLOURS[self.plan.scene_draw.ground][0], float) / 255.0) ** 2.2))
        pad = float(np.mean(SRGB_TO_LINEAR[self.pad.texture_rgb[::8, ::8]]))
        gy, gx = np.mgrid[0:32, 0:32]
        px = np.column_stack([(gx.ravel() + 0.5) * self.camera.width / 32 - 0.5,
                              (gy.ravel() + 0.5) * self.camera.height / 32 - 0.5])
        rays = np.column_stack([self.camera.normalized_from_pixels(px), np.ones(len(px))])
        h = self.pad.side_m / 2
        share = np.empty(n)
        for k in range(n):
            T = self.cam2pad(k)
            d = rays @ T[:3, :3].T
            with np.errstate(divide="ignore", invalid="ignore"):
                s = -T[2, 3] / d[:, 2]
            hit = T[:3, 3] + s[:, None] * d
            share[k] = np.mean((s > 0) & (np.abs(hit[:, 0]) <= h) & (np.abs(hit[:, 1]) <= h))
        target = ground / (share * pad + (1 - share) * ground)
        a = 1.0 - np.exp(-np.diff(self.times, prepend=self.times[0]) / lag_s)
        gain = np.empty(n)
        gain[0] = target[0]
        for k in range(1, n):
            gain[k] = gain[k - 1] + a[k] * (target[k] - gain[k - 1])
        return gain

    def _subframes(self, t: float, n: int) -> np.ndarray:
        """The reference blur: one render per sample time, averaged in linear light."""
        tau = mo.sample_times(self.exposure, n)
        B, P = self._poses_at(t + tau)
        acc = None
        now = self._pad2world_now
        try:
            for Bi, Pi in zip(B, P):
                self.scene.set_platform(Pi)
                self.scene.set_drone(Bi)
                rgb, z = self.scene.render_with_depth(Bi @ self.T_B_C)
                lin = self.imaging.linear(rgb)
                depth = self.imaging.depth_to_pixels(z)
                self._pad2world_now = Pi  # (the pad's glare and relief: each sample's own)
                self._surface_light(lin, depth, Bi @ self.T_B_C, Pi, invert(Pi) @ Bi @ self.T_B_C)
                acc = lin if acc is None else acc + lin
        finally:
            self._pad2world_now = now
        return acc * np.float32(1.0 / len(B))

    def _labels(self, k: int, t: float, cam2pad, facts: dict, n: int, T_W_B, T_W_P) -> dict:
        px = facts["corners_px"].copy()
        if self.line_s > 0:  # where each corner appears: at the time of the row it lands on
            for _ in range(3):  # (a fixed point: each round shrinks the row's error ~30x on a fast yaw)
                rows = np.clip(np.nan_to_num(px[:, 1], nan=self.ref_row), 0, self.camera.height - 1)
                B, P = self._poses_at(t + (rows - self.ref_row) * self.line_s)
                last, px = px, np.stack([self.camera.project_from(invert(Pi) @ Bi @ self.T_B_C, self.pad.outer_corners_P[i:i + 1])[0]
                                         for i, (Bi, Pi) in enumerate(zip(B, P))])
                if np.nanmax(np.abs(px - last), initial=0.0) < 1e-4:
                    break
        px[~self.camera.in_image(px)] = np.nan
        pose = tum_from_transform(cam2pad)
        if np.allclose(cam2pad, self.cam2pad(k), atol=1e-12):
            pose[3:] = self._quats[k]  # the hemisphere kept from row to row
        blur = 0.0
        if self.blur:  # the image motion over the exposure of the pad in view (none where blur is not rendered)
            B, P = self._poses_at(t + np.array([-self.exposure / 2, self.exposure / 2]))
            ends = [invert(Pi) @ Bi @ self.T_B_C for Bi, Pi in zip(B, P)]
            blur = pad_image_motion_px(self.camera, ends[0], ends[1], self.pad.geometry.half_side_m, (cam2pad,))
        phase = phase_gt(self.camera, cam2pad, self.pad.geometry, self.spec.phase_rule.min_module_px, facts)
        body = tum_from_transform(T_W_B)
        if np.allclose(T_W_B, self.body2world[k], atol=1e-12):
            body[3:] = self._body_quats[k]
        padw = tum_from_transform(T_W_P)
        idx = int(self.plan.frame_index[k])  # the frame's own index (gaps where frames were dropped)
        row = {"frame": idx, "t": t, "image": f"images/{idx:06d}.png",
               **dict(zip(("tx", "ty", "tz", "qx", "qy", "qz", "qw"), pose)), "height_above_pad": pose[2],
               "phase_gt": phase, "pad_fully_visible": facts["pad_fully_visible"],
               "markers_visible": facts["markers_visible"], "module_px": facts["module_px"], "blur_px": blur,
               "blur_subframes": n}
        for i in range(4):
            row[f"c{i}u"], row[f"c{i}v"] = px[i]
        # a rolling shutter can carry a corner seen at the frame time out of the image at its row's
        # time: then it is not in view, whatever the frame-time visibility said
        in_view = np.isfinite(px).all(axis=1)
        for i in range(4):
            row[f"c{i}_visible"] = bool(facts["corner_visible"][i]) and bool(in_view[i])
        if not in_view.all():
            row["pad_fully_visible"] = False
        for name, vis in facts["marker_visible"].items():
            row[f"marker_{name.lower()}_visible"] = vis
        row["pad_visible_fraction"] = facts["pad_visible_fraction"]
        row.update({f"pad2world_{c}": v for c, v in zip(("tx", "ty", "tz", "qx", "qy", "qz", "qw"), padw)})
        row.update({f"body2world_{c}": v for c, v in zip(("tx", "ty", "tz", "qx", "qy", "qz", "qw"), body)})
        row.update({f"body_vel_{c}": v for c, v in zip("xyz", self.body_vel[k])})
        row.update({f"pad_vel_{c}": v for c, v in zip("xyz", self.pad_vel[k])})
        return row

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        self.scene.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False
