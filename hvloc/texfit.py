"""A far pad's pose fitted to the frame through its printed design, the tilt held.

The outline's corners come from colour and luma edges fitted as steps.  On a pad 20-60 px across
a step fit is biased by what lies a few pixels inside the edge (the border's checker, the white
field, the markers): the quad comes out ~1 % too large, the height ~0.5-1 % low.  The design
itself is known exactly (``pad.png``), so the pad can instead be drawn at a pose, blurred as the
camera blurs it, and compared with the frame pixel by pixel: the pose whose drawing matches the
frame best places every edge at once, each with its real profile.

With the IMU's gravity the pad's tilt is known to a fraction of a degree, and a far pad's pixels
say little about it; what they do fix is where the pad lies in the image, how large it is and its
yaw.  So four pose parameters are fitted (the camera's position in the pad frame and its yaw about
the pad's normal; from :data:`TILT_MIN_SIDE_PX` the tilt too, weighed against the IMU's: seen
obliquely, a few tenths of a degree of it change the pad's foreshortening, and so its fitted size,
by as many tenths of a percent), and two of the camera's: its blur (a Gaussian's sigma, in px: lens, sensor
and codec together, which couples with the size: a wider blur spreads the white field outward)
and its own sharpening (an unsharp mask's amount).  Each of the camera's channels is linear in
light (the design's red, green and blue, the ground's, an offset), solved at every step, and
written through sRGB's tone curve (:data:`TONE`); the fit compares the frame's luma.  Residuals
are weighed by Huber's rule, so a shadow across part of the pad counts as little as it fits.

Where the bias went: on frames made as a camera makes them (light averaged over each pixel, blurred,
written through sRGB), a grey frame taken to light as one channel, with the tone's exponent fitted,
put 15-19 m pads 0.24-0.62 % too near under 0-1 px of blur (the exponent came out 1.0-1.4,
standing in for the model's error, and the blur's coupling with size did the rest); per channel
with sRGB's tone, within 0.07 %.  On bench_v2's renders, fitted from the true pose at 20-30 px:
-0.9 to -0.2 % before, -0.0 to +0.4 % now, except the wide lens under JPEG 55 (-1.1 %) and
dusk_noise (-0.6 %); the renderer mixes texels in display space (README).

The pad is compared with a ring of ground around it: the border's outer edge is seen against the
ground, whose texture counts as noise.

Gauss-Newton (Levenberg-Marquardt) with the Jacobian from the drawing's gradients and the image
motion each pose parameter causes at each pixel's pad point; ~10-20 ms for a 30-60 px pad.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from pad_design.texture import texture_to_pad

from .features import ncc as _ncc, srgb_to_linear
from .geometry import Camera, invert, pad_plane_homography, so3_exp
from .synthesis import box_levels, level_for

MAX_SIDE_PX = 64.0  # fitted only on pads at most this many px across (under a rolling shutter; GLOBAL_MAX_SIDE_PX
# below under a global one): larger ones the step fit places well ...
# ... unless the frame's chroma is at half resolution (JPEG, H.264): there the border's colour edges smear and
# the step fit's sides come out 0.7-1 % of the height off at 64-140 px (far_wide, unseen100), the design's
# luma within 0.2 % (~45 ms at 64-100 px, ~95 ms at 100-140 px)
HALVED_MAX_SIDE_PX = 140.0
# ... and under a global shutter up to this: there the step fit places a pad well but tilts it as the AHRS does
# (its four corners say little of a few tenths of a degree), and the AHRS's error moves it sideways by the height
# times that error: bench_v1's sim800 (two descents, an AHRS 0.47 degrees off in the median) at 64-100 px, 1.01 %
# of the height sideways with the step fit, 0.09 % with the design fitted with its tilt (as at 44-64 px: 0.18 %).
# Not further: the fit's cost grows with the pad's area (one thread: ~100 ms at 64-100 px against the step fit's
# ~20, ~300 ms at 100-140 px).  Not under a rolling shutter (but on an untracked deck, drawn row by row: the
# localizer's ``_design_fit``): drawn as one instant, a frame's turn while its rows are read skews the pad as a
# tilt does (fuzz seed 112, 73-100 px at 5 Hz: its poses 2.6 % of the height off in the median, 6.7 % beyond
# their 3 sigma), and drawn row by row its 64-100 px pads cost 1.3 times the CPU for nothing (fuzz seed 162)
GLOBAL_MAX_SIDE_PX = 100.0
# ... and at least this many: below, the design is a few px of blur (a 13-15 px pad's height came out 11 % off).
# At 16-20 px it stands in for the white field's corners, which a camera summing light puts 7-9 % of the
# field's side too large there (the checker averages to a bright grey): README, "A far pad placed by its drawn design"
MIN_SIDE_PX = 16.0
# Each pixel is drawn as the mean of this many x this many points spread over it, as a camera's pixel sums the
# light over its area.  Drawn at its centre alone from the level whose texels are no larger than a pixel, the
# drawing was blurred by 0.25-0.5 px, and unlike a blur, by how far that level's texels were from a pixel's
# size: the fitted pad's height went off in a sawtooth with the level, 0.4 % low at 16-20 px and 0.3 % at
# 20-30, 0.1 % high at 45-64 px, from the labelled pose on renders whose pixels average 3 x 3 samples; drawn
# from 2 x 2 points, 0.06 % or less at every size (3 x 3: 0.07 %).  The fit takes 0.9-1.3 times as long.
SUBSAMPLES = 2
MIN_PIXELS = 120       # compared pixels needed (the pad and its ring of ground, in view)
BLUR_START_PX = 0.7    # the blur's first guess (frame px) ...
BLUR_RANGE_PX = (0.25, 3.0)  # ... and the range it is kept in: a fit whose blur ends at the top fails, the frame
# blurred past what the drawing models (a motion smear of over half a far pad's side: views smeared 16-24 px fitted
# 24-60 px pads 3-21 % of the height off, all at the top; conditions' snow scene, a 26 px smear from a 4 rad/s
# jolt, a 102 px pad 10.6 % off, "ok"; under 12 px of smear no view's blur reached it)
TONE = 2.2             # the tone curve's exponent (written = light ** (1 / it)): sRGB's, as cameras write, unless the
                       # camera's response is known.  Not fitted: the colour gains leave only the edges' profiles to
                       # fix it, and a fitted one took up the model's errors (far_wide's renders: 0.15-0.3 low)
SHARPEN_SIGMA_PX = 1.0  # a camera's own sharpening (an unsharp mask) subtracts a blur this wide (px) ...
SHARPEN_RANGE = (0.0, 1.5)  # ... this many times over (fitted; 0: none)
UNSHARP_ROUNDS = 12    # a known sharpening undone on the frame by this many rounds (each leaves a / (1 + a) of the error)
LIGHT_FLOOR = 1e-3     # light below this (of the brightest) is taken as this: a black marker's grey is noise
ITERATIONS = 10
# A descent has settled when its last step moved the pad's image less than a tenth of its steps (~0.01 px) ...
# ... the tilt less than this share of its doubt (a tenth of a tenth of a px at the corners asked of a 100 px
# pad's tilt took half its iterations, each moving it a twentieth of its doubt) ...
TILT_SETTLED = 0.1
# ... and the blur and the sharpening less than this, on a pad CAMERA_SETTLED_SIDE_PX across, and as much more as the
# pad is larger: the blur moves the fitted size by a share that falls with the side (px) (stopped where they moved
# under 0.1 at every size, one of 18 synthetic JPEG views at 24-62 px, a 32 px pad, ended 2.3 % of the height off
# against 0.35 %; at 66-138 px, 0.02 % or less of where 0.02 ended them)
CAMERA_SETTLED = 0.02
CAMERA_SETTLED_SIDE_PX = 32.0
HUBER_K = 2.0          # residuals beyond this many robust sigmas weigh less (shadows, glare, dirt) ...
# ... but each still pulls, and a far pad's tilt shows only in a few tenths of a pixel of foreshortening: a shadow over
# part of the pad and the ground beside it (the drone's own, under a high sun) outweighed that.  Fuzz seed 545's grey
# 47-58 px pad, fitted from its labelled pose against a 5 degree prior, tilted 3.3-7.8 degrees off stating 1.5-1.7 (two
# false accepts at 2.9-3.2 m).  So where the tilt is fitted, the pixels of a patch of light the drawing does not hold
# count for nothing (:func:`_unexplained`): where the held fit's residual, averaged over a Gaussian of PATCH_SIGMA_PX,
# lies more than PATCH_K robust sigmas (of such averages) off its median.  Fz545's frames then 0.7-1.9 off, stating
# 1.7-2.0.  A shadow is a patch of one sign; a drawing's misfit along an edge is a thin pair of both and averages out.
# Per pixel instead (Tukey's biweight on the residual, 4.7 robust sigmas) the edges' own misfits went with the shadows,
# and a camera pitched 35 degrees off nadir lost what its fitted tilt gave its height (tests: test_a_pitched_cameras_
# far_pad_...); at 8-10 sigmas the shadow's soft edge stayed and tilted a 48 px view 1.4-1.8 degrees
PATCH_SIGMA_PX = 1.5
PATCH_K = 6.0
MIN_NCC = 0.8          # the fitted drawing's correlation with the frame, for the fit to be used
GRAD_PX = 0.25         # the drawing's gradient is its difference this far (ideal px) each way
# The pad's tilt, with the IMU's up as its prior (``up_C``), is fitted too where the pad is this many px across
# or more and the fit's blur at most TILT_MAX_BLUR_PX: with the AHRS's tilt (0.3-0.5 degrees off) held, a camera
# pitched 35 degrees off nadir put its pads 0.45-0.76 % of the height too high at 44-150 px (the fitted size
# follows the tilt's foreshortening), fitted 0.04-0.09 % (unseen104, from the labelled position).  Smaller
# (unseen106's 30-44 px pads, fast, JPEG 60: heights 0.33 % off held, 0.44-0.78 % fitted), or smeared past that
# blur (motion the isotropic blur does not model: a 55 px pad under 5 px of smear fitted its tilt 0.3-0.7
# degrees off), the image tells the tilt worse than the AHRS does
TILT_MIN_SIDE_PX = 44.0
TILT_MAX_BLUR_PX = 1.0
# the residuals of neighbouring pixels are not independent (the blur and the codec spread each error): the image's
# evidence on the tilt is counted once per this many pixels against the prior.  Counted per pixel, unseen106's
# 44-64 px pads came out 0.25 % off in height in the median (held: 0.14 %), at 10 0.18 %; unseen104's as well
TILT_PIXELS_PER_SAMPLE = 10.0
# ... and however many pixels it counts, the drawing is not the pad: stains, glare, wear and relief the design
# does not show move its edges' fitted places by about this much (px) together, which the residuals' scatter
# does not tell.  A tilt shows only in the pad's foreshortening, about its side squared over the focal length
# per radian in px, so that error alone tilts a pad of ``side`` px by DESIGN_MODEL_PX * f / side**2 radians.
# (Random scenes, their design fitted with its tilt from 24 px on untracked tilting decks, 346 fits of 7 scenes:
# the tilt was 3.8 times its stated doubt off at 24-32 px in the median, 1.3-1.8 at 32-300 px, and a dirty
# pad's 31 px view, fitted from the labelled pose, went 3.5 degrees off stating 0.9, 0.6 off its stains
# removed; with this error as well, 0.6-1.3 times in the median at every size, 0-3 % beyond three)
DESIGN_MODEL_PX = 0.1
# ... where the drawing matches the pad as well as it does on most frames: a correlation of DESIGN_MODEL_NCC or
# more.  Below, what the drawing leaves unexplained grows, and the drawing's error with it (as 1 - ncc).
# fz377's grey JPEG 60 pads, 51-54 px at 11 m on a tilting deck, matched at 0.90: tilts stated to 1.6-2.0
# degrees lay 5-7 off (1-1.3 m), and were accepted.  A proxy, and a weak one: 384 fits of 32 random deck
# scenes' 44-140 px pads, each started from and weighed against a tilt 4 degrees off, lay 0.52-0.67 times their
# stated doubt off in the median at a correlation of 0.96 or more, 0.77 at 0.93-0.96, 0.88 at 0.90-0.93 (1.8 %
# beyond three; with this, 1.3 %).  Its cost: far deck frames stated just past the loose-tilt bar (README)
DESIGN_MODEL_NCC = 0.95
LUMA = (0.299, 0.587, 0.114)  # an RGB frame is compared in this mix of its written channels (OpenCV's grey, JPEG's luma)


def _unexplained(r: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(n,) bool: which of the compared pixels (``mask``'s, in row order; their residuals ``r``) lie in
    a patch of light the drawing does not explain (a shadow, a glare, a stain, an occluder): their
    residual averaged over its neighbours (a Gaussian of :data:`PATCH_SIGMA_PX`, within ``mask``)
    lies more than :data:`PATCH_K` robust sigmas of such averages off their median."""
    R = np.zeros(mask.shape, np.float32)
    R[mask] = r
    num = cv2.GaussianBlur(R, (0, 0), PATCH_SIGMA_PX)
    den = cv2.GaussianBlur(mask.astype(np.float32), (0, 0), PATCH_SIGMA_PX)
    local = (num / np.maximum(den, 1e-6))[mask].astype(np.float64)
    dev = np.abs(local - np.median(local))
    return dev > PATCH_K * 1.4826 * float(np.median(dev)) + 1e-12


RESPONSE_FIELDS = (("gamma", None, 0.2, 10.0), ("sharpen", 0.0, 0.0, 10.0), ("sharpen_sigma_px", SHARPEN_SIGMA_PX, 1e-3, 20.0))


def parse_response(value) -> tuple:
    """A camera's photometric response (``camera.json``'s ``response``: ``{gamma, sharpen,
    sharpen_sigma_px}``, or that tuple) as ``(gamma, sharpen, sharpen_sigma_px)``; a
    :class:`ValueError` naming the field no camera's response has."""
    if isinstance(value, dict):
        if "gamma" not in value:
            raise ValueError(f"response must be an object with gamma (and sharpen, sharpen_sigma_px), got {value!r}")
        items = [value.get(k, d) for k, d, _, _ in RESPONSE_FIELDS]
    elif isinstance(value, (tuple, list)) and len(value) in (2, 3):
        items = list(value) + [SHARPEN_SIGMA_PX] * (3 - len(value))
    else:
        raise ValueError(f"response must be an object with gamma (and sharpen, sharpen_sigma_px), got {value!r}")
    for v, (key, _, lo, hi) in zip(items, RESPONSE_FIELDS):
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and lo <= v <= hi) or \
                (key != "sharpen" and v <= 0):
            raise ValueError(f"response.{key} {v!r} is not a camera's (a number in [{lo:g}, {hi:g}])")
    return tuple(float(v) for v in items)


def _design_levels(synth) -> list:
    """The pad's design as four channels, float32: its red, green and blue in linear light and how
    much of each texel is pad (1), box-filtered to halves, quarters,
    ... (kept on ``synth``), each with its own texels per metre.  A frame's brightness is linear in
    the three colours under any light's colour and gain: the magenta border's brightness relative
    to the white field is not one number.  Each level is the whole pad in a whole number of texels,
    box-filtered as a pixel averages (:func:`hvloc.synthesis.box_levels`): with a Gaussian pyramid's
    levels the fitted pad moved sideways by 0.11 % of the height on bench_v2's wide720 at 23-60 px
    (0.03 % with these).
    """
    levels = getattr(synth, "_design_levels", None)
    if levels is None:
        rgb = srgb_to_linear(np.ascontiguousarray(synth.pad.texture_rgb)).astype(np.float32) / 255.0
        levels = box_levels(np.dstack([rgb, np.ones(rgb.shape[:2], np.float32)]), synth.pad.side_m, 16)
        synth._design_levels = levels
    return levels


def _draw(levels: list, synth, camera: Camera, points: np.ndarray, cam2pad: np.ndarray,
          per_px: int = 1, ends=None) -> np.ndarray:
    """``(h, w, 4)``: the design's channels (:func:`_design_levels`) seen from ``cam2pad`` over the
    window's pixels, 0 off the pad: each pixel the mean of its ``per_px`` x ``per_px`` points of
    ``points`` (their ideal pinhole places: :meth:`PadSynthesis.window` at that scale), each read
    from the level whose texels are the finest no smaller than the points' spacing.  ``ends``: a
    rolling shutter's poses at the first and the last row of ``points``, each row seen from its own,
    the map from image to pad linear in the row between them (as :func:`_row_mapped`'s)."""
    H = pad_plane_homography(camera, cam2pad)  # pad (x, y) m -> ideal pixel
    tex, ppm = level_for(levels, synth.pad.side_m, H, per_px)
    K = texture_to_pad(synth.pad.side_m, ppm)
    if ends is None:
        M = np.linalg.inv(H @ K)  # ideal pixel -> texel
        uv = cv2.perspectiveTransform(np.ascontiguousarray(points).reshape(-1, 1, 2), M).reshape(points.shape)
    else:
        q = _row_mapped([np.linalg.inv(pad_plane_homography(camera, T) @ K) for T in ends],  # ideal pixel -> texel
                        points[..., 0].astype(np.float64), points[..., 1].astype(np.float64), 1.0,
                        _row_shares(points.shape[0])[:, None])
        uv = np.dstack([q[0] / q[2], q[1] / q[2]]).astype(np.float32)
    d = cv2.remap(tex, uv, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    if per_px == 1:
        return d
    # (an integer factor's INTER_AREA is the blocks' mean; numpy's mean over two strided axes took 5 times as long)
    return cv2.resize(d, (points.shape[1] // per_px, points.shape[0] // per_px), interpolation=cv2.INTER_AREA)


def _row_shares(rows: int) -> np.ndarray:
    """``(rows,)``: each row's share of the way from the first row to the last (0 to 1)."""
    return np.linspace(0.0, 1.0, rows) if rows > 1 else np.zeros(1)


def _row_mapped(ends: list, x, y, w, share) -> list:
    """``[x', y', w']``: the homogeneous points ``(x, y, w)`` (arrays, or ``w`` a number) each mapped by
    the 3 x 3 map its row sees: the two maps ``ends`` (at the first row and at the last) taken linearly
    from one to the other by its row's ``share`` (broadcast with the points).  A rolling shutter's
    rows see the pad from poses a few ms apart: a map between image and pad is linear in that time
    to first order (a drone turning at 2 rad/s over 15 ms of readout: the second order moves a point
    ~0.01 px)."""
    a, b = (np.asarray(m, np.float64) for m in ends)
    d = b - a
    return [x * (a[i, 0] + share * d[i, 0]) + y * (a[i, 1] + share * d[i, 1]) + w * (a[i, 2] + share * d[i, 2])
            for i in range(3)]


def _posed(T: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``T`` (``T_P_C``) turned by ``q[3]`` about the pad's normal and moved by ``q[:3]`` (pad frame),
    then tilted by ``q[6:8]`` (radians about the pad's x and y axes): the camera carried
    round the pad's centre, so that a tilt changes how the pad is foreshortened, not where it lies."""
    Rz = so3_exp(np.array([0.0, 0.0, q[3]]))
    out = T.copy()
    out[:3, :3] = Rz @ T[:3, :3]
    out[:3, 3] = Rz @ T[:3, 3] + q[:3]
    if q[6] or q[7]:
        Rt = so3_exp(np.array([q[6], q[7], 0.0]))
        out[:3, :3] = Rt @ out[:3, :3]
        out[:3, 3] = Rt @ out[:3, 3]
    return out


def _tilt_to(T: np.ndarray, up_C) -> np.ndarray:
    """``(2,)``: the tilt (:func:`_posed`'s ``q[6:8]``) that turns the pad's normal in the camera, as
    ``T`` (``T_P_C``) has it, onto ``up_C``."""
    u = T[:3, :3] @ (np.asarray(up_C, np.float64) / np.linalg.norm(up_C))  # up_C in the pad's frame
    n = math.hypot(u[0], u[1])
    if n < 1e-12:
        return np.zeros(2)
    return math.atan2(n, u[2]) * np.array([u[1], -u[0]]) / n


def fit_pose_to_design(image: np.ndarray, camera: Camera, synth, cam2pad: np.ndarray, response=None,
                       max_side_px: float = MAX_SIDE_PX, up_C: np.ndarray | None = None,
                       up_sigma_deg: float | None = None, tilt_min_side_px: float = TILT_MIN_SIDE_PX,
                       shutter=None) -> tuple:
    """``(cam2pad | None, info)``: ``cam2pad`` (``T_P_C``) with its position and yaw refined so that
    the pad's design, drawn there (``synth``: :class:`hvloc.synthesis.PadSynthesis`) and blurred,
    best matches ``image`` as the camera wrote it (0-255): RGB ``(H, W, 3)``, compared in its luma
    (:data:`LUMA`), or a grey camera's ``(H, W)``.  ``info``: the blur (px),
    and sharpening fitted, the drawing's correlation with the frame, the residual's RMS, the
    pixels compared, iterations, the pad's side (px) at the start.  None (``info["why"]``) for a pad outside :data:`MIN_SIDE_PX` - ``max_side_px`` across,
    too little of it in view, or a drawing that matches the frame poorly (:data:`MIN_NCC`).

    ``response``: the camera's photometric calibration where it is known, ``(gamma, sharpen[,
    sigma])``: its tone curve's exponent (written = light ** (1 / gamma)) and its own sharpening, an
    unsharp mask (a Gaussian of ``sigma`` px, :data:`SHARPEN_SIGMA_PX` unless given) of the values
    it writes (``camera.json``'s ``response``).
    Both move a far pad's fitted size: blurred, an edge's profile as written depends on the tone,
    and the mask's overshoot on the side it falls.  Unknown, sRGB's exponent is taken and a
    sharpening is fitted in light, which stands in for it (far_wide's renders: a camera's exponent
    2.02 or 2.40 and a 0.35-0.45 mask put the pad 0.3-0.9 % too near from the labelled pose;
    known, 0.0-0.5 %, as an unsharpened sRGB camera's).

    ``up_C``, ``up_sigma_deg``: the IMU's up in the camera and how far the pad's normal may lie from it
    (one sigma).  Where the pad is ``tilt_min_side_px`` (:data:`TILT_MIN_SIDE_PX` unless given) or
    more across and sharp enough (:data:`TILT_MAX_BLUR_PX`), the pad's tilt is then fitted too, weighed
    against that prior, once the pose with the start's tilt held has settled (``info["tilt_deg"]``: how
    far it moved from the start's, about the pad's x and y axes; ``info["tilt_sigma_deg"]``: its doubt,
    the image's with the drawing's own error, :data:`DESIGN_MODEL_PX`, and the prior's).  Without them
    the start's tilt is held.

    ``shutter``: a rolling shutter's ``(line_s, ref_row, twist)`` (hvloc.shutter: row ``r`` seen at
    ``(r - ref_row) * line_s`` from the frame's time, the camera moving by the Twist: the gyro's turn,
    the velocity where known): each row drawn from the pose its time saw, ``cam2pad`` and the pose
    returned the reference row's (``info["rolled"]``).  A frame's turn while its rows are read skews a far pad as a tilt
    does: drawn as one instant, 50-90 px pads read in 30 ms while the drone turned at 0.6-2.7 rad/s
    were fitted 0.8-6.4 degrees off in tilt and 1.4-11 % of the height off, row by row within 0.25
    degrees and 0.5 % (tests/test_shutter.py); each iteration costs ~1.5 times a global shutter's."""
    info: dict = {}
    half = synth.pad.side_m / 2.0
    outer = np.array([[-half, half, 0.0], [half, half, 0.0], [half, -half, 0.0], [-half, -half, 0.0]])
    quad = camera.project_from(cam2pad, outer)
    if quad is None or not np.isfinite(quad).all():
        return None, {"why": "pad not in front of the camera"}
    side_px = float(np.mean(np.linalg.norm(quad - np.roll(quad, 1, axis=0), axis=1)))
    m = 3.0 * BLUR_RANGE_PX[1]
    lo, hi = quad.min(axis=0) - m, quad.max(axis=0) + m
    box = (max(0, int(math.floor(lo[0]))), max(0, int(math.floor(lo[1]))),
           min(camera.width, int(math.ceil(hi[0]))), min(camera.height, int(math.ceil(hi[1]))))
    if box[2] - box[0] < 8 or box[3] - box[1] < 8:
        return None, {"why": "pad out of view"}
    if not MIN_SIDE_PX <= side_px <= max_side_px:
        return None, {"why": f"the pad is {side_px:.0f} px across (fitted at {MIN_SIDE_PX:.0f}-{max_side_px:.0f})"}
    fine = synth.window(camera, box, float(SUBSAMPLES), own=True)  # the points each pixel is drawn from ...
    # ... and each pixel's centre, their mean (a pinhole's exactly; through a k1 -0.25 lens within 1.2e-4 px:
    # undistorted a second time, 30-160 px windows cost their fit 0.4-4.3 ms more)
    grid = cv2.resize(fine, (box[2] - box[0], box[3] - box[1]), interpolation=cv2.INTER_AREA)
    img = np.asarray(image[box[1]:box[3], box[0]:box[2]], np.float64) / 255.0
    img = img.reshape(img.shape[0], img.shape[1], -1)
    luma = np.array(LUMA) if img.shape[2] == 3 else np.full(img.shape[2], 1.0 / img.shape[2])  # a grey camera: its one channel
    levels = _design_levels(synth)
    # a rolling shutter (``shutter``: its line time, its reference row and the camera's motion, a
    # hvloc.shutter.Twist, where known): each row drawn as seen at its own time
    rolling = shutter is not None and bool(shutter[0]) and shutter[2] is not None \
        and not (shutter[2].v_P is None and shutter[2].w_C is None)

    def at_rows(q, first: float, last: float) -> tuple | None:
        """q's pose as seen by the window's image rows ``first`` and ``last`` (frame rows), or ``None``
        for a global shutter (:func:`_draw`'s ``ends``)."""
        if not rolling:
            return None
        T = _posed(cam2pad, q)
        return tuple(shutter[2].moved(T, (y - shutter[1]) * shutter[0]) for y in (first, last))

    fine_rows = (box[1] + 0.5 / SUBSAMPLES - 0.5, box[1] + (fine.shape[0] - 0.5) / SUBSAMPLES - 0.5)  # their frame rows

    def draw(q, pts=fine):
        """The design's channels over the window's pixels (:func:`_draw`) at q's pose, each row at its time."""
        return _draw(levels, synth, camera, pts, _posed(cam2pad, q), SUBSAMPLES, at_rows(q, *fine_rows))

    inside = (draw(np.zeros(8))[..., 3] > 0.5).astype(np.uint8)
    # compared: the pad and a ring of ground around it (the border's outer edge is seen against
    # the ground, whose mean brightness is fitted with the pad's), within the window
    ring = int(math.ceil(3.0 * BLUR_START_PX)) + 1
    mask = cv2.dilate(inside, np.ones((2 * ring + 1, 2 * ring + 1), np.uint8)) > 0
    n = int(mask.sum())
    if n < MIN_PIXELS:
        return None, {"why": f"{n} pixels near the pad (< {MIN_PIXELS})"}
    known = response is not None
    tone, amount, sharp_sigma = parse_response(response) if known else (TONE, 0.0, SHARPEN_SIGMA_PX)
    # the pixels modelled: those compared, or with a known sharpening the whole window (its blur
    # reaches past them); ``at``: the compared among the modelled
    sel = np.ones_like(mask) if amount > 0 else mask
    at = mask[sel] if amount > 0 else slice(None)
    target = img[mask]  # (n, channels) as written
    seen = target @ luma  # the luma compared
    # ... and each channel in light, the gains' target: where the camera sharpened, as it was before
    # (the mask undone: x = (written + a G(x)) / (1 + a), a contraction; solved on the sharpened
    # values, the gains took the mask's halos for the pad's levels and the pad came out 0.1 % small)
    unsharp = img.astype(np.float32)
    for _ in range(UNSHARP_ROUNDS if amount > 0 else 0):
        unsharp = (img + amount * cv2.GaussianBlur(unsharp, (0, 0), sharp_sigma).reshape(img.shape)) / (1.0 + amount)
    target_light = np.clip(unsharp[mask], 0.0, 1.0) ** tone
    depth = max(float(invert(cam2pad)[2, 3]), 1e-3)
    m_per_px = depth / camera.fx
    # the pose parameters' steps for the image motion they cause: a tenth of a px at the pad
    # (and the tilt's: about a tenth of a px at the pad's corners on the foreshortening)
    turn = 0.1 / max(side_px / 2.0, 1e-6)
    steps = np.array([0.1 * m_per_px, 0.1 * m_per_px, 0.1 * m_per_px * depth / half, turn, turn, turn])
    POSE = (0, 1, 2, 3, 6, 7)  # q's pose parameters (4, 5: the blur and the sharpening)
    ideal = np.column_stack([grid[sel].astype(np.float64), np.ones(int(sel.sum()))])  # the modelled pixels' ideal places
    row_share = _row_shares(sel.shape[0])[np.nonzero(sel)[0]]  # (their rows' shares of the window's: _row_mapped)

    def homographies(q) -> list:
        """The pad (x, y) -> ideal pixel homographies at q's pose as the window's first and last rows saw
        it (a rolling shutter's: :func:`_row_mapped` takes each modelled pixel's between them)."""
        return [pad_plane_homography(camera, T) for T in at_rows(q, box[1], box[3] - 1)]

    def written(t):
        """Toned values ``t`` (modelled pixels, channels) as the camera writes them: sharpened by
        ``amount`` where its sharpening is known (a mask of the written values, not of light)."""
        if amount <= 0:
            return t
        win = t.reshape(mask.shape + (-1,)).astype(np.float32)
        return (1.0 + amount) * t - amount * cv2.GaussianBlur(win, (0, 0), sharp_sigma).reshape(t.shape)

    def drawn(q):
        """``(D, B1, B2)``, each ``(h, w, 4)``: the design's channels at q's pose blurred as the camera
        does (:func:`blurred`)."""
        return blurred(draw(q), q)

    def blurred(d, q):
        """``(D, B1, B2)``: drawn channels ``d`` blurred as the camera does, ``D = B1 + a (B1 - B2)``:
        ``B1`` by q's blur, ``B2`` by that and the sharpening's own width (:data:`SHARPEN_SIGMA_PX`),
        ``a = q[5]`` the sharpening's amount.  Linear in ``d``."""
        sig = max(q[4], 0.05)
        b1 = cv2.GaussianBlur(d, (0, 0), sig)
        b2 = cv2.GaussianBlur(d, (0, 0), math.hypot(sig, SHARPEN_SIGMA_PX))
        return b1 + np.float32(q[5]) * (b1 - b2), b1, b2

    def toned(d):
        """The frame's luma less the drawing's, both as the camera wrote them.  Each of the camera's
        channels is linear in light (the design's red, green and blue, the ground's, an offset:
        solved on that channel taken to light through the tone curve) and toned on its own; the
        luma mixes the toned channels.  A luma taken to light as one channel is not linear in the
        design's colours: blurred, the magenta border's edges were drawn where the camera does not
        put them (synthetic 35 px pads under 0.6-1.5 px of blur: 0.4-1.0 % too near)."""
        A = np.column_stack([d[:, 0], d[:, 1], d[:, 2], 1.0 - d[:, 3], np.ones(len(d))])
        g, *_ = np.linalg.lstsq(A[at], target_light, rcond=None)  # (5, channels)
        light = np.maximum(A @ g, LIGHT_FLOOR)  # (the tone curve's slope is unbounded at black)
        return seen - (written(light ** (1.0 / tone)) @ luma)[at], A, g, light

    def jacobian(q, DB, A, g, light, tilt):
        """``(n, 8)``: the residuals' derivatives.  The pose's four (six with the ``tilt``) from
        the drawing's gradient and the image motion each parameter causes at each pixel's pad point;
        the blur's from the drawings' Laplacians (a Gaussian's width grows as the heat equation
        says); the sharpening's from the two blurs' difference.  Each carries the change of the brightness solved with it
        (the gains are least squares in light, not in the residual's terms: held fixed, the
        Jacobian's columns correlated 0.2-0.5 with the residual's true change)."""
        _, B1, B2 = DB
        if rolling:  # each modelled pixel's pad point, as its row saw it
            X = np.column_stack(_row_mapped([np.linalg.inv(H) for H in homographies(q)], ideal[:, 0], ideal[:, 1],
                                            1.0, row_share))
        else:
            X = np.linalg.solve(pad_plane_homography(camera, _posed(cam2pad, q)), ideal.T).T
        # the drawing's gradient in the ideal image, from drawings a quarter px off each way, blurred
        # once (the blur is linear): the grid's own differences of a drawing blurred by under a px are
        # not its derivative (the pose's columns correlated 0.6-0.7 with the residual's true change)
        off = [draw(q, fine + np.float32(o)) for o in ((GRAD_PX, 0.0), (-GRAD_PX, 0.0), (0.0, GRAD_PX), (0.0, -GRAD_PX))]
        grad = blurred(np.concatenate([off[0] - off[1], off[2] - off[3]], axis=2) / np.float32(2 * GRAD_PX), q)[0]
        gx, gy = grad[..., :4][sel].astype(np.float64), grad[..., 4:][sel].astype(np.float64)
        sig = max(q[4], 0.05)
        lap = sig * ((1.0 + q[5]) * cv2.Laplacian(B1, cv2.CV_32F, ksize=1)[sel].astype(np.float64)
                     - q[5] * cv2.Laplacian(B2, cv2.CV_32F, ksize=1)[sel].astype(np.float64))
        # (n, channels): the tone curve's slope; 0 where the light was floored (the residual does not
        # move there: the slope at the floor, ~20, made the Jacobian's columns 2-4 times too long)
        slope = np.where(light > LIGHT_FLOOR, light ** (1.0 / tone - 1.0) / tone, 0.0)

        Ac = A[at]
        lit = target_light - Ac @ g  # (n, channels): what the gains leave of each channel in light
        AtA_inv = np.linalg.pinv(Ac.T @ Ac)

        # a change ``dd`` of the drawn channels changes the design matrix A by ``[dd0, dd1, dd2, -dd3, 0]``
        # (toned's columns), and A @ g by dd @ g4: taken so, without building that change (3.5 times faster)
        g4 = g[:4] * np.array([[1.0], [1.0], [1.0], [-1.0]])

        def of(dd):  # the residuals' change for a change ``dd`` (modelled pixels, 4) of the drawn channels
            moved = dd @ g4  # the change of A @ g
            dAt_lit = np.zeros_like(g)
            dAt_lit[:4] = dd[at].T @ lit
            dAt_lit[3] = -dAt_lit[3]
            dg = AtA_inv @ (dAt_lit - Ac.T @ moved[at])  # the gains' change (the normal equations')
            return -(written(slope * (moved + A @ dg)) @ luma)[at]

        J = np.zeros((n, len(q)))
        for i, k in enumerate(POSE):  # each pose parameter moves the pad points' ideal images
            if k >= 6 and not tilt:
                continue
            dq = np.zeros(len(q))
            dq[k] = steps[i]
            moved = np.column_stack(_row_mapped(homographies(q + dq), X[:, 0], X[:, 1], X[:, 2], row_share)) \
                if rolling else X @ pad_plane_homography(camera, _posed(cam2pad, q + dq)).T
            flow = (moved[:, :2] / moved[:, 2:3] - ideal[:, :2]) / steps[i]
            J[:, k] = of(-(gx * flow[:, :1] + gy * flow[:, 1:]))
        J[:, 4] = of(lap)
        J[:, 5] = of((B1 - B2)[sel].astype(np.float64))
        return J

    camera_settled = CAMERA_SETTLED * max(1.0, side_px / CAMERA_SETTLED_SIDE_PX)
    model = DESIGN_MODEL_PX * float(camera.fx) / side_px ** 2  # the drawing's own error as a tilt (radians)

    def tilt_doubt(info_matrix: np.ndarray, prior: float):
        """The tilt's doubt (radians, one sigma along its worst axis) from the normal equations'
        information (the tilt's two parameters last, with ``prior`` per radian squared of its prior's
        in them): the image's alone, marginal over the other parameters, with the drawing's own error
        (``model``) added, then the prior's again; ``None`` where that is singular."""
        try:
            C = np.linalg.inv(info_matrix)[-2:, -2:]
            image = np.linalg.inv(np.linalg.inv(C) - prior * np.eye(2)) + model ** 2 * np.eye(2)
            worst = float(np.linalg.eigvalsh(np.linalg.inv(np.linalg.inv(image) + prior * np.eye(2))).max())
        except np.linalg.LinAlgError:
            return None
        return math.sqrt(worst) if worst > 0 and math.isfinite(worst) else None

    def descend(state, tilt: bool, drop=None):
        """Levenberg-Marquardt from ``state`` (``(q, DB, r, A, g, light)``), the tilt (``q[6:8]``)
        fitted or held, the pixels ``drop`` (bool over the compared, :func:`_unexplained`) left out;
        returns the last state, the iterations taken and the tilt's doubt (radians, one sigma along
        its worst axis: :func:`tilt_doubt`; ``None`` when held)."""
        q, DB, r, A, g, light = state
        # the tilt's prior (centred on the IMU's, ``q0``), in the residuals' units: their robust variance
        # per sample (TILT_PIXELS_PER_SAMPLE)
        prior = TILT_PIXELS_PER_SAMPLE / math.radians(up_sigma_deg) ** 2 if tilt else 0.0
        lam = 1e-3
        it = 0
        doubt = None
        settled = False
        for it in range(1, ITERATIONS + 1):
            s = 1.4826 * float(np.median(np.abs(r))) + 1e-9
            w = np.where(np.abs(r) <= HUBER_K * s, 1.0, HUBER_K * s / np.maximum(np.abs(r), 1e-12))
            if drop is not None:
                w = np.where(drop, 0.0, w)
            J = jacobian(q, DB, A, g, light, tilt)
            N = J.T @ (J * w[:, None])
            b = J.T @ (w * r)
            pw = prior * s * s
            N[6:8, 6:8] += pw * np.eye(2)
            b[6:8] += pw * (q[6:8] - q0)
            cost = float(np.sum(w * r * r)) + pw * float((q[6:8] - q0) @ (q[6:8] - q0))
            # a camera parameter at the end of its range that the descent would push past is held there
            # this step: clipped after the solve, its step would spoil the others' (the pose stopped
            # where it started whenever the sharpening sat at 0)
            free = np.ones(len(q), bool)
            for k, (lo, hi) in ((4, BLUR_RANGE_PX), (5, SHARPEN_RANGE)):
                free[k] = not ((q[k] <= lo and b[k] > 0) or (q[k] >= hi and b[k] < 0))
            free[5] &= not known  # (a known sharpening is the camera's, in its written values)
            free[6:8] = tilt
            if tilt:
                unit = TILT_PIXELS_PER_SAMPLE * s * s  # the residuals' variance per sample
                doubt = tilt_doubt(N[np.ix_(free, free)] / unit, pw / unit)
            moved = False
            for _ in range(8):
                dq = np.zeros(len(q))
                try:
                    Nf = N[np.ix_(free, free)]
                    dq[free] = -np.linalg.solve(Nf + lam * np.diag(np.diag(Nf) + 1e-12), b[free])
                except np.linalg.LinAlgError:
                    break
                qn = q + dq
                qn[4] = float(np.clip(qn[4], *BLUR_RANGE_PX))
                qn[5] = float(np.clip(qn[5], *SHARPEN_RANGE))
                DBn = drawn(qn)
                rn, An, gn, ln = toned(DBn[0][sel].astype(np.float64))
                if float(np.sum(w * rn * rn)) + pw * float((qn[6:8] - q0) @ (qn[6:8] - q0)) < cost:
                    q, DB, r, A, g, light, moved = qn, DBn, rn, An, gn, ln, True
                    lam = max(lam / 10.0, 1e-9)
                    break
                lam *= 10.0
            tol = 0.1 * steps
            if doubt is not None:  # (the tilt's to a share of its doubt)
                tol[4:] = np.maximum(tol[4:], TILT_SETTLED * doubt)
            if not moved or (np.all(np.abs(dq[list(POSE)]) < tol) and np.all(np.abs(dq[4:6]) < camera_settled)):  # settled
                settled = True
                break
        if doubt is not None and not settled:
            # stopped at ITERATIONS with the tilt still moving: it is known no better than its last step
            # (fz531's 40 px deck pad moved 2.4 degrees in its last, stating 1.9 degrees, and lay 4.9-5.5 off;
            # the nine other tilts stopped so over 18 random deck scenes had last moved 0.22 degrees at most)
            doubt = math.hypot(doubt, float(np.linalg.norm(dq[6:8])))
        return (q, DB, r, A, g, light), it, doubt

    q = np.array([0.0, 0.0, 0.0, 0.0, BLUR_START_PX, 0.0, 0.0, 0.0])
    q0 = np.zeros(2)
    DB = drawn(q)
    on = inside[mask] > 0  # the correlation on the pad alone

    def correlation(r) -> float:
        """The fitted drawing's correlation with the frame's luma on the pad, its residual ``r``."""
        return _ncc(seen[on] - r[on], seen[on])  # (the drawing's luma, the frame's)

    state, it, _ = descend((q, DB) + toned(DB[0][sel].astype(np.float64)), False)
    q, doubt = state[0], None
    if up_C is not None and up_sigma_deg and side_px >= tilt_min_side_px and q[4] <= TILT_MAX_BLUR_PX:
        q0 = _tilt_to(_posed(cam2pad, q), up_C)
        # the drawing's own error, as far as the held fit shows it matching the pad (DESIGN_MODEL_NCC)
        model *= max(1.0, (1.0 - correlation(state[2])) / (1.0 - DESIGN_MODEL_NCC))
        state, more, doubt = descend(state, True, _unexplained(state[2], mask) if PATCH_K > 0 else None)
        q, it = state[0], it + more
    r = state[2]
    ncc = correlation(r)
    info = {"blur_px": round(float(q[4]), 3), "sharpen": round(amount if known else float(q[5]), 3), "ncc": round(ncc, 3), "rms": round(float(np.sqrt(np.mean(r ** 2))), 5), "pixels": n, "iterations": it,
            "side_px": round(side_px, 2)}
    if rolling:
        info["rolled"] = True  # (each row drawn at its own time: the pose is the reference row's)
    if q[6] or q[7]:
        info["tilt_deg"] = [round(math.degrees(float(x)), 3) for x in q[6:8]]
        info["tilt_sigma_deg"] = round(math.degrees(min(doubt, math.radians(up_sigma_deg))), 4) \
            if doubt is not None and math.isfinite(doubt) else up_sigma_deg
    if not np.isfinite(q).all() or ncc < MIN_NCC:
        info["why"] = f"the drawing matches the frame poorly (correlation {ncc:.2f} < {MIN_NCC})"
        return None, info
    if q[4] >= BLUR_RANGE_PX[1]:
        info["why"] = f"blurred past what the drawing models (its blur at the top of its range, {BLUR_RANGE_PX[1]:g} px)"
        return None, info
    return _posed(cam2pad, q), info
