"""The landing scene in pyrender (OSMesa): pad on a platform or the ground, procedural ground,
distractors, sun and ambient light, planar shadows (buildings' and the drone's own).

Lighting is Lambertian under one sun and ambient light, computed exactly but cheaply: every
horizontal surface gets the same irradiance, so the scene is rasterised unlit (pyrender's FLAT
mode: texture colours exactly) and the common irradiance is applied in linear light after
rendering (:mod:`render.imaging`).  What differs from it is baked in: box faces carry their
Lambert factor relative to a horizontal surface as vertex colours, and shadows are translucent
black polygons whose opacity turns "sun + ambient" into "ambient only".  This is ~4x faster
than pyrender's per-pixel PBR shading on llvmpipe and has no shadow-map resolution limits.

The one conversion between OpenCV's camera and pyrender's (OpenGL) camera lives here:
:func:`pyrender_camera_pose` and :func:`pyrender_intrinsics`.  Nothing downstream flips an axis.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from hvloc.geometry import Camera, make_transform, rotation_z

from .gl import float_framebuffer, import_pyrender, linear_texture, render_color, render_color_depth, translucent_texture
from .imaging import SRGB_GAMMA
from .textures import GROUND_TILE_M, aruco_image, finder_marker_image, ground_texture

# OpenCV camera axes (x right, y down, z forward) -> OpenGL camera axes (x right, y up, z backward)
CV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])
PAD_THICKNESS_M = 0.002
SHADOW_LIFT_M = 0.001
PLATFORM_SHADOW_M_PER_PX = 0.01  # the platform's shadow's texels on the ground


def pyrender_camera_pose(cam2world_cv: np.ndarray) -> np.ndarray:
    """``T_W_C`` of an OpenCV camera -> the pose pyrender wants for the same camera."""
    return np.asarray(cam2world_cv, np.float64) @ CV_TO_GL


def pyrender_intrinsics(camera: Camera) -> tuple:
    """(fx, fy, cx, cy) for ``pyrender.IntrinsicsCamera``: OpenGL puts pixel centres at +0.5,
    OpenCV at 0, so the principal point moves by half a pixel (the image is read back top-down)."""
    return camera.fx, camera.fy, camera.cx + 0.5, camera.cy + 0.5


@dataclass
class SceneDraw:
    """Everything random about a scene, drawn once per sequence (written into meta.json)."""

    ground: str
    sun_elevation_rad: float
    sun_azimuth_rad: float
    sun_intensity: float
    ambient: float
    boxes: list            # [(x, y, yaw, sx, sy, sz, (r, g, b))]
    decoy_patches: list    # [(x, y, yaw, sx, sy)]
    decoy_markers: list    # [(x, y, yaw, size, kind, id)]

    def to_dict(self) -> dict:
        return {"ground": self.ground, "sun_elevation_deg": math.degrees(self.sun_elevation_rad),
                "sun_azimuth_deg": math.degrees(self.sun_azimuth_rad), "sun_intensity": self.sun_intensity,
                "ambient": self.ambient, "boxes": self.boxes, "decoy_patches": self.decoy_patches,
                "decoy_markers": self.decoy_markers}

    @property
    def sun_dir_W(self) -> np.ndarray:
        """Unit vector pointing from the scene toward the sun."""
        e, a = self.sun_elevation_rad, self.sun_azimuth_rad
        return np.array([math.cos(e) * math.sin(a), math.cos(e) * math.cos(a), math.sin(e)])


PATH_STEP_M = 0.05  # a moving pad's path is checked at points this far apart, and a distractor moved off it in such steps


def _footprint_distance(pts: np.ndarray, x: float, y: float, yaw: float, sx: float, sy: float) -> float:
    """The least distance from the ``(N, 2)`` points to the ``sx`` by ``sy`` footprint centred at
    ``(x, y)`` and turned by ``yaw`` (0 for a point inside it)."""
    c, s = math.cos(yaw), math.sin(yaw)
    d = pts - [x, y]
    local = np.abs(np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1))
    out = np.maximum(local - [sx / 2, sy / 2], 0.0)
    return float(np.hypot(out[:, 0], out[:, 1]).min())


def draw_scene(env, rng: np.random.Generator, view_radius_m: float, pad_path_m=None,
               platform_side_m: float = 0.0) -> SceneDraw:
    """The sequence's ground, sun and distractors.  ``pad_path_m``: where a moving platform takes the
    pad's centre over the sequence (east, north: the end of its straight path from the origin), so
    that no distractor drawn at random lies within ``keep_clear_m`` of it at any time (a box the
    deck drove through, and the pad under it, in the conditions suite's moving_deck); nor within
    the platform's half-diagonal (``platform_side_m``: its side, 0 without a platform), however
    small ``keep_clear_m``: a box drawn into the platform's solid would stand through it, a patch
    or a marker under it.  ``boxes_at`` stay where the spec puts them."""
    u = lambda r: rng.uniform(r[0], r[1]) if r[1] > r[0] else r[0]  # noqa: E731
    ri = lambda r: int(rng.integers(r[0], r[1] + 1))  # noqa: E731
    d = env.distractors
    lo = max(d.keep_clear_m, platform_side_m / math.sqrt(2.0))
    hi = max(lo + 1.0, view_radius_m)

    def place():
        r = math.sqrt(rng.uniform(lo * lo, hi * hi))
        a = rng.uniform(0, 2 * math.pi)
        return r * math.cos(a), r * math.sin(a), rng.uniform(0, math.pi)

    def clear(x, y, yaw, sx, sy):
        """``(x, y)`` moved out along its bearing until no point of the ``sx`` by ``sy`` footprint
        (turned by ``yaw``) lies within ``lo`` of the pad centre: the spec's promise is about the
        distractor, not its centre (a 5 m box drawn 2.5 m away used to cover the pad)."""
        r = math.hypot(x, y)
        if r < 1e-9:
            return x, y
        ux, uy = x / r, y / r
        # the footprint's half-extent toward the pad (its support function along the bearing)
        reach = abs(sx / 2 * (ux * math.cos(yaw) + uy * math.sin(yaw))) + \
            abs(sy / 2 * (-ux * math.sin(yaw) + uy * math.cos(yaw)))
        r2 = max(r, lo + reach)
        return off_path(ux * r2, uy * r2, yaw, sx, sy)

    path = None
    if pad_path_m is not None and np.hypot(*pad_path_m) > 0:
        n = int(math.ceil(float(np.hypot(*pad_path_m)) / PATH_STEP_M)) + 1
        path = np.linspace(0.0, 1.0, n)[:, None] * np.asarray(pad_path_m, np.float64)

    def off_path(x, y, yaw, sx, sy):
        """``(x, y)`` moved straight away from the nearest point of the pad's path until the
        footprint keeps ``lo`` from all of it (as it does from the pad's start)."""
        if path is None:
            return x, y
        for _ in range(100000):
            if _footprint_distance(path, x, y, yaw, sx, sy) >= lo:
                return float(x), float(y)
            near = path[int(np.argmin(np.hypot(path[:, 0] - x, path[:, 1] - y)))]
            away = np.array([x, y]) - near
            if np.hypot(*away) < 1e-9:  # on the path itself: off it sideways
                away = np.array([-pad_path_m[1], pad_path_m[0]], np.float64)
            away = away / np.hypot(*away)
            x, y = x + PATH_STEP_M * away[0], y + PATH_STEP_M * away[1]
        return x, y

    boxes = []
    for b in d.boxes_at:
        boxes.append((float(b.xy_m[0]), float(b.xy_m[1]), math.radians(b.yaw_deg), *map(float, b.size_m),
                      (120, 120, 125)))
    for _ in range(ri(d.boxes)):
        x, y, yaw = place()
        sx, sy, sz = rng.uniform(1.0, 6.0), rng.uniform(1.0, 6.0), rng.uniform(0.4, 6.0)
        col = tuple(int(c) for c in rng.choice([(150, 60, 50), (120, 120, 125), (200, 195, 185), (90, 80, 70),
                                                (60, 90, 140)]))
        boxes.append((*clear(x, y, yaw, sx, sy), yaw, sx, sy, sz, col))
    patches = []
    for _ in range(ri(d.decoy_patches)):
        x, y, yaw = place()
        sx, sy = rng.uniform(0.3, 1.2), rng.uniform(0.3, 1.2)
        patches.append((*clear(x, y, yaw, sx, sy), yaw, sx, sy))
    markers = []
    for i in range(ri(d.decoy_markers)):
        x, y, yaw = place()
        size = rng.uniform(0.15, 0.6)
        markers.append((*clear(x, y, yaw, size, size), yaw, size, "finder" if i % 2 == 0 else "aruco",
                        int(rng.integers(10, 50))))
    return SceneDraw(str(rng.choice(env.ground)), math.radians(u(env.sun_elevation_deg)),
                     math.radians(u(env.sun_azimuth_deg)), u(env.sun_intensity), u(env.ambient),
                     boxes, patches, markers)


def _sample_at(img: np.ndarray, u: np.ndarray, v: np.ndarray, row: int = 4096) -> np.ndarray:
    """``img`` bilinearly at the ``(N,)`` pixel positions ``u, v`` (0 outside).  The points are laid
    out in rows of ``row``: ``cv2.remap``'s maps may not be 32767 or more wide, and a pad near the
    camera covers more pixels than that."""
    n = len(u)
    rows = max(1, -(-n // row))
    pad = rows * row - n
    U = np.append(np.asarray(u, np.float32), np.full(pad, -1.0, np.float32)).reshape(rows, row)
    V = np.append(np.asarray(v, np.float32), np.full(pad, -1.0, np.float32)).reshape(rows, row)
    out = cv2.remap(img, U, V, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return out.reshape(-1)[:n]


class LandingScene:
    """A pyrender scene plus an offscreen renderer for one camera size.

    ``render(cam2world)`` returns an ``(H, W, 3)`` uint8 RGB image in OpenCV's pixel convention.
    """

    DRONE_TOP_TEXELS = 64  # the alpha texels a side of the drone's shadow where a platform's edge cuts it

    def __init__(self, pad, draw: SceneDraw, platform_height: float, platform_size: float,
                 camera: Camera, border_rgb, rng: np.random.Generator, shadows: bool = True,
                 znear: float = 0.05, ground_extent_m: float = 120.0, drone_size_m: float = 0.45,
                 pad_texture: np.ndarray | None = None, legs: list | None = None, pad_relief=None,
                 deck_drop_m: float = 0.0, deck_turns: bool = False, light: bool = False):
        """``pad_texture``: what the pad looks like here (default: its design); ``legs``: the
        airframe's legs as ``(bottom xyz, top xyz, diameter, sRGB)`` in the body frame;
        ``pad_relief``: the printed pad's departure from flat (:class:`render.relief.PadRelief`);
        ``deck_drop_m``: how far a heaving, rolling deck may take its platform's top below its mean
        height (its box reaches as far below the ground, so that it never lifts off); ``deck_turns``:
        whether the deck rolls, pitches or yaws (the pad's light and the drone's shadow on it are
        then worked out in the pad's frame); ``light``: everything mixed in linear light (float
        textures and framebuffer: ``camera.mix_in_light``), ``render`` then gives float32 light."""
        pr = import_pyrender()
        self.pr = pr
        self.camera = camera
        self.draw = draw
        self.shadows = shadows
        self.platform_height = platform_height
        self.platform_size = platform_size
        self.pad_surface_z = platform_height + PAD_THICKNESS_M
        self.pad_relief = pad_relief
        # shadows are drawn as layers just above what they fall on: above the relief's highest point
        self.relief_top_m = float(pad_relief.amplitude_m) if pad_relief is not None else 0.0
        amb = draw.ambient
        self.light = bool(light)
        # colours as the scene holds them: display values, or light (the same colour, decoded)
        held = (lambda c: np.asarray(c, np.float64) ** SRGB_GAMMA) if self.light else (lambda c: np.asarray(c, np.float64))
        scene = pr.Scene(bg_color=[*held([0.6, 0.7, 0.85]), 1.0], ambient_light=[1.0, 1.0, 1.0])
        self.scene = scene
        self._count = 0
        from OpenGL.GL import GL_LINEAR, GL_LINEAR_MIPMAP_LINEAR, GL_REPEAT, GL_CLAMP_TO_EDGE

        def textured_quad(img, sx, sy, uv_repeat=1.0, repeat=False, soft_edge_px=0, relief=None):
            """A flat quad.  ``soft_edge_px``: surround the texture with that many transparent
            texels (edge colour replicated) and alpha-blend it, so the quad's outline is filtered
            like any texture edge (sub-pixel exact) instead of being a hard, aliased polygon edge.
            ``relief``: a height field (:class:`render.relief.PadRelief`) the quad follows, as a grid
            fine enough for its shortest wrinkle."""
            sampler = pr.Sampler(magFilter=GL_LINEAR, minFilter=GL_LINEAR_MIPMAP_LINEAR,
                                 wrapS=GL_REPEAT if repeat else GL_CLAMP_TO_EDGE,
                                 wrapT=GL_REPEAT if repeat else GL_CLAMP_TO_EDGE)
            # RGBA rows are always 4-byte aligned: RGB rows of odd widths would be skewed by
            # OpenGL's default unpack alignment
            rgba = np.concatenate([img, np.full(img.shape[:2] + (1,), 255, np.uint8)], axis=2)
            if soft_edge_px:
                m = int(soft_edge_px)
                sx *= (img.shape[1] + 2 * m) / img.shape[1]
                sy *= (img.shape[0] + 2 * m) / img.shape[0]
                rgba = cv2.copyMakeBorder(rgba, m, m, m, m, cv2.BORDER_REPLICATE)
                rgba[:m, :, 3] = rgba[-m:, :, 3] = 0
                rgba[:, :m, 3] = rgba[:, -m:, 3] = 0
            if self.light:
                lin = rgba.astype(np.float32) * np.float32(1 / 255)
                lin[..., :3] = held(lin[..., :3])
                tex = linear_texture(pr, lin, sampler)
            else:
                tex = pr.Texture(source=np.ascontiguousarray(rgba), source_channels="RGBA", sampler=sampler)
            if soft_edge_px:
                translucent_texture(tex)
            mat = pr.MetallicRoughnessMaterial(baseColorTexture=tex, metallicFactor=0.0, roughnessFactor=1.0,
                                               alphaMode="BLEND" if soft_edge_px else "OPAQUE")
            hx, hy = sx / 2, sy / 2
            n = 2 if relief is None else int(np.ceil(max(sx, sy) / max(relief.shortest_m / 8, 1e-3))) + 1
            u, v = np.meshgrid(np.linspace(0.0, 1.0, n), np.linspace(0.0, 1.0, n))
            xy = np.column_stack([(u.ravel() - 0.5) * sx, (v.ravel() - 0.5) * sy])
            z = np.zeros(len(xy)) if relief is None else relief.height(xy)
            pos = np.column_stack([xy, z]).astype(np.float32)
            # pyrender flips the image on upload, so v = 1 is its top row (pad +y)
            uv = (np.column_stack([u.ravel(), v.ravel()]) * uv_repeat).astype(np.float32)
            normals = (np.tile([[0.0, 0.0, 1.0]], (len(xy), 1)) if relief is None else relief.normal(xy)).astype(np.float32)
            i = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]).ravel()
            tris = np.concatenate([np.column_stack([i, i + 1, i + n + 1]), np.column_stack([i, i + n + 1, i + n])])
            prim = pr.Primitive(positions=pos, normals=normals, texcoord_0=uv, indices=tris.astype(np.uint32),
                                material=mat)
            return pr.Mesh([prim])

        def flat_quad(rgb, sx, sy, alpha=1.0):
            mat = pr.MetallicRoughnessMaterial(baseColorFactor=[*held(np.asarray(rgb) / 255.0), alpha], metallicFactor=0.0,
                                               roughnessFactor=1.0, alphaMode="BLEND" if alpha < 1 else "OPAQUE")
            hx, hy = sx / 2, sy / 2
            pos = np.array([[-hx, -hy, 0], [hx, -hy, 0], [hx, hy, 0], [-hx, hy, 0]], np.float32)
            normals = np.tile(np.array([[0, 0, 1]], np.float32), (4, 1))
            return pr.Mesh([pr.Primitive(positions=pos, normals=normals,
                                         indices=np.array([[0, 1, 2], [0, 2, 3]], np.uint32), material=mat)])

        sun = draw.sun_dir_W
        direct = draw.sun_intensity
        horizontal = amb + direct * max(sun[2], 0.0)

        def box(size, rgb, yaw=0.0):
            import trimesh

            m = trimesh.creation.box(size)
            n_W = m.face_normals @ rotation_z(yaw).T
            rel = (amb + direct * np.clip(n_W @ sun, 0.0, None)) / horizontal
            lin = (np.asarray(rgb, float)[None, :] / 255.0) ** SRGB_GAMMA * rel[:, None]
            held_c = np.clip(lin, 0, 1) ** (1.0 if self.light else 1 / SRGB_GAMMA) * 255
            m.visual.face_colors = np.column_stack([held_c, np.full(len(held_c), 255)]).astype(np.uint8)
            return pr.Mesh.from_trimesh(m, smooth=False)

        def pose_xy(x, y, z, yaw=0.0):
            return make_transform(rotation_z(yaw), (x, y, z))

        # ground: a large plane, its texture repeated every GROUND_TILE_M
        tile = GROUND_TILE_M
        self._add(textured_quad(ground_texture(draw.ground, rng), ground_extent_m, ground_extent_m,
                                uv_repeat=ground_extent_m / tile, repeat=True), pose=np.eye(4))
        # the platform and everything on it move together: children of one node (set_platform)
        self.platform_node = pr.Node(name="platform", matrix=np.eye(4))
        scene.add_node(self.platform_node)
        self.has_platform_box = platform_height > 0 and platform_size > 0
        self.deck_turns = bool(deck_turns)
        if self.has_platform_box:
            tall = platform_height + deck_drop_m
            self._add(box((platform_size, platform_size, tall), (110, 112, 118)),
                      pose=pose_xy(0, 0, platform_height - tall / 2), parent=self.platform_node)
        # the pad's outline is a labelled feature: soft (texture-filtered) edges, not aliased ones
        tex = pad.texture_rgb if pad_texture is None else pad_texture
        self.pad_node = self._add(textured_quad(tex, pad.side_m, pad.side_m, soft_edge_px=16, relief=pad_relief),
                                  pose=pose_xy(0, 0, self.pad_surface_z), parent=self.platform_node)
        for x, y, yaw, sx, sy, sz, col in draw.boxes:
            self._add(box((sx, sy, sz), col, yaw), pose=pose_xy(x, y, sz / 2, yaw))
        for x, y, yaw, sx, sy in draw.decoy_patches:
            self._add(flat_quad(border_rgb, sx, sy), pose=pose_xy(x, y, 0.003, yaw))
        for x, y, yaw, size, kind, mid in draw.decoy_markers:
            img = finder_marker_image() if kind == "finder" else aruco_image(mid)
            self._add(textured_quad(img, size, size), pose=pose_xy(x, y, 0.003, yaw))

        # what the sun adds to a horizontal surface, relative to ambient alone (applied in imaging)
        self.irradiance = horizontal
        self._amb, self._direct = amb, direct
        # planar shadows: what the sun does not reach gets only ambient light (alpha in sRGB)
        k = amb / horizontal
        # (a shadow layer blends black over what it covers: in light by 1 - k, in display values so that
        # the display value falls as light by k would)
        self.shadow_alpha = float(np.clip(1 - k ** (1.0 if self.light else 1 / SRGB_GAMMA), 0.0, 0.95)) if shadows else 0.0
        self._shade = lambda sx, sy: flat_quad((0, 0, 0), sx, sy, self.shadow_alpha)
        # the layer that shadows on the ground lie in: above the pad when the pad lies on the ground
        # (a shadow in the pad's own plane z-fights with it: the depth test then draws it in stripes)
        self.ground_shadow_z = SHADOW_LIFT_M + (0.0 if self.has_platform_box else self.pad_surface_z + self.relief_top_m)
        self._ground_shadow_maps = []
        self.platform_xy = np.zeros(2)
        self.pad2world = make_transform(np.eye(3), (0.0, 0.0, self.pad_surface_z))
        if shadows and self.shadow_alpha > 0 and draw.boxes:
            self._add_box_shadows(draw.boxes)
        # the platform's shadow lies on the ground: it follows the platform's position, and where the
        # deck turns, its shape is cast again from the box as it stands (set_platform)
        self.platform_shadow_node = pr.Node(name="platform_shadow", matrix=np.eye(4))
        scene.add_node(self.platform_shadow_node)
        self._deck_drop_m = float(deck_drop_m)
        self._platform_shadow = None  # (its node, its index in _ground_shadow_maps)
        if shadows and self.shadow_alpha > 0 and self.has_platform_box:  # moves with the platform
            self._platform_shadow = self._add_shadow_map(
                [self._platform_shadow_polygon(make_transform(np.eye(3), (0.0, 0.0, self.pad_surface_z)))],
                parent=self.platform_shadow_node, m_per_px=PLATFORM_SHADOW_M_PER_PX)
        # the drone's own legs: children of the body node (set_drone moves them)
        self.body_node = pr.Node(name="body", matrix=np.eye(4))
        scene.add_node(self.body_node)
        self.airframe_nodes = []
        for bottom, top, diameter, rgb in legs or []:
            import trimesh

            seg = np.array([bottom, top], float)
            m = trimesh.creation.cylinder(radius=diameter / 2, segment=seg, sections=16)
            m.visual.face_colors = np.array([*(np.round(held(np.asarray(rgb) / 255.0) * 255) if self.light else rgb), 255],
                                            np.uint8)
            self.airframe_nodes.append(self._add(pr.Mesh.from_trimesh(m, smooth=False), np.eye(4), "airframe",
                                                 parent=self.body_node))
        self.drone_size = drone_size_m
        self.drone_shadow = None
        self.drone_parts = []  # the drone's shadow where other shadows or the platform's edge cut it (set_drone)
        self._drone_shadow_at = None  # (xy, yaw) of the drone's shadow square as last placed (world)
        self._drone_shadow_on_pad = None  # the same in the pad's frame, where it lies on a tilting deck
        if shadows and self.shadow_alpha > 0:
            self.drone_shadow = self._add(self._shade(drone_size_m, drone_size_m), pose_xy(0, 0, -100), "shadow_drone")

        fx, fy, cx, cy = pyrender_intrinsics(camera)
        self.znear, self.zfar = float(znear), 2000.0
        self.cam_node = scene.add(pr.IntrinsicsCamera(fx=fx, fy=fy, cx=cx, cy=cy, znear=self.znear, zfar=self.zfar),
                                  pose=np.eye(4))
        self.renderer = pr.OffscreenRenderer(camera.width, camera.height)
        if self.light:
            try:
                float_framebuffer(self.renderer)
            except Exception:
                self.close()
                raise

    def _add(self, mesh, pose=None, name: str = "mesh", parent=None):
        """Add a mesh node with a unique, ordered name (draw order is deterministic)."""
        self._count += 1
        return self.scene.add(mesh, pose=np.eye(4) if pose is None else pose, name=f"{name}_{self._count:04d}",
                              parent_node=parent)

    def _add_box_shadows(self, boxes, m_per_px: float = 0.02, parent=None):
        """All boxes' shadows on the ground as one alpha texture: the union of each box's corners
        cast along the sun (overlapping shadows darken once, and the draw order cannot matter)."""
        shift = self._sun_shift()
        polys = []
        for x, y, yaw, sx, sy, sz, _ in boxes:
            c, sn = math.cos(yaw), math.sin(yaw)
            pts = []
            for dx in (-sx / 2, sx / 2):
                for dy in (-sy / 2, sy / 2):
                    bx, by = x + c * dx - sn * dy, y + sn * dx + c * dy
                    pts += [(bx, by), (bx + shift[0] * sz, by + shift[1] * sz)]
            polys.append(cv2.convexHull(np.array(pts, np.float32))[:, 0, :].astype(np.float64))
        self._add_shadow_map(polys, m_per_px, parent)

    def _sun_shift(self) -> np.ndarray:
        """How far (x, y) a point's shadow on the ground lies from it per metre of its height (the sun
        held at least a little above the horizon)."""
        s = self.draw.sun_dir_W
        return -s[:2] / max(s[2], 0.05)

    def _platform_shadow_polygon(self, pad2world: np.ndarray) -> np.ndarray:
        """``(M, 2)``: the platform's shadow on the ground, about the platform's centre (x, y): the
        part of its box above the ground (its top's corners and where its sides meet the ground, a
        box that reaches below the ground by the deck's travel), cast along the sun.  A level box's
        is its footprint and its top cast."""
        shift = self._sun_shift()
        node = np.asarray(pad2world, np.float64) @ make_transform(np.eye(3), (0.0, 0.0, -self.pad_surface_z))
        half, top, bottom = self.platform_size / 2, self.platform_height, -self._deck_drop_m
        pts = []
        for dx in (-half, half):
            for dy in (-half, half):
                a = node[:3, :3] @ np.array([dx, dy, top]) + node[:3, 3]
                b = node[:3, :3] @ np.array([dx, dy, bottom]) + node[:3, 3]
                g = b + (a - b) * (-b[2] / (a[2] - b[2])) if b[2] < 0.0 < a[2] else b
                pts += [g[:2] + shift * g[2], a[:2] + shift * a[2]]
        pts = np.array(pts) - np.asarray(pad2world, np.float64)[:2, 3]  # (the shadow's node is at the pad's centre)
        return cv2.convexHull(pts.astype(np.float32))[:, 0, :].astype(np.float64)

    def _add_shadow_map(self, polys, m_per_px: float, parent=None, index: int | None = None) -> tuple:
        """Shadow polygons on the ground (in the frame of ``parent``, else the world's) as one alpha
        texture; ``(its node, its index in _ground_shadow_maps)`` (``index``: the map it replaces)."""
        allp = np.concatenate(polys)
        lo, hi = allp.min(axis=0) - 0.1, allp.max(axis=0) + 0.1
        w, h = (np.ceil((hi - lo) / m_per_px)).astype(int) + 1
        alpha = np.zeros((h, w), np.uint8)
        for p in polys:
            px = np.column_stack([(p[:, 0] - lo[0]) / m_per_px, (hi[1] - p[:, 1]) / m_per_px])
            cv2.fillPoly(alpha, [np.round(px * 16).astype(np.int32)], 255, cv2.LINE_AA, shift=4)
        # the map, kept to tell where the ground is already in shadow (the drone's shadow must not
        # darken it twice), in the frame of its parent (the platform's moves with it)
        entry = (alpha.astype(np.float32) / 255.0, lo, hi, m_per_px, parent is not None)
        if index is None:
            self._ground_shadow_maps.append(entry)
            index = len(self._ground_shadow_maps) - 1
        else:
            self._ground_shadow_maps[index] = entry
        sx, sy = w * m_per_px, h * m_per_px
        mesh = self._shadow_mesh((alpha.astype(np.float32) * self.shadow_alpha).astype(np.uint8), sx, sy, (0.0, 0.0))
        node = self._add(mesh, make_transform(np.eye(3), (lo[0], hi[1] - sy, self.ground_shadow_z)), "shadow_boxes",
                         parent=parent)
        return node, index

    def _shadow_mesh(self, alpha: np.ndarray, sx: float, sy: float, origin: tuple):
        """A flat translucent black quad ``sx`` x ``sy`` m whose corner ``(0, 0)`` of the texture (its
        top-left row) lies at ``origin + (0, sy)``; ``alpha`` (h, w) uint8, row 0 at the far +y edge."""
        pr = self.pr
        from OpenGL.GL import GL_CLAMP_TO_EDGE, GL_LINEAR, GL_LINEAR_MIPMAP_LINEAR

        rgba = np.zeros(alpha.shape + (4,), np.uint8)
        rgba[..., 3] = alpha
        tex = translucent_texture(pr.Texture(source=rgba, source_channels="RGBA",
                                             sampler=pr.Sampler(magFilter=GL_LINEAR, minFilter=GL_LINEAR_MIPMAP_LINEAR,
                                                                wrapS=GL_CLAMP_TO_EDGE, wrapT=GL_CLAMP_TO_EDGE)))
        mat = pr.MetallicRoughnessMaterial(baseColorTexture=tex, metallicFactor=0.0, roughnessFactor=1.0,
                                           alphaMode="BLEND")
        x0, y0 = origin
        pos = np.array([[x0, y0, 0], [x0 + sx, y0, 0], [x0 + sx, y0 + sy, 0], [x0, y0 + sy, 0]], np.float32)
        uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
        normals = np.tile(np.array([[0, 0, 1]], np.float32), (4, 1))
        prim = pr.Primitive(positions=pos, normals=normals, texcoord_0=uv, material=mat,
                            indices=np.array([[0, 1, 2], [0, 2, 3]], np.uint32))
        return pr.Mesh([prim])

    def relative_light(self, normals_W: np.ndarray) -> np.ndarray:
        """``(N,)`` the light a sunlit facet of normal ``normals_W`` gets, relative to a horizontal one
        (what the renders are normalised to), as the boxes' faces are shaded."""
        return (self._amb + self._direct * np.clip(np.asarray(normals_W) @ self.draw.sun_dir_W, 0.0, None)) / self.irradiance

    def pad_sun_visibility(self, xy_W: np.ndarray) -> np.ndarray:
        """``(N,)`` how much of the sun reaches points of the pad's surface (1 lit, 0 in a shadow):
        the drone's shadow as last placed, and the boxes' where the pad lies on the ground (on a
        platform their shadows stay on the ground).  What the sun's glare on the pad is weighted by.
        Computed in float32 when ``xy_W`` is (a pad filling the view is most of the frame's pixels;
        a few micrometres are nothing to a shadow's edge), else in float64."""
        xy_W = np.asarray(xy_W)
        xy_W = xy_W.astype(np.float64 if xy_W.dtype != np.float32 else np.float32, copy=False).reshape(-1, 2)
        ftype = xy_W.dtype.type
        shade = np.zeros(len(xy_W), xy_W.dtype)
        if not self.has_platform_box and self._ground_shadow_maps:
            shade = self._ground_shadow_cover(xy_W)
        if self._drone_shadow_at is not None:
            shade[self._in_drone_shadow(xy_W, *self._drone_shadow_at)] = 1.0
        return ftype(1.0) - shade

    def _in_drone_shadow(self, xy: np.ndarray, centre, yaw: float) -> np.ndarray:
        """``(N,)`` bool: which points ``xy`` (N, 2) lie in the drone's shadow square at ``centre``,
        turned by ``yaw`` (in the points' frame)."""
        (cx, cy), c, sn = centre, math.cos(yaw), math.sin(yaw)
        to_square = np.array([[c, sn, -(c * cx + sn * cy)], [-sn, c, sn * cx - c * cy]], xy.dtype)
        h = self.drone_size / 2
        return cv2.inRange(cv2.transform(xy.reshape(-1, 1, 2), to_square), (-h, -h), (h, h)).reshape(-1) > 0

    def pad_sun_visibility_on_deck(self, xy_P: np.ndarray) -> np.ndarray:
        """:meth:`pad_sun_visibility` for a tilting deck's pad, at points ``xy_P`` of the pad's frame
        (N, 2): only the drone's shadow can reach it there (a platform's pad is above the boxes')."""
        xy_P = np.asarray(xy_P).reshape(-1, 2)
        vis = np.ones(len(xy_P), xy_P.dtype)
        if self._drone_shadow_on_pad is not None:
            vis[self._in_drone_shadow(xy_P, *self._drone_shadow_on_pad)] = 0.0
        return vis

    def pad_may_be_shaded(self, centre_xy_W, radius_m: float) -> bool:
        """Whether any shadow that :meth:`pad_sun_visibility` counts can reach within ``radius_m``
        of ``centre_xy_W`` (world): ``False`` means it is 1 at every point there."""
        c = np.asarray(centre_xy_W, np.float64)[:2]
        if self._drone_shadow_on_pad is not None:  # on a tilting deck: in the pad's frame, about its centre
            if np.hypot(*self._drone_shadow_on_pad[0]) <= radius_m + self.drone_size / math.sqrt(2.0):
                return True
        if self._drone_shadow_at is not None:
            if np.hypot(*(self._drone_shadow_at[0] - c)) <= radius_m + self.drone_size / math.sqrt(2.0):
                return True
        if self.has_platform_box:
            return False
        for alpha, lo, hi, m_per_px, on_platform in self._ground_shadow_maps:
            q = c - (self.platform_xy if on_platform else 0.0)
            # the map's texels around the disc's box, a texel more each way (samples are bilinear)
            c0, c1 = (np.array([q[0] - radius_m, q[0] + radius_m]) - lo[0]) / m_per_px + [-1, 2]
            r0, r1 = (hi[1] - np.array([q[1] + radius_m, q[1] - radius_m])) / m_per_px + [-1, 2]
            r0, r1 = max(int(r0), 0), min(int(r1), alpha.shape[0])
            c0, c1 = max(int(c0), 0), min(int(c1), alpha.shape[1])
            if r1 > r0 and c1 > c0 and alpha[r0:r1, c0:c1].max() > 0:
                return True
        return False

    def _ground_shadow_cover(self, xy_W: np.ndarray) -> np.ndarray:
        """``(N,)`` how much of the sun the boxes' and the platform's shadows already take at ground
        points (0 lit, 1 in full shadow; anti-aliased edges between)."""
        cover = np.zeros(len(xy_W), xy_W.dtype)
        for alpha, lo, hi, m_per_px, on_platform in self._ground_shadow_maps:
            xy = xy_W - (self.platform_xy.astype(xy_W.dtype) if on_platform else 0.0)
            u = ((xy[:, 0] - xy_W.dtype.type(lo[0])) / xy_W.dtype.type(m_per_px)).astype(np.float32)
            v = ((xy_W.dtype.type(hi[1]) - xy[:, 1]) / xy_W.dtype.type(m_per_px)).astype(np.float32)
            cover = np.maximum(cover, _sample_at(alpha, u, v))
        return cover

    def set_platform(self, pad2world: np.ndarray) -> None:
        """Move the platform and the pad to ``T_W_P`` (a deck's heave, roll and pitch turn them about
        the pad's centre), and the platform's shadow to its horizontal position."""
        T = np.asarray(pad2world, np.float64)
        self.pad2world = T.copy()
        self.platform_xy = T[:2, 3].copy()
        self.scene.set_pose(self.platform_node, T @ make_transform(np.eye(3), (0.0, 0.0, -self.pad_surface_z)))
        self.scene.set_pose(self.platform_shadow_node, make_transform(np.eye(3), (*self.platform_xy, 0.0)))
        if self.deck_turns and self._platform_shadow is not None:
            node, i = self._platform_shadow
            self.scene.remove_node(node)
            self._platform_shadow = self._add_shadow_map([self._platform_shadow_polygon(T)], PLATFORM_SHADOW_M_PER_PX,
                                                         parent=self.platform_shadow_node, index=i)

    def set_drone(self, body2world: np.ndarray) -> None:
        """Move the drone: its legs, and its shadow (a flat square cast along the sun onto the
        surface below: a platform's top where the square meets it, the ground beyond the top's edge)."""
        self.scene.set_pose(self.body_node, np.asarray(body2world, np.float64))
        if self.drone_shadow is None:
            return
        s = self.draw.sun_dir_W
        p = body2world[:3, 3]
        yaw = math.atan2(body2world[1, 0], body2world[0, 0])
        self._drone_shadow_on_pad = None
        for node in self.drone_parts:
            self.scene.remove_node(node)
        self.drone_parts = []
        top = self._drone_shadow_on_top(p, yaw, s)
        if top == "whole":
            return
        # the ground: where the platform's top took the rest, the platform's own shadow lies (the
        # cover below leaves it out)
        k = p[2] / max(s[2], 0.05)
        xy = p[:2] - s[:2] * k
        # one layer above the others (a translucent layer in another's plane z-fights with it too)
        pose = make_transform(rotation_z(yaw), (xy[0], xy[1], self.ground_shadow_z + SHADOW_LIFT_M))
        if not top:
            self._drone_shadow_at = (np.array(xy, np.float64), yaw)
        # on the ground, where a box's or the platform's shadow already lies, the sun is already gone:
        # there the drone's shadow takes nothing more (two translucent layers used to darken twice)
        cover = None
        if self._ground_shadow_maps:
            n = 24
            cover = self._ground_shadow_cover(self._square_points(xy, yaw, n)).reshape(n, n)
        if cover is None or cover.max() <= 0.0:
            self.scene.set_pose(self.drone_shadow, pose)
            return
        if not top:
            self.scene.set_pose(self.drone_shadow, make_transform(np.eye(3), (0.0, 0.0, -100.0)))  # out of sight
        self._masked_drone_shadow(1.0 - cover, pose)

    def _square_points(self, centre, yaw: float, n: int) -> np.ndarray:
        """``(n * n, 2)``: the centres of an n x n grid over the drone's shadow square at ``centre``
        turned by ``yaw``, row 0 at its far +y edge (as :meth:`_shadow_mesh` lays a texture)."""
        h = self.drone_size / 2
        g = (np.arange(n) + 0.5) / n * 2 * h - h
        gx, gy = np.meshgrid(g, g[::-1])
        c, sn = math.cos(yaw), math.sin(yaw)
        return np.column_stack([centre[0] + c * gx.ravel() - sn * gy.ravel(), centre[1] + sn * gx.ravel() + c * gy.ravel()])

    def _masked_drone_shadow(self, alpha01: np.ndarray, pose: np.ndarray) -> None:
        """A part of the drone's shadow square at ``pose``: its texels' share of the shadow ``alpha01``
        (n, n), row 0 at the square's far +y edge."""
        h = self.drone_size / 2
        alpha = np.round(self.shadow_alpha * alpha01 * 255).astype(np.uint8)
        self.drone_parts.append(self._add(self._shadow_mesh(alpha, 2 * h, 2 * h, (-h, -h)), pose, "shadow_dronemasked"))

    def _drone_shadow_on_top(self, p_W: np.ndarray, yaw: float, sun_W: np.ndarray) -> str:
        """Lay the drone's shadow (from its centre ``p_W``) on the platform's top, in the deck's plane
        where it is now, as far as it falls there: ``"whole"``, ``"part"`` (the part on the top laid;
        the rest falls past its edge, to the ground) or ``""`` (none).  (The whole square used to be laid
        on the top when its centre fell there, hanging in the air past the edge, and none of it when
        the centre fell beyond.)"""
        if not self.has_platform_box:
            return ""
        T = self.pad2world
        if self.deck_turns:  # in the pad's frame, about its centre
            R, o = T[:3, :3], T[:3, 3]
            p, s = R.T @ (p_W - o), R.T @ sun_W
            xy = p[:2] - s[:2] * (p[2] / max(s[2], 0.05))
            yaw_top = yaw - math.atan2(R[1, 0], R[0, 0])
            rel = xy
            pose = T @ make_transform(rotation_z(yaw_top), (xy[0], xy[1], self.relief_top_m + SHADOW_LIFT_M))
        else:
            surface = float(T[2, 3])
            xy = p_W[:2] - sun_W[:2] * ((p_W[2] - surface) / max(sun_W[2], 0.05))
            yaw_top = yaw
            rel = xy - self.platform_xy
            pose = make_transform(rotation_z(yaw), (xy[0], xy[1], surface + self.relief_top_m + SHADOW_LIFT_M))
        half = self.platform_size / 2
        h = self.drone_size / 2
        c, sn = math.cos(yaw_top), math.sin(yaw_top)
        corners = rel + np.array([[-h, -h], [h, -h], [h, h], [-h, h]]) @ np.array([[c, sn], [-sn, c]])
        whole = bool(np.abs(corners).max() <= half)
        if not whole:
            n = self.DRONE_TOP_TEXELS
            on = (np.abs(self._square_points(rel, yaw_top, n)) <= half).all(axis=1)
            if not on.any():
                return ""
        if self.deck_turns:
            self._drone_shadow_on_pad, self._drone_shadow_at = (np.array(xy, np.float64), yaw_top), None
        else:
            self._drone_shadow_at = (np.array(xy, np.float64), yaw)
        if whole:
            self.scene.set_pose(self.drone_shadow, pose)
            return "whole"
        self.scene.set_pose(self.drone_shadow, make_transform(np.eye(3), (0.0, 0.0, -100.0)))  # out of sight
        self._masked_drone_shadow(on.reshape(n, n).astype(np.float64), pose)
        return "part"

    def render(self, cam2world: np.ndarray) -> np.ndarray:
        """``(H, W, 3)`` uint8 RGB of the render camera at ``cam2world`` (OpenCV camera, ``T_W_C``), or
        float32 light where the scene mixes light (:func:`render.imaging.display_bytes` writes it)."""
        self.scene.set_pose(self.cam_node, pyrender_camera_pose(cam2world))
        return render_color(self.renderer, self.scene, self.pr.RenderFlags.FLAT)

    def airframe_only(self, only: bool) -> None:
        """Hide everything but the airframe (``True``), or show everything again."""
        for node in self.scene.mesh_nodes:
            node.mesh.is_visible = (not only) or node in self.airframe_nodes

    def render_with_depth(self, cam2world: np.ndarray) -> tuple:
        """``(rgb (H, W, 3) uint8, or float32 light where the scene mixes light, z (H, W) float32)``:
        colour and depth along the optical axis in metres (``inf`` where nothing), at the render
        camera's pixels."""
        self.scene.set_pose(self.cam_node, pyrender_camera_pose(cam2world))
        return render_color_depth(self.renderer, self.scene, self.pr.RenderFlags.FLAT, self.znear, self.zfar)

    def close(self) -> None:
        if self.renderer is not None:
            self.renderer.delete()
            self.renderer = None
