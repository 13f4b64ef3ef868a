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

import math
from dataclasses import replace

import cv2
import numpy as np

from pad_design.texture import texture_to_pad

from .features import linear_to_srgb, srgb_to_linear
from .geometry import Camera, ideal_grid, pad_plane_homography
from .phases import LK_PARAMS, Detection

MIN_INLIERS = 20        # homography inliers for a location: another pad's texture gives at most ~11
MIN_SHARE = 0.1         # ... and this share of the matches (another pad's: ~4 %; this pad's, 20-70 %)
RANSAC_PX = 3.0         # inlier threshold, undistorted pixels
RATIO = 0.8             # Lowe's ratio test on Hamming distances
FRAME_FEATURES = 1500   # ORB features per frame (bounds the work)
TEXTURE_FEATURES = 6000
REFINE_CORNERS = 300    # corners of the drawn texture tracked into the frame ...
REFINE_AGAIN_PX = 4.0   # ... then drawn again where they were found, and tracked within this (_refined) ...
# ... each pass keeping at least this share of the corners drawn: a drawing that far off the frame is not refined
# by the few that track (unseen83: 32 of 300 under 10 px of smear at 0.4 m, 9.6 mm off; this pad's synthetic views
# 75-100 %, rendered frames 23-100 %: unseen85's at 0.6 m without the IMU, 69 of 300, 7.4 mm off within its sigma)
REFINE_MIN_SHARE = 0.2
PYRAMID_REACH = 4.0     # the texture is found while the image's pixels per metre are within this factor of its own
FRAME_REACH = 2.0       # ... but a frame that sees it magnified more than this is shrunk for ORB (locate)
COLD_SHRINK = 4         # with no height known, a frame the texture is not found in is tried shrunk this much too
DENSE_FEATURES = 50000  # every ORB feature the texture holds (14-28 thousand at 1000-2000 px/m), matched ...
TILE_VIEWS = 2.0        # ... in squares of the pad this many views' diagonals wide (locate), ...
TILE_MAX_SHARE = 0.75   # ... where they are at most this share of the pad's side, ...
TILE_TRIES = 2          # ... the squares with the most matches posed, and refined to a drawing that correlates
TILE_MIN_CC = 0.75      # ... this well with the frame (this pad's views 0.998-1, another pad's found in a square 0.5)
LIT_WINDOW_PX = 121     # the drawing is lit as the frame over squares this wide (_lit_as) ...
LIT_SHRINK = 8          # ... their sums taken on the images shrunk this much
SMEAR_INSTANTS = 12     # a smeared drawing (refined_under) averages at most this many instants of the exposure ...
SMEAR_INSTANT_PX = 3.0  # ... one per this many px of smear at the frame's centre


class PadTexture:
    """ORB features of a pad's texture, in pad-frame metres; :meth:`locate` finds them in a frame."""

    def __init__(self, pad):
        self.pad = pad
        gray = cv2.cvtColor(np.ascontiguousarray(pad.texture_rgb), cv2.COLOR_RGB2GRAY)
        self.levels = [gray]  # box-filtered halvings, to draw the texture at the image's scale
        while min(self.levels[-1].shape) > 64:
            self.levels.append(cv2.pyrDown(self.levels[-1]))
        self._dense_set = None  # every feature of the texture (_dense)
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

    def shrinks(self, camera: Camera, height: float | None, lowest: float | None = None) -> tuple:
        """How much the frame is shrunk for ORB, in the order tried (:meth:`locate`): where the camera's
        ``height`` over the pad is known and the frame sees the texture magnified past
        :data:`FRAME_REACH`, by the power of two that brings it within, and then that of ``lowest``
        where it differs; with no height known, not at all and then :data:`COLD_SHRINK`-fold."""
        return tuple(s for s, _ in self._tries(camera, height, lowest))

    def _tries(self, camera: Camera, height: float | None, lowest: float | None) -> list:
        """``[(shrink, the view's diagonal or None), ...]`` in the order :meth:`locate` tries them."""
        if height is None or not height > 0:
            return [(s, self._view_m(camera, None, s)) for s in (1, COLD_SHRINK)]

        def shrink(h):
            m = min(camera.fx, camera.fy) / (h * self.pad.ppm)
            return int(2 ** np.ceil(np.log2(m / FRAME_REACH))) if m > FRAME_REACH else 1

        tries = [(shrink(height), self._view_m(camera, height, 1))]
        if lowest is not None and 0 < lowest < height and shrink(lowest) != tries[0][0]:
            tries.append((shrink(lowest), self._view_m(camera, lowest, 1)))
        return tries

    def locate(self, gray: np.ndarray, camera: Camera, height: float | None = None, smear=None,
               lowest: float | None = None) -> tuple:
        """``(Detection | None, reason)``: the frame's features that are the texture's, as pad
        points and their (distorted) pixels: the inliers of a RANSAC homography, at least
        :data:`MIN_INLIERS` of them, refined against the texture's drawing.  ``height``: the
        camera's over the pad where known; ``lowest``: the lowest it may be now, where that height
        is an older pose's (the frame is also tried as shrunk and its view as small as there: a
        drone lost at 0.26 m found at 0.17-0.19 m, unseen88).  ``smear``: ``(pts_P, px) -> (cam2pad, motion,
        exposure_s, reach_px) | None``, the pose of the matches and the motion that smears the
        frame, where it does: the drawing is then smeared alike (:meth:`refined_under`), and
        drawn sharp only where that does not track (one refinement a frame, not both: a sharp one
        first cost 77 ms of a 1280x960 frame that the smeared one then replaced).

        ORB's pyramid shrinks the frame, and the texture's pyramid the texture, but the frame's
        shrunk levels hold few features: a view that magnifies the texture 2.9 times (0.3 m over a
        pad printed at 2000 px/m by a camera of f 1760 px) found 17 agreeing matches of 208, and at
        4-9 times (a long lens, a coarse texture, the ground at 0.1-0.2 m) 7-8: a landed drone off
        the flow's chain was never found again (unseen87: every touchdown frame lost).  Such a
        frame is shrunk first (:meth:`shrinks`); the features are placed back in the frame's own
        pixels, and refined there (:meth:`_refined`).

        A view of a few hundredths of the pad holds as few of the :data:`TEXTURE_FEATURES` spread
        over it (unseen88: a 55 degree lens at 0.15 m sees 1.6 % of the pad; 13 of 14 landed frames
        found 7-19 agreeing matches).  Where the whole pad's fail and the view is small beside the
        pad, the frame is matched to every feature the texture has (:meth:`_dense`) in each of
        overlapping squares of the pad a view fits in (:meth:`_tiles`), and the squares with the
        most matches are tried, each taken only refined to a drawing that correlates
        :data:`TILE_MIN_CC` with the frame (a square's own features hold fewer rivals: another pad's
        texture was found once in one, its drawing correlating 0.5).  unseen88's touchdown: 31 ->
        52 % posed; synthetic views of 1.3-2.6 % of the pad, 3 -> 6 of 8."""
        if not self.usable:
            return None, "the pad's texture has too few features"
        whys = []
        for s, view_m in self._tries(camera, height, lowest):
            det, why = self._located(gray, camera, s, view_m, smear)
            if det is not None:
                return det, why
            whys.append(why)
        return None, "; ".join(whys)

    def _view_m(self, camera: Camera, height: float | None, shrink: int) -> float | None:
        """The diagonal (m) of the pad's part a frame shrunk ``shrink``-fold sees, about: by the
        ``height`` where known; with none, the widest a frame is shrunk that much for (the least
        magnification :meth:`shrinks` gives it); ``None`` for an unshrunk frame of no known height."""
        diag_px = math.hypot(camera.width, camera.height)
        if height is not None and height > 0:
            return height * diag_px / min(camera.fx, camera.fy)
        if shrink > 1:
            return diag_px / (self.pad.ppm * FRAME_REACH * shrink / 2)
        return None

    def _tiles(self, view_m: float | None) -> list:
        """``[(pts_P, descriptors), ...]``: the texture's every feature (:meth:`_dense`) in each of
        the squares of side :data:`TILE_VIEWS` times ``view_m``, half a side apart, that cover the
        pad (any view of that diagonal lies wholly in one); none where they would be wider than
        :data:`TILE_MAX_SHARE` of the pad."""
        if view_m is None:
            return []
        side = self.pad.side_m
        L = TILE_VIEWS * view_m
        if not L <= TILE_MAX_SHARE * side:
            return []
        P, des = self._dense()
        half = side / 2
        cs = list(np.arange(-half + L / 2, half - L / 2 + 1e-9, L / 2))
        if cs[-1] < half - L / 2 - 1e-9:
            cs.append(half - L / 2)
        out = []
        for cx in cs:
            for cy in cs:
                m = (np.abs(P[:, 0] - cx) <= L / 2) & (np.abs(P[:, 1] - cy) <= L / 2)
                if m.sum() >= 4 * MIN_INLIERS:
                    out.append((P[m], des[m]))
        return out

    def _dense(self) -> tuple:
        """``(pts_P, descriptors)``: every ORB feature of the texture (up to :data:`DENSE_FEATURES`),
        made when first asked for (0.03-0.07 s for pads printed at 1000-2000 px/m)."""
        if self._dense_set is None:
            orb = cv2.ORB_create(nfeatures=DENSE_FEATURES, scaleFactor=1.2, nlevels=8, fastThreshold=10)
            kps, des = orb.detectAndCompute(self.levels[0], None)
            self._dense_set = (self.pad.from_texture_px(np.array([k.pt for k in kps], np.float64).reshape(-1, 2)),
                               des if des is not None else np.zeros((0, 32), np.uint8))
        return self._dense_set

    def _located(self, gray: np.ndarray, camera: Camera, shrink: int, view_m: float | None, smear=None) -> tuple:
        """:meth:`locate` on the frame shrunk ``shrink``-fold for ORB: matched to the whole pad's
        features, then to the squares of the pad a view of diagonal ``view_m`` fits in."""
        small = gray
        if shrink > 1:
            small = cv2.resize(gray, (max(gray.shape[1] // shrink, 1), max(gray.shape[0] // shrink, 1)),
                               interpolation=cv2.INTER_AREA)
        kps, des = self.frame_orb.detectAndCompute(small, None)
        where = "" if shrink == 1 else f" (the frame shrunk {shrink}-fold)"
        if des is None or len(kps) < MIN_INLIERS:
            return None, f"{0 if des is None else len(kps)} features in the image{where}"
        found = (gray, small.shape, kps, des, shrink, smear)
        det, why = self._matched(camera, found, [(self.pts_P, self.des)], 1)
        if det is not None:
            return det, why
        tiles = self._tiles(view_m)
        if tiles:
            det, why2 = self._matched(camera, found, tiles, TILE_TRIES, _tile_refusal)
            if det is not None:
                return replace(det, info=dict(det.info, tiles=len(tiles))), why2
            why += f"; in {len(tiles)} squares of the pad, the best: {why2}"
        return None, why + where

    def _matched(self, camera: Camera, found: tuple, sets: list, tries: int, refusal=None) -> tuple:
        """The frame's features (``found``: the frame, its shrunk copy's shape, the keypoints, their
        descriptors, the shrink, :meth:`locate`'s ``smear``) matched to each of ``sets`` (``(pts_P, descriptors)``), the
        ``tries`` with the most matches passing Lowe's ratio test posed by RANSAC in that order:
        :meth:`locate`'s answer, the first that ``refusal`` (``(det) -> why not, "" to take it``)
        does not refuse, or the first one's reason."""
        gray, small_shape, kps, des, shrink, smear = found
        tried = []
        for pts_P, tex_des in sets:
            pairs = self.matcher.knnMatch(des, tex_des, k=2)
            tried.append(([p[0] for p in pairs if len(p) == 2 and p[0].distance < RATIO * p[1].distance], pts_P))
        tried.sort(key=lambda g: -len(g[0]))
        whys = []
        for good, pts_P in tried[:tries]:
            det, why = self._homography(gray, camera, small_shape, kps, shrink, good, pts_P, smear)
            no = refusal(det) if det is not None and refusal is not None else ""
            if no:
                det, why = None, no
            if det is not None:
                return det, why
            whys.append(why)
        return None, whys[0]

    def _homography(self, gray, camera: Camera, small_shape, kps, shrink: int, good: list, pts_P, smear=None) -> tuple:
        """The matches ``good`` (of the frame's ``kps`` to ``pts_P``) posed by a RANSAC homography
        and refined (:meth:`_refined`; smeared, :meth:`refined_under`, where ``smear`` says the
        frame is: :meth:`locate`): :meth:`locate`'s answer."""
        if len(good) < MIN_INLIERS:
            return None, f"{len(good)} texture matches (< {MIN_INLIERS})"
        px = np.array([kps[m.queryIdx].pt for m in good], np.float64)
        if shrink > 1:  # back to the frame's pixels (pixel centres)
            px = (px + 0.5) * np.array([gray.shape[1] / small_shape[1], gray.shape[0] / small_shape[0]]) - 0.5
        P = pts_P[[m.trainIdx for m in good]]
        und = camera.undistort_pixels(px) if camera.has_distortion else px
        fin = np.isfinite(und).all(axis=1)
        if fin.sum() < MIN_INLIERS:
            return None, f"{int(fin.sum())} texture matches inside the lens's model (< {MIN_INLIERS})"
        H, inl = cv2.findHomography(P[fin, :2], und[fin], cv2.RANSAC, RANSAC_PX * shrink, maxIters=2000,
                                    confidence=0.999)
        n = 0 if inl is None else int(inl.sum())
        if H is None or n < max(MIN_INLIERS, MIN_SHARE * len(good)):
            return None, f"{n} of {len(good)} texture matches agree on a homography (< {MIN_INLIERS}, {MIN_SHARE:.0%})"
        keep = np.nonzero(fin)[0][inl[:, 0] == 1]
        info = {"matches": len(good), "inliers": n}
        plan = smear(P[keep], px[keep]) if smear is not None else None
        if plan is not None:
            det, why = self.refined_under(gray, camera, *plan)
            if det is not None:
                return replace(det, info={**info, **det.info}), "ok"
            info["smeared_drawing"] = why
        refined = self._detection(self._refined(gray, camera, [H], H, 2.0 * RANSAC_PX * shrink))
        if refined is not None:
            return replace(refined, info={**info, **refined.info}), "ok"
        return Detection(P[keep], px[keep], "texture", info), "ok"

    def placed_at(self, gray: np.ndarray, camera: Camera, cam2pad: np.ndarray, motion, exposure_s: float,
                  reach_px: float) -> tuple:
        """``(Detection | None, reason)``: the texture's corners in the frame, tracked from the texture
        drawn at ``cam2pad`` (a pose known to a few pixels: another method's), within ``reach_px`` of
        where it draws them: no ORB (its features and their matching took 130-270 ms of a 1280x720
        frame through a lens, this 60-110 ms).  Smeared as ``motion`` smears it over ``exposure_s``
        (:meth:`refined_under`, whose arguments these are), sharp where no motion is given.  Taken
        where the drawing correlates :data:`TILE_MIN_CC` with the frame."""
        if motion is not None and exposure_s > 0:
            det, why = self.refined_under(gray, camera, cam2pad, motion, exposure_s, reach_px)
        else:
            H = pad_plane_homography(camera, cam2pad)
            det, why = self._detection(self._refined(gray, camera, [H], H, reach_px)), "the drawing did not track into the frame"
        if det is None:
            return None, why
        no = _tile_refusal(det)
        return (None, no) if no else (det, "ok")

    @staticmethod
    def _detection(refined, **info):
        """:meth:`_refined`'s answer as a :class:`Detection` (``None`` for none)."""
        if refined is None:
            return None
        pts, seen, cc = refined
        return Detection(pts, seen, "texture", {"refined": len(pts), "cc": round(cc, 3), **info})

    def refined_under(self, gray: np.ndarray, camera: Camera, cam2pad: np.ndarray, motion, exposure_s: float,
                      reach_px: float) -> tuple:
        """``(Detection | None, reason)``: the texture's corners in a smeared frame, tracked from the
        texture drawn at ``cam2pad`` (a pose of ORB's keypoints) as ``motion`` (a
        :class:`hvloc.shutter.Twist`) smears it over ``exposure_s``, centred on the frame's time.

        ORB's keypoints land anywhere along a smear, and a sharp drawing's corners do not track into
        a smeared frame: unseen85's texture pose at 0.2 m under 28 px of smear stood on 26 keypoints
        fitting at 2.2 px, 3.9 mm off (1 % in scale).  The frame's smear is known to a fraction
        (the velocity filter's velocity, the gyro's rate): the drawing smeared alike (a few instants
        of the exposure averaged in linear light, as the frame's light was) is what Lucas-Kanade
        can follow, and a corner of it is its pad point's place at the frame's time wherever the
        smear is symmetric about it."""
        if not self.usable:
            return None, "the pad's texture has too few features"
        e = max(float(exposure_s), 0.0)
        H0 = pad_plane_homography(camera, cam2pad)
        centre = np.array([[[camera.cx, camera.cy]]], np.float64)
        ends = [cv2.perspectiveTransform(cv2.perspectiveTransform(centre, np.linalg.inv(H0)),
                                         pad_plane_homography(camera, motion.moved(cam2pad, tau)))[0, 0]
                for tau in (-e / 2, e / 2)]
        smear = float(np.linalg.norm(ends[1] - ends[0])) if np.isfinite(ends).all() else float("nan")
        if not np.isfinite(smear):
            return None, "the smear is not known at the frame's centre"
        n = int(np.clip(np.ceil(smear / SMEAR_INSTANT_PX), 1, SMEAR_INSTANTS))
        taus = np.linspace(-e / 2, e / 2, n) if n > 1 else [0.0]
        refined = self._refined(gray, camera, [pad_plane_homography(camera, motion.moved(cam2pad, tau)) for tau in taus],
                                H0, reach_px)
        if refined is None:
            return None, f"the drawing smeared {smear:.0f} px did not track into the frame"
        return self._detection(refined, smeared_px=round(smear, 1)), "ok"

    def _refined(self, gray: np.ndarray, camera: Camera, Hs: list, H: np.ndarray, reach_px: float):
        """``(pts_P, px, cc)`` to a fraction of a pixel, or ``None``: ORB's keypoints sit on a pyramid's
        grid (a millimetre or two and half a degree at 0.25 m).  The texture is drawn where each of
        the homographies ``Hs`` puts it (the frame's ``H``; or the instants of its exposure,
        averaged in linear light: :meth:`refined_under`) and its corners tracked into the frame
        (:meth:`_tracked`); then drawn again where those tracks put it, and tracked again within
        :data:`REFINE_AGAIN_PX`.  Matches of a view of 2 % of the pad at 0.15 m (20-25 agreeing)
        put the drawing up to ~50 px off: Lucas-Kanade's pyramid carried it part of the way, and
        the refined poses were 0.5-5 mm and up to 1.7 degrees off; tracked again, within 0.11 mm
        and 0.04 degrees.  ``cc``: the last drawing's correlation with the frame over the pad."""
        found = self._tracked(gray, camera, Hs, H, reach_px)
        if found is None:
            return None
        und = camera.undistort_pixels(found[1]) if camera.has_distortion else found[1]
        H1, inl = cv2.findHomography(found[0][:, :2], und, cv2.RANSAC, REFINE_AGAIN_PX, maxIters=2000,
                                     confidence=0.999)
        if H1 is None or inl.sum() < MIN_INLIERS:
            return found
        moved = H1 @ np.linalg.inv(H)  # image to image: where the tracks moved the drawing
        again = self._tracked(gray, camera, [moved @ Hk for Hk in Hs], H1, REFINE_AGAIN_PX)
        return found if again is None else again

    def _tracked(self, gray: np.ndarray, camera: Camera, Hs: list, H: np.ndarray, reach_px: float):
        """:meth:`_refined`'s one pass: the texture drawn through the lens, from the pyramid level of
        the image's scale, where each of ``Hs`` puts it; its corners tracked from that drawing into
        the frame by Lucas-Kanade (forward and back, each within ``reach_px`` of where ``H`` drew
        it), and each keeping the pad point ``H`` drew it from; with the drawing's correlation
        with the frame over the pad."""
        h, w = camera.height, camera.width
        Hinv = np.linalg.inv(H)  # undistorted pixels -> pad metres
        c = cv2.perspectiveTransform(np.array([[[w / 2 - 1, h / 2], [w / 2, h / 2]]], np.float64), Hinv)[0]
        m_per_px = float(np.linalg.norm(c[1] - c[0]))
        if not np.isfinite(m_per_px) or m_per_px <= 0:
            return None
        level = int(np.clip(np.floor(np.log2(max(self.pad.ppm * m_per_px, 1.0))), 0, len(self.levels) - 1))
        tex = self.levels[level] if len(Hs) == 1 else srgb_to_linear(self.levels[level])
        # level texels -> pad metres
        A = texture_to_pad(self.pad.side_m, self.pad.ppm / 2**level)
        edge = np.ones(tex.shape, np.uint8)
        edge[:2], edge[-2:], edge[:, :2], edge[:, -2:] = 0, 0, 0, 0
        if camera.has_distortion:
            acc, inside = self._through_lens(camera, tex, edge, [Hk @ A for Hk in Hs], H @ A)
        else:
            acc, inside = None, None
            for Hk in Hs:
                M = Hk @ A  # level texels -> image pixels
                drawn = cv2.warpPerspective(tex, M, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
                ins = cv2.warpPerspective(edge, M, (w, h), flags=cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT)
                acc = drawn.astype(np.float32) if acc is None else acc + drawn
                inside = ins if inside is None else inside & ins
        drawn = acc if len(Hs) == 1 else linear_to_srgb(acc / len(Hs))
        drawn = np.clip(drawn, 0, 255).astype(np.uint8)
        inside = cv2.erode(inside, np.ones((23, 23), np.uint8))  # LK's window stays on the pad
        p0 = cv2.goodFeaturesToTrack(drawn, REFINE_CORNERS, 0.01, 8, mask=inside)
        if p0 is None or len(p0) < MIN_INLIERS:
            return None
        drawn = _lit_as(drawn, gray, inside)
        cc = float(cv2.computeECC(drawn.astype(np.float32), gray.astype(np.float32), inside))  # zero-mean normalized
        cc = cc if math.isfinite(cc) else 0.0  # (a flat drawing or frame correlates with nothing)
        params = {**LK_PARAMS, "maxLevel": 2}  # the drawing is within a few pixels of the frame
        p1, st, _ = cv2.calcOpticalFlowPyrLK(drawn, gray, p0, p0.copy(), flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **params)
        if p1 is None:
            return None
        pb, stb, _ = cv2.calcOpticalFlowPyrLK(gray, drawn, p1, p0.copy(), flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **params)
        ok = ((st[:, 0] == 1) & (stb[:, 0] == 1) & (np.linalg.norm((pb - p0)[:, 0], axis=1) < 0.5)
              & (np.linalg.norm((p1 - p0)[:, 0], axis=1) < reach_px))
        if ok.sum() < max(MIN_INLIERS, REFINE_MIN_SHARE * len(p0)):
            return None
        p0, p1 = p0[ok, 0].astype(np.float64), p1[ok, 0].astype(np.float64)
        und = camera.undistort_pixels(p0) if camera.has_distortion else p0
        P = cv2.perspectiveTransform(und.reshape(-1, 1, 2), Hinv).reshape(-1, 2)
        return np.column_stack([P, np.zeros(len(P))]), p1, cc

    def _through_lens(self, camera: Camera, tex: np.ndarray, edge: np.ndarray, Ms: list, M: np.ndarray) -> tuple:
        """``(sum, inside)``: the texture level ``tex`` drawn through the lens where each of ``Ms``
        (level texels -> ideal pixels) puts it, summed (float32), and where every one of them
        draws it within ``edge``.  Each pixel's ideal pinhole place is carried to the texels once,
        by ``M`` (the frame's); the instants are drawn in the texture's own plane, each by the
        texel-to-texel move from ``M`` to its own (a homography: warped, not mapped pixel by
        pixel), over the texels the frame sees, and the sum is taken through the lens in one
        remap.  Mapping every pixel for every instant cost 12 ms an instant at 1280x720 (a
        smeared drawing of 8 instants, drawn twice: 190 ms)."""
        grid = ideal_grid(camera)
        h, w = grid.shape[:2]
        uv = cv2.perspectiveTransform(grid.reshape(-1, 1, 2), np.linalg.inv(M)).reshape(h, w, 2).astype(np.float32)
        if len(Ms) == 1:
            return (cv2.remap(tex, uv[..., 0], uv[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT).astype(np.float32),
                    cv2.remap(edge, uv[..., 0], uv[..., 1], cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT))
        # the texels the frame sees (and one beyond, for the bilinear reads), within the texture: the
        # frame's edge bounds them (a homography of the plane in front of the camera)
        n_y, n_x = tex.shape[:2]
        rim = np.concatenate([uv[0], uv[-1], uv[:, 0], uv[:, -1]])
        rim = rim[np.isfinite(rim).all(axis=1)]
        if not len(rim):
            return np.zeros((h, w), np.float32), np.zeros((h, w), np.uint8)
        x0, y0 = (int(np.clip(np.floor(rim[:, i].min()) - 1, 0, size - 1)) for i, size in ((0, n_x), (1, n_y)))
        x1, y1 = (int(np.clip(np.ceil(rim[:, i].max()) + 2, x + 1, size)) for i, x, size in ((0, x0, n_x), (1, y0, n_y)))
        shift = np.array([[1.0, 0.0, x0], [0.0, 1.0, y0], [0.0, 0.0, 1.0]])
        acc = np.zeros((y1 - y0, x1 - x0), np.float32)
        ins = np.ones((y1 - y0, x1 - x0), np.uint8)
        for Mk in Ms:
            E = np.linalg.inv(Mk) @ M @ shift  # the window's texels at the frame's time -> this instant's texels
            flags = cv2.WARP_INVERSE_MAP
            acc += cv2.warpPerspective(tex, E, (x1 - x0, y1 - y0), flags=cv2.INTER_LINEAR | flags, borderMode=cv2.BORDER_CONSTANT)
            ins &= cv2.warpPerspective(edge, E, (x1 - x0, y1 - y0), flags=cv2.INTER_NEAREST | flags, borderMode=cv2.BORDER_CONSTANT)
        uv -= np.array([x0, y0], np.float32)
        return (cv2.remap(acc, uv[..., 0], uv[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT),
                cv2.remap(ins, uv[..., 0], uv[..., 1], cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT))


def _lit_as(drawn: np.ndarray, gray: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``drawn`` with the frame's brightness and contrast where ``mask`` is set, each pixel's by
    the mean and spread of both images over the :data:`LIT_WINDOW_PX` square about it (within the
    mask): Lucas-Kanade takes a brightness difference for motion.  A drone's shadow over the pad
    at touchdown turns its white field grey (255 -> 90): tracked from the white drawing, the
    corners drifted 150 px in the median, and none of a landed drone's views was refined.  The
    shadow's edge crosses the view: matched over the whole view, unseen85's shadowed field at
    0.2 m was drawn at twice its grey, and its corners tracked 5.7 px off."""
    m = (mask > 0).astype(np.float32)
    if m.sum() < 2:
        return drawn
    d, g = drawn.astype(np.float32), gray.astype(np.float32)
    # the squares' sums are smooth: taken on the images shrunk LIT_SHRINK-fold and drawn back up (a
    # full-size box filter cost 30 ms a 1280x960 frame, twice a refinement)
    h, w = m.shape
    size = (max(w // LIT_SHRINK, 1), max(h // LIT_SHRINK, 1))
    k = (max(LIT_WINDOW_PX // LIT_SHRINK, 1) | 1,) * 2

    def sums(x):
        return cv2.boxFilter(cv2.resize(x, size, interpolation=cv2.INTER_AREA), -1, k, normalize=False)

    n = np.maximum(sums(m), 1e-6)
    md, mg, dd, gg = (sums(x) / n for x in (d * m, g * m, d * d * m, g * g * m))
    sd, sg = np.sqrt(np.maximum(dd - md * md, 0.0)), np.sqrt(np.maximum(gg - mg * mg, 0.0))
    a = np.where(sd > 1.0, sg / np.maximum(sd, 1.0), 1.0)  # drawn * a + b, gain and offset per square
    a, b = (cv2.resize(x, (w, h), interpolation=cv2.INTER_LINEAR) for x in (a, mg - a * md))
    return np.clip(a * d + b, 0, 255).astype(np.uint8)


def _tile_refusal(det) -> str:
    """Why a texture detection found among a square's features is not taken (:meth:`PadTexture._located`),
    ``""`` where it is: refined to a drawing that correlates :data:`TILE_MIN_CC` with the frame."""
    cc = det.info.get("cc")
    if cc is None:
        return "its drawing did not refine it"
    return "" if cc >= TILE_MIN_CC else f"its drawing correlates {cc} with the frame (< {TILE_MIN_CC})"
