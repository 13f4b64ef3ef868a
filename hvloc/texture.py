"""The pad found by its own printed texture: a pose near the ground when the chain of flow poses
has broken and neither markers nor outline are in view.

At touchdown the camera sees a few decimetres of the pad's field.  A gust (a 30 ms exposure
smears 40 px near the ground) or the pad leaving the view breaks the flow tracker's tracks, and
the flow tracker can only be anchored again by a pad pose; the markers and the outline are out
of view or larger than the image.  The texture itself is known exactly (``pad.png``, the file
the pad was printed from), and its shapes are random, so ORB features of the frame matched to
ORB features of the texture, with a RANSAC homography, say where the camera is over the pad.

ORB (OpenCV): binary, rotation invariant, an 8-level pyramid on both sides (the texture's
scale and the image's differ by up to ~4x over the heights it serves), and deterministic (the
work per frame is bounded by a feature count; OpenCV's RANSAC has a fixed seed).
"""
from __future__ import annotations

import cv2
import numpy as np

from pad_design.texture import texture_to_pad

from .geometry import Camera
from .phases import LK_PARAMS, Detection

MIN_INLIERS = 20        # homography inliers for a location: another pad's texture gives at most ~11
MIN_SHARE = 0.1         # ... and this share of the matches (another pad's: ~4 %; this pad's, 20-70 %)
RANSAC_PX = 3.0         # inlier threshold, undistorted pixels
RATIO = 0.8             # Lowe's ratio test on Hamming distances
FRAME_FEATURES = 1500   # ORB features per frame (bounds the work)
TEXTURE_FEATURES = 6000
REFINE_CORNERS = 300    # corners of the drawn texture tracked into the frame
PYRAMID_REACH = 4.0     # the texture is found while the image's pixels per metre are within this factor of its own
FRAME_REACH = 2.0       # ... but a frame that sees it magnified more than this is shrunk for ORB (locate)
COLD_SHRINK = 4         # with no height known, a frame the texture is not found in is tried shrunk this much too


class PadTexture:
    """ORB features of a pad's texture, in pad-frame metres; :meth:`locate` finds them in a frame."""

    def __init__(self, pad):
        self.pad = pad
        gray = cv2.cvtColor(np.ascontiguousarray(pad.texture_rgb), cv2.COLOR_RGB2GRAY)
        self.levels = [gray]  # box-filtered halvings, to draw the texture at the image's scale
        while min(self.levels[-1].shape) > 64:
            self.levels.append(cv2.pyrDown(self.levels[-1]))
        self._grid = None  # (camera, (H, W, 2) undistorted pixel of every pixel)
        self.orb = cv2.ORB_create(nfeatures=TEXTURE_FEATURES, scaleFactor=1.2, nlevels=8, fastThreshold=10)
        kps, self.des = self.orb.detectAndCompute(gray, None)
        self.pts_P = pad.from_texture_px(np.array([k.pt for k in kps], np.float64).reshape(-1, 2))
        self.frame_orb = cv2.ORB_create(nfeatures=FRAME_FEATURES, scaleFactor=1.2, nlevels=8, fastThreshold=10)
        self.matcher = cv2.BFMatcher(cv2.NORM_HAMMING)

    @property
    def usable(self) -> bool:
        return self.des is not None and len(self.des) >= 4 * MIN_INLIERS

    def max_height_m(self, camera: Camera) -> float:
        """Above this height the image's pixels per metre on the pad (``f / h``) are fewer than
        the texture's over :data:`PYRAMID_REACH`: ORB's pyramids no longer meet."""
        return PYRAMID_REACH * min(camera.fx, camera.fy) / self.pad.ppm

    def shrinks(self, camera: Camera, height: float | None) -> tuple:
        """How much the frame is shrunk for ORB, in the order tried (:meth:`locate`): where the camera's
        ``height`` over the pad is known and the frame sees the texture magnified past
        :data:`FRAME_REACH`, by the power of two that brings it within; with no height known, not
        at all and then :data:`COLD_SHRINK`-fold."""
        if height is None or not height > 0:
            return (1, COLD_SHRINK)
        m = min(camera.fx, camera.fy) / (height * self.pad.ppm)
        return (int(2 ** np.ceil(np.log2(m / FRAME_REACH))) if m > FRAME_REACH else 1,)

    def locate(self, gray: np.ndarray, camera: Camera, height: float | None = None) -> tuple:
        """``(Detection | None, reason)``: the frame's features that are the texture's, as pad
        points and their (distorted) pixels: the inliers of a RANSAC homography, at least
        :data:`MIN_INLIERS` of them.  ``height``: the camera's over the pad where known.

        ORB's pyramid shrinks the frame, and the texture's pyramid the texture, but the frame's
        shrunk levels hold few features: a view that magnifies the texture 2.9 times (0.3 m over a
        pad printed at 2000 px/m by a camera of f 1760 px) found 17 agreeing matches of 208, and at
        4-9 times (a long lens, a coarse texture, the ground at 0.1-0.2 m) 7-8: a landed drone off
        the flow's chain was never found again (unseen87: every touchdown frame lost).  Such a
        frame is shrunk first (:meth:`shrinks`); the features are placed back in the frame's own
        pixels, and refined there (:meth:`_refined`)."""
        if not self.usable:
            return None, "the pad's texture has too few features"
        whys = []
        for s in self.shrinks(camera, height):
            det, why = self._located(gray, camera, s)
            if det is not None:
                return det, why
            whys.append(why)
        return None, "; ".join(whys)

    def _located(self, gray: np.ndarray, camera: Camera, shrink: int) -> tuple:
        """:meth:`locate` on the frame shrunk ``shrink``-fold for ORB."""
        small = gray
        if shrink > 1:
            small = cv2.resize(gray, (max(gray.shape[1] // shrink, 1), max(gray.shape[0] // shrink, 1)),
                               interpolation=cv2.INTER_AREA)
        kps, des = self.frame_orb.detectAndCompute(small, None)
        where = "" if shrink == 1 else f" (the frame shrunk {shrink}-fold)"
        if des is None or len(kps) < MIN_INLIERS:
            return None, f"{0 if des is None else len(kps)} features in the image{where}"
        pairs = self.matcher.knnMatch(des, self.des, k=2)
        good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < RATIO * p[1].distance]
        if len(good) < MIN_INLIERS:
            return None, f"{len(good)} texture matches (< {MIN_INLIERS}){where}"
        px = np.array([kps[m.queryIdx].pt for m in good], np.float64)
        if shrink > 1:  # back to the frame's pixels (pixel centres)
            px = (px + 0.5) * np.array([gray.shape[1] / small.shape[1], gray.shape[0] / small.shape[0]]) - 0.5
        P = self.pts_P[[m.trainIdx for m in good]]
        und = camera.undistort_pixels(px) if camera.has_distortion else px
        fin = np.isfinite(und).all(axis=1)
        if fin.sum() < MIN_INLIERS:
            return None, f"{int(fin.sum())} texture matches inside the lens's model (< {MIN_INLIERS}){where}"
        H, inl = cv2.findHomography(P[fin, :2], und[fin], cv2.RANSAC, RANSAC_PX * shrink, maxIters=2000,
                                    confidence=0.999)
        n = 0 if inl is None else int(inl.sum())
        if H is None or n < max(MIN_INLIERS, MIN_SHARE * len(good)):
            return None, (f"{n} of {len(good)} texture matches agree on a homography (< {MIN_INLIERS}, "
                          f"{MIN_SHARE:.0%}){where}")
        keep = np.nonzero(fin)[0][inl[:, 0] == 1]
        info = {"matches": len(good), "inliers": n}
        refined = self._refined(gray, camera, H, 2.0 * RANSAC_PX * shrink)
        if refined is not None:
            return Detection(*refined, "texture", {**info, "refined": len(refined[0])}), "ok"
        return Detection(P[keep], px[keep], "texture", info), "ok"

    def _refined(self, gray: np.ndarray, camera: Camera, H: np.ndarray, reach_px: float):
        """``(pts_P, px)`` to a fraction of a pixel, or ``None``: ORB's keypoints sit on a pyramid's
        grid (a millimetre or two and half a degree at 0.25 m).  The texture is drawn where the
        homography puts it (through the lens, from the pyramid level of the image's scale), its
        corners are tracked from that drawing into the frame by Lucas-Kanade (forward and back, each
        within ``reach_px`` of where the homography drew it: twice its RANSAC threshold), and each
        keeps the pad point it was drawn from."""
        h, w = camera.height, camera.width
        Hinv = np.linalg.inv(H)  # undistorted pixels -> pad metres
        c = cv2.perspectiveTransform(np.array([[[w / 2 - 1, h / 2], [w / 2, h / 2]]], np.float64), Hinv)[0]
        m_per_px = float(np.linalg.norm(c[1] - c[0]))
        if not np.isfinite(m_per_px) or m_per_px <= 0:
            return None
        level = int(np.clip(np.floor(np.log2(max(self.pad.ppm * m_per_px, 1.0))), 0, len(self.levels) - 1))
        tex = self.levels[level]
        # level texels -> pad metres
        A = texture_to_pad(self.pad.side_m, self.pad.ppm / 2**level)
        edge = np.ones_like(tex)
        edge[:2], edge[-2:], edge[:, :2], edge[:, -2:] = 0, 0, 0, 0
        if not camera.has_distortion:
            M = H @ A  # level texels -> image pixels
            drawn = cv2.warpPerspective(tex, M, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
            inside = cv2.warpPerspective(edge, M, (w, h), flags=cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT)
        else:  # through the lens: every pixel's ideal pinhole place, then the inverse homography
            grid = self._undistorted_grid(camera)
            uv = cv2.perspectiveTransform(grid.reshape(-1, 1, 2), np.linalg.inv(H @ A)).reshape(h, w, 2).astype(np.float32)
            drawn = cv2.remap(tex, uv[..., 0], uv[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
            inside = cv2.remap(edge, uv[..., 0], uv[..., 1], cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT)
        inside = cv2.erode(inside, np.ones((23, 23), np.uint8))  # LK's window stays on the pad
        p0 = cv2.goodFeaturesToTrack(drawn, REFINE_CORNERS, 0.01, 8, mask=inside)
        if p0 is None or len(p0) < MIN_INLIERS:
            return None
        drawn = _lit_as(drawn, gray, inside)
        params = {**LK_PARAMS, "maxLevel": 2}  # the drawing is within a few pixels of the frame
        p1, st, _ = cv2.calcOpticalFlowPyrLK(drawn, gray, p0, p0.copy(), flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **params)
        if p1 is None:
            return None
        pb, stb, _ = cv2.calcOpticalFlowPyrLK(gray, drawn, p1, p0.copy(), flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **params)
        ok = ((st[:, 0] == 1) & (stb[:, 0] == 1) & (np.linalg.norm((pb - p0)[:, 0], axis=1) < 0.5)
              & (np.linalg.norm((p1 - p0)[:, 0], axis=1) < reach_px))
        if ok.sum() < MIN_INLIERS:
            return None
        p0, p1 = p0[ok, 0].astype(np.float64), p1[ok, 0].astype(np.float64)
        und = camera.undistort_pixels(p0) if camera.has_distortion else p0
        P = cv2.perspectiveTransform(und.reshape(-1, 1, 2), Hinv).reshape(-1, 2)
        return np.column_stack([P, np.zeros(len(P))]), p1

    def _undistorted_grid(self, camera: Camera) -> np.ndarray:
        """``(H, W, 2)`` float64: every pixel's place in the ideal pinhole image (kept per camera)."""
        if self._grid is None or self._grid[0] is not camera:
            self._grid = (camera, camera.ideal_pixel_grid())
        return self._grid[1]


def _lit_as(drawn: np.ndarray, gray: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``drawn`` with the frame's brightness and contrast where ``mask`` is set (its mean and
    spread matched): Lucas-Kanade takes a brightness difference for motion.  A drone's shadow over
    the pad at touchdown turns its white field grey (255 -> 90): tracked from the white drawing,
    the corners drifted 150 px in the median, and none of a landed drone's views was refined."""
    m = mask > 0
    if m.sum() < 2:
        return drawn
    d, g = drawn[m].astype(np.float32), gray[m].astype(np.float32)
    sd = float(d.std())
    if not sd > 1e-3:
        return drawn
    a = float(g.std()) / sd
    return np.clip(a * (drawn.astype(np.float32) - float(d.mean())) + float(g.mean()), 0, 255).astype(np.uint8)
