"""Ground with detail at every height: a multi-octave albedo modulation in world coordinates.

The rasterised ground texture (a 32 m tile at 15.6 mm per texel, mipmapped) is right from 20 m
down to a few metres;
below that real ground keeps showing finer structure (blades, stones, cracks) while a texture
only blurs.  So every pixel that sees the ground gets its albedo multiplied by
``exp(sum_o w_o * a_o * tile(R_o (x, y) / lambda_o + offset_o))``: the same kind-specific,
tileable detail tile at several scales ``lambda_o`` (octaves), each rotated and shifted.  Each
octave is read as the GPU reads a mipmapped texture with trilinear filtering: from the two levels
of its tile's mipmap whose texels are just finer and just coarser than the pixels' footprint on
the ground, blended by where the footprint lies between them (in log2, in steps of an eighth):
prefiltered, so nothing aliases, and with a scale-free tile the image shows the same amount of
detail at every height.  (Render revisions up to 6 read the finer level alone: texels up to half
a pixel's footprint, so the ground was sharper than a camera sees it at most heights, most at
footprints just under twice a texel, and its detail jumped as the footprint crossed a power of
two.)  The levels and the blend are chosen per octave and frame from the median footprint of the
ground in view.

Applied in linear light on the sharp frame (before motion blur), from the frame's depth and
pose: ground is where the world height is within a few millimetres of zero and no flat object
(the pad on the ground, decoys) lies; the modulation fades out within two pixels of their edges
so that no labelled edge moves.
"""
from __future__ import annotations

import functools
import math

import cv2
import numpy as np

TILE_PX = 512
# octave scales (metres per tile), and the log-albedo amplitude of each octave, per ground kind
OCTAVES_M = (4.0, 2.0, 1.0, 0.5, 0.25, 0.125)
AMPLITUDE = {"grass": 0.32, "dry_grass": 0.235, "gravel": 0.30, "soil": 0.22, "asphalt": 0.95, "sand": 0.14,
             "concrete": 0.65, "snow": 0.06}
# the coarse octaves (32, 16, 8 m, in the rasterised texture) relative to the fine ones: real ground
# has more structure at the scale of blades and stones than at the scale of tufts and patches
COARSE = {"grass": 0.8, "dry_grass": 0.8, "gravel": 0.6, "soil": 0.8, "asphalt": 0.0, "sand": 0.8, "concrete": 0.15,
          "snow": 1.0}
# per-octave weights (OCTAVES_M order) for kinds whose detail has a physical size, not the same at
# every scale; the rest weigh every octave alike.  Asphalt is its aggregate alone: stones of 3-18
# mm across in the 0.5 m octave, 1.5-9 mm and 0.7-4.5 mm (chippings and sand) in the two finest;
# its copies at 1 m and more per tile (and in the rasterised texture) were stones of 1-28 cm that
# no asphalt has (render revision 8: field1080's camera saw 332 strong corners per 256 px patch
# from 15 m, over eight draws, where the quay's asphalt shows 3).  Concrete's grains are 1.5-8 mm
# (the two finest octaves' tiles; its coarser octaves' copies stand for stains and wear).  Matched
# to real nadir frames of quay pavement (benchmarks/real_ground/omu_quay.csv), grass and dry grass
# to frames of mixed grass (benchmarks/real_ground/agh_grass.csv), at what field1080's camera
# sees from 1, 5 and 15 m (benchmarks/realism.py, eight draws of its light and defocus)
OCTAVE_WEIGHT = {"asphalt": (0.0, 0.0, 0.0, 0.3, 1.0, 1.6), "concrete": (0.2, 0.16, 0.2, 0.6, 1.0, 1.0),
                 "grass": (0.8, 0.8, 0.8, 1.0, 1.2, 0.8), "dry_grass": (0.8, 0.8, 0.8, 1.0, 1.2, 0.8)}
GROUND_Z_TOL_M = 0.005
MAP_STEPS = (4, 2)  # texture coordinates are made every 4 (or 2) px and upsampled (GroundDetail._map_grid)
MAP_TOL_PX = 0.02  # ... where the lens's rays, so upsampled, stay this close to every pixel's own


def _wrap_lines(canvas, pts_a, pts_b, values, widths):
    """Anti-aliased strokes on a tileable canvas (each drawn at its 3x3 wrapped copies)."""
    n = canvas.shape[0]
    for (a, b, v, w) in zip(pts_a, pts_b, values, widths):
        for dx in (-n, 0, n):
            for dy in (-n, 0, n):
                p = (int(round((a[0] + dx) * 16)), int(round((a[1] + dy) * 16)))
                q = (int(round((b[0] + dx) * 16)), int(round((b[1] + dy) * 16)))
                cv2.line(canvas, p, q, float(v), int(max(1, round(w))), cv2.LINE_AA, shift=4)


def _wrap_ellipse(canvas, centre, axes, angle_deg: float, value: float) -> None:
    """An anti-aliased filled ellipse on a tileable canvas (drawn at the wrapped copies it reaches)."""
    n = canvas.shape[0]
    reach = axes[0] + 2
    for dx in (-n, 0, n):
        for dy in (-n, 0, n):
            x, y = centre[0] + dx, centre[1] + dy
            if -reach < x < n + reach and -reach < y < n + reach:
                cv2.ellipse(canvas, (int(round(x * 16)), int(round(y * 16))),
                            (int(round(axes[0] * 16)), int(round(axes[1] * 16))), angle_deg, 0, 360, float(value),
                            -1, cv2.LINE_AA, shift=4)


def _aggregate(n: int, rng, binder: float, binder_grain: float, count: int, radius: tuple, value: tuple,
               grain: float, fbm: float) -> np.ndarray:
    """Stones in a binder, tileable: ``count`` ellipses (radius log-normal about ``radius[0]`` with a
    0.5 log-sd, clipped to ``radius[1:]`` texels; aspect 0.55-1; value normal ``value``) laid
    largest first on ``binder`` with its own grain, then a fine grain and a fractal mottle over all."""
    t = binder + binder_grain * _blur_wrapped(rng.standard_normal((n, n)).astype(np.float32), 0.7)
    radii = np.sort(np.clip(np.exp(rng.normal(math.log(radius[0]), 0.5, count)), radius[1], radius[2]))[::-1]
    for r in radii:
        _wrap_ellipse(t, rng.uniform(0, n, 2), (r, r * rng.uniform(0.55, 1.0)), rng.uniform(0, 180),
                      rng.normal(*value))
    return t + grain * _blur_wrapped(rng.standard_normal((n, n)).astype(np.float32), 0.6) + fbm * _fbm(n, rng, 1.0)


def _blur_wrapped(t: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian blur of a tileable image (OpenCV's blur has no wrapping border)."""
    m = int(math.ceil(4 * sigma)) + 1
    big = np.pad(t, m, mode="wrap")
    return cv2.GaussianBlur(big, (0, 0), sigma)[m:-m, m:-m]


def _fbm(n: int, rng, beta: float) -> np.ndarray:
    white = rng.standard_normal((n, n))
    f = np.fft.fftfreq(n) * n
    r = np.hypot(*np.meshgrid(f, f))
    r[0, 0] = 1.0
    out = np.real(np.fft.ifft2(np.fft.fft2(white) / r ** (beta / 2)))
    return ((out - out.mean()) / out.std()).astype(np.float32)


def _voronoi(n: int, rng, cells: int) -> tuple:
    """(cell value, distance to the nearest border in px) of a tileable Voronoi pattern."""
    pts = rng.uniform(0, n, (cells, 2))
    vals = rng.standard_normal(cells).astype(np.float32)
    tiled = np.concatenate([pts + [dx, dy] for dx in (-n, 0, n) for dy in (-n, 0, n)])
    tval = np.tile(vals, 9)
    yy, xx = np.mgrid[0:n, 0:n].astype(np.float32)
    best = np.full((n, n), np.inf, np.float32)
    second = np.full((n, n), np.inf, np.float32)
    val = np.zeros((n, n), np.float32)
    for (px, py), v in zip(tiled, tval):
        if not (-0.3 * n < px < 1.3 * n and -0.3 * n < py < 1.3 * n):
            continue
        d = np.hypot(xx - px, yy - py)
        closer = d < best
        second = np.where(closer, best, np.minimum(second, d))
        val = np.where(closer, v, val)
        best = np.where(closer, d, best)
    return val, (second - best) / 2.0


@functools.lru_cache(maxsize=16)
def detail_tile(kind: str, seed: int) -> np.ndarray:
    """``(TILE_PX, TILE_PX)`` float32, tileable, zero mean, unit std: the kind's log-albedo detail."""
    n = TILE_PX
    rng = np.random.default_rng([seed, sum(map(ord, kind))])
    t = np.zeros((n, n), np.float32)
    if kind in ("grass", "dry_grass"):
        dry = kind == "dry_grass"
        count = 2600 if dry else 1800
        c = rng.uniform(0, n, (count, 2))
        ang = rng.uniform(0, math.pi, count)
        length = rng.uniform(18, 70 if dry else 45, count)
        d = np.stack([np.cos(ang), np.sin(ang)], axis=1) * length[:, None] / 2
        vals = rng.choice([-1.0, 1.0], count, p=[0.45, 0.55]) * rng.uniform(0.4, 1.0, count)
        _wrap_lines(t, c - d, c + d, vals, rng.uniform(1.0, 2.2 if dry else 3.0, count))
        t += 0.35 * _fbm(n, rng, 1.6)
    elif kind == "gravel":
        val, border = _voronoi(n, rng, 700)
        t = val * 0.6 - 1.4 * np.exp(-border / 1.2) + 0.25 * _fbm(n, rng, 0.8)
    elif kind == "soil":
        t = _fbm(n, rng, 1.5) + 0.4 * _fbm(n, rng, 0.3)
        pits = rng.uniform(0, n, (500, 2))
        for x, y in pits:
            cv2.circle(t, (int(x), int(y)), int(rng.integers(1, 4)), -2.0, -1, cv2.LINE_AA)
    elif kind == "asphalt":
        # aggregate: dark binder packed with stones of 3-18 texels' radius (1.5-9 mm at the finest
        # octave), light and dark; cracks as random walks
        t = _aggregate(n, rng, binder=-1.0, binder_grain=0.3, count=2400, radius=(6.0, 3.0, 18.0),
                       value=(0.3, 0.8), grain=0.5, fbm=0.1)
        for _ in range(2):
            p = rng.uniform(0, n, 2)
            a = rng.uniform(0, 2 * math.pi)
            pts = [p.copy()]
            for _ in range(60):
                a += rng.normal(0, 0.35)
                p = p + 6 * np.array([math.cos(a), math.sin(a)])
                pts.append(p.copy())
            _wrap_lines(t, pts[:-1], pts[1:], [-3.0] * (len(pts) - 1), [2.0] * (len(pts) - 1))
    elif kind == "sand":
        grain = _blur_wrapped(rng.standard_normal((n, n)).astype(np.float32), 0.8)
        y = np.arange(n, dtype=np.float32)[:, None]
        t = grain + 0.8 * np.sin(2 * np.pi * (y * 6 / n + 0.4 * _fbm(n, rng, 2.5))).astype(np.float32)
    elif kind == "concrete":
        # cement paste with sand and fine aggregate showing, and pores: grains of 1.5-8 texels' radius
        # (0.7-4 mm at the finest octave), mostly darker than the paste
        t = _aggregate(n, rng, binder=0.0, binder_grain=0.4, count=8000, radius=(3.0, 1.5, 8.0),
                       value=(-0.5, 1.0), grain=0.7, fbm=0.2)
    elif kind == "snow":
        t = _fbm(n, rng, 1.2)
        sparkle = rng.random((n, n)) > 0.997
        t[sparkle] += 4.0
    else:
        raise ValueError(f"unknown ground kind {kind!r}")
    t = _blur_wrapped(t.astype(np.float32), 0.6)
    return ((t - t.mean()) / max(float(t.std()), 1e-6)).astype(np.float32)


class GroundDetail:
    """The detail of one sequence's ground, for one camera (pixel rays precomputed).

    ``flat_objects``: rectangles lying on the ground that are not ground, ``(x, y, yaw, sx, sy,
    moves_with_pad)`` in the world at t = 0 (the pad when it lies on the ground, decoys)."""

    def __init__(self, kind: str, seed: int, camera, xn: np.ndarray, yn: np.ndarray, flat_objects=()):
        self.kind = kind
        tile = detail_tile(kind, int(seed) % 2**31)
        rng = np.random.default_rng([int(seed) % 2**31, 99])
        # octaves pre-summed in groups (a mipmap of a sum is the sum of the mipmaps): each group is
        # one tile over its coarsest octave's period at its finest octave's texel, the octaves in it
        # turned by right angles, mirrored and shifted (so the sum stays tileable), and the group
        # turned by a free angle when it is read
        self.octaves = []
        weights = OCTAVE_WEIGHT.get(kind, (1.0,) * len(OCTAVES_M))
        for g0, group in ((0, OCTAVES_M[:3]), (3, OCTAVES_M[3:])):
            period, fine = group[0], group[-1]
            n = int(round(TILE_PX * period / fine))
            weighs = any(weights[g0:g0 + len(group)])  # a group weighing nothing changes no pixel
            acc = np.zeros((n, n), np.float32) if weighs else None
            for j, lam in enumerate(group):
                t = np.rot90(tile, int(rng.integers(4)))  # drawn either way: the next group's draws stay
                t = t[:, ::-1] if rng.random() < 0.5 else t
                t = np.roll(t, tuple(int(v) for v in rng.integers(0, TILE_PX, 2)), axis=(0, 1))
                if not weighs:
                    continue
                px = int(round(TILE_PX * lam / fine))  # this octave's tile, in the group's texels
                up = cv2.resize(np.ascontiguousarray(t), (px, px), interpolation=cv2.INTER_CUBIC) if px != TILE_PX else t
                acc += (AMPLITUDE[kind] * weights[g0 + j]) * np.tile(up, (n // px, n // px))
            ang = rng.uniform(0, 2 * math.pi)
            offset = rng.uniform(0, n, 2)
            if not weighs:
                continue
            mip = [acc]
            while mip[-1].shape[0] > 4:  # box-filtered halvings: the group's prefiltered levels
                mip.append(cv2.resize(mip[-1], None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA))
            self.octaves.append((period, fine / TILE_PX, math.cos(ang), math.sin(ang), *offset, mip))
        self.f = float(min(camera.fx, camera.fy))
        self.xn, self.yn = xn, yn
        self.r2 = (xn * xn + yn * yn + 1.0).astype(np.float32)
        self.min_dot = (0.05 * np.sqrt(self.r2)).astype(np.float32)
        self.flat_objects = list(flat_objects)
        self._blend_cache: dict = {}  # (group, level, step) -> blended tile (:meth:`_blended`)
        self._toward: dict = {}  # (group, level) -> the coarser level less this one (:meth:`_toward_coarser`)
        # the rays of a coarse grid (one node past each edge): texture coordinates on the ground plane
        # are smooth functions of the pixel, made there and upsampled (:meth:`_plane_map`)
        self.shape = (camera.height, camera.width)
        self.map_step, self.grid_rays = self._map_grid(camera, xn, yn)

    @staticmethod
    def _map_grid(camera, xn: np.ndarray, yn: np.ndarray) -> tuple:
        """``(step, rays)``: the coarsest grid step (4, 2 or 1 px) over which the lens's rays,
        upsampled bilinearly, stay within MAP_TOL_PX of every pixel's own (a pinhole's rays are
        linear: 4; a strong barrel lens curves them toward its corners), and the grid's rays
        ``(gh, gw, 3)`` float64 (x/z, y/z, 1), nodes at pixel ``step * (i - 1) + (step - 1) / 2``."""
        H, W = xn.shape
        for st in (MAP_STEPS[0], MAP_STEPS[1], 1):
            gx = st * (np.arange(-(-W // st) + 2) - 1) + (st - 1) / 2.0
            gy = st * (np.arange(-(-H // st) + 2) - 1) + (st - 1) / 2.0
            grid = np.stack(np.meshgrid(gx, gy), axis=-1)
            rays = camera.normalized_from_pixels(grid.reshape(-1, 2)).reshape(*grid.shape[:2], 2)
            if st == 1:
                break
            up = cv2.resize(rays.astype(np.float32), (rays.shape[1] * st, rays.shape[0] * st),
                            interpolation=cv2.INTER_LINEAR)[st:st + H, st:st + W]
            err = np.hypot(up[..., 0] - xn, up[..., 1] - yn) * float(min(camera.fx, camera.fy))
            if float(err.max()) <= MAP_TOL_PX:
                break
        return st, np.concatenate([rays, np.ones((*rays.shape[:2], 1))], axis=-1)

    def factor(self, z: np.ndarray, cam2world: np.ndarray, pad2world: np.ndarray) -> np.ndarray | None:
        """``(H, W)`` float32 albedo factor (1 off the ground), or ``None`` where nothing would change."""
        sub = np.s_[::4, ::4]
        finite4 = np.isfinite(z[sub])
        if not finite4[::2, ::2].any():
            return None
        footprint4 = self._footprint(np.where(finite4, z[sub], np.float32(0.0)), cam2world, sub)
        fp_all = float(np.median(footprint4[::2, ::2][finite4[::2, ::2]]))
        if not any(self._level(fp_all, o[1], o[-1]) is not None for o in self.octaves):
            return None  # every octave averages out within a pixel
        R, t = cam2world[:3, :3], cam2world[:3, 3]
        # the ground: where the depth is the ground plane's (z = 0 in the world) within a few mm (a
        # depth that is not finite is nowhere)
        dot = cv2.addWeighted(self.xn, float(R[2, 0]), self.yn, float(R[2, 1]), float(R[2, 2]))  # ray . world up
        on = cv2.inRange(cv2.multiply(z, dot), float(-t[2] - GROUND_Z_TOL_M), float(-t[2] + GROUND_Z_TOL_M))
        ground = np.multiply(on, np.float32(1.0 / 255.0), dtype=np.float32)
        plane = self._ground_plane_grid(cam2world)
        H, Wd = z.shape
        for x0, y0, yaw, sx, sy, moves in self.flat_objects:  # fade out within 2 px of their edges
            ox, oy = (x0 + pad2world[0, 3], y0 + pad2world[1, 3]) if moves else (x0, y0)
            roi = self._image_box(cam2world, ox, oy, yaw, sx, sy, H, Wd)
            if roi is None:
                continue
            r0, r1, c0, c1 = roi
            c, s = math.cos(yaw), math.sin(yaw)
            # the ground's points in the object's frame (c X + s Y, -s X + c Y), X, Y from its centre
            turn = np.array([[c, s], [-s, c]])
            uv = self._plane_map(plane, turn, -turn @ (ox, oy))[r0:r1, c0:c1]
            # max(|u| - sx / 2, |v| - sy / 2) / footprint - 1, clipped to [0, 1]
            u = np.abs(uv[..., 0]) - np.float32(sx / 2)
            np.maximum(u, np.abs(uv[..., 1]) - np.float32(sy / 2), out=u)
            zr = z[r0:r1, c0:c1]
            fp = self._footprint(np.where(np.isfinite(zr), zr, np.float32(0.0)), cam2world, np.s_[r0:r1, c0:c1])
            u /= np.maximum(fp, 1e-9, out=fp)
            u -= 1.0
            ground[r0:r1, c0:c1] *= np.clip(u, 0.0, 1.0, out=u)
        if not ground.any():
            return None
        logf = np.zeros(z.shape, np.float32)
        cx, cy = t[0], t[1]
        fp = float(np.median(footprint4[ground[sub] > 0])) if (ground[sub] > 0).any() else fp_all
        for g, (period, texel, c, s, ox, oy, mip) in enumerate(self.octaves):
            got = self._blended(g, fp, texel, mip)
            if got is None:
                continue
            level, tile = got
            n, n0 = tile.shape[0], mip[0].shape[0]
            k = n / period
            # texel coordinates near the camera stay small (remap's fixed point has 16-bit integers):
            # shift by whole tiles, which leaves the world-fixed pattern as it is
            u0 = n0 / period * (c * cx - s * cy) + ox
            v0 = n0 / period * (s * cx + c * cy) + oy
            # into the level's texels (centres: level texel i covers base texels [2i, 2i + 1])
            u0, v0, lx, ly = (q * n / n0 for q in (u0, v0, ox, oy))
            lx, ly = lx + 0.5 * n / n0 - 0.5, ly + 0.5 * n / n0 - 0.5
            maps = self._plane_map(plane, k * np.array([[c, -s], [s, c]]),
                                   (lx - n * math.floor(u0 / n), ly - n * math.floor(v0 / n)))
            logf += cv2.remap(tile, maps, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        cv2.multiply(logf, ground, dst=logf)
        return cv2.exp(logf)

    def _ground_plane_grid(self, cam2world: np.ndarray) -> tuple:
        """``(camera x y, offsets)``: where the coarse grid's rays meet the ground plane, as world
        x, y offsets ``(gh, gw, 2)`` float32 from the camera's (0 where a ray does not reach it)."""
        R, t = cam2world[:3, :3], cam2world[:3, 3]
        d = self.grid_rays @ R.T
        with np.errstate(divide="ignore", invalid="ignore"):
            s = -t[2] / d[..., 2]
        s[~(s > 0)] = 0.0
        return t[:2].copy(), (s[..., None] * d[..., :2]).astype(np.float32)

    def _plane_map(self, plane: tuple, A: np.ndarray, b) -> np.ndarray:
        """``(H, W, 2)`` float32: ``A @ (x, y) + b`` of the world point on the ground plane each pixel
        sees, made on the coarse grid (``plane``: :meth:`_ground_plane_grid`) and upsampled
        bilinearly (within a few hundredths of a pixel of its exact value); where no ground is
        seen, its value at the camera's foot."""
        origin, offsets = plane
        M = np.hstack([A, (A @ origin + np.asarray(b, np.float64))[:, None]]).astype(np.float32)
        m = cv2.transform(offsets, M)
        st, (H, W) = self.map_step, self.shape
        if st == 1:
            return m[1:1 + H, 1:1 + W]
        big = cv2.resize(m, (m.shape[1] * st, m.shape[0] * st), interpolation=cv2.INTER_LINEAR)
        return big[st:st + H, st:st + W]

    def _footprint(self, zc: np.ndarray, cam2world: np.ndarray, where) -> np.ndarray:
        """The footprint (m) on a horizontal surface of the pixels ``where`` (a slice) at depths
        ``zc`` (there): ``z |r|^2 / (f |up . r|)``, ``r = (xn, yn, 1)``, ``up`` the world's up in
        the camera frame; grazing rays are held at 20 x the pixel's length."""
        up = cam2world[2, :3]
        dot = cv2.addWeighted(self.xn[where], float(up[0]), self.yn[where], float(up[1]), float(up[2]))
        cv2.max(np.abs(dot), self.min_dot[where], dst=dot)
        return cv2.divide(cv2.multiply(zc, self.r2[where]), dot, scale=1.0 / self.f)

    def _image_box(self, cam2world, ox, oy, yaw, sx, sy, H, W):
        """Rows and columns ``(r0, r1, c0, c1)`` around where a flat rectangle on the ground shows
        (a generous box; ``None`` when it is out of view)."""
        c, s = math.cos(yaw), math.sin(yaw)
        m = 0.6 * max(sx, sy) + 0.05
        pts = np.array([[ox + dx * c - dy * s, oy + dx * s + dy * c, 0.0] for dx in (-m, m) for dy in (-m, m)])
        Pc = (pts - cam2world[:3, 3]) @ cam2world[:3, :3]
        if np.all(Pc[:, 2] <= 1e-3):
            return None
        if np.any(Pc[:, 2] <= 1e-3):
            return 0, H, 0, W  # partly behind the camera: look everywhere
        xn, yn = Pc[:, 0] / Pc[:, 2], Pc[:, 1] / Pc[:, 2]
        xs, ys = self.xn[::16, ::16], self.yn[::16, ::16]
        cols = np.nonzero((xs >= xn.min()) & (xs <= xn.max()))[1]
        rows = np.nonzero((ys >= yn.min()) & (ys <= yn.max()))[0]
        if not len(cols) or not len(rows):
            return None
        return (max(0, 16 * rows.min() - 16), min(H, 16 * rows.max() + 32),
                max(0, 16 * cols.min() - 16), min(W, 16 * cols.max() + 32))

    LOD_BIAS = -0.5
    BLEND_STEPS = 8  # the blend of two mipmap levels, in eighths (the blended tiles are kept)

    def _blended(self, group: int, footprint_m: float, texel_m: float, mip: list):
        """``(level, tile)``: the finer of the two mipmap levels around the footprint, blended with
        the coarser one, upsampled onto its texels, by the footprint's place between them
        (trilinear filtering; the coarser level past the last is the tile's mean, 0); ``None``
        where the tile averages out within a pixel (:meth:`_level`)."""
        footprint_m = footprint_m * 2.0 ** self.LOD_BIAS
        level = self._level(footprint_m, texel_m, mip)
        if level is None:
            return None
        lam = math.log2(max(footprint_m / texel_m, 1e-9))
        step = int(round(min(max(lam - level, 0.0), 1.0) * self.BLEND_STEPS))
        if step == 0:
            return level, mip[level]
        key = (group, level, step)
        tile = self._blend_cache.get(key)
        if tile is None:
            toward = self._toward_coarser(group, level, mip)
            tile = cv2.scaleAdd(toward, step / self.BLEND_STEPS, mip[level])
            if len(self._blend_cache) >= 4:  # a descent moves through the levels: keep the last few
                self._blend_cache.pop(next(iter(self._blend_cache)))
            self._blend_cache[key] = tile
        return level, tile

    def _toward_coarser(self, group: int, level: int, mip: list) -> np.ndarray:
        """The coarser level, upsampled onto ``level``'s texels, less ``level`` (a blend of the two
        is ``level`` plus a share of it); past the last level worth reading (:meth:`_level`), minus
        ``level`` (it fades to the tile's mean, 0).  Made once per level and kept (as much memory
        again as the group's mipmap: a descent reads most levels)."""
        key = (group, level)
        d = self._toward.get(key)
        if d is None:
            fine = mip[level]
            if level + 1 < len(mip) and mip[level + 1].shape[0] > 16:
                # the coarser level at the finer level's texel centres (wrapped), by the mean of a
                # bilinear and a bicubic upsampling: read again bilinearly by the remap, the one is
                # softer than the level read directly and the other sharper, and the mean is what
                # keeps the detail's statistics continuous where the level changes
                big = np.pad(mip[level + 1], 2, mode="wrap")
                up = cv2.addWeighted(cv2.resize(big, None, fx=2.0, fy=2.0, interpolation=cv2.INTER_LINEAR), 0.5,
                                     cv2.resize(big, None, fx=2.0, fy=2.0, interpolation=cv2.INTER_CUBIC), 0.5,
                                     0.0)[4:-4, 4:-4]
                d = cv2.subtract(np.ascontiguousarray(up), fine)
            else:
                d = -fine
            self._toward[key] = d
        return d

    @staticmethod
    def _level(footprint_m: float, texel_m: float, mip: list):
        """The mipmap level whose texels match the footprint (the finer of the two around it), or
        None when the tile is down to 16 texels or fewer there (it averages out within a pixel)."""
        level = max(0, int(math.floor(math.log2(max(footprint_m / texel_m, 1e-9)))))
        return level if level < len(mip) and mip[level].shape[0] > 16 else None
