"""Dataset specs: validated pydantic models (unknown keys rejected), loaded from YAML.

Lengths in metres, times in seconds, angles in degrees *in specs only* (people write specs);
everything is converted to radians where it is used.  A range is written ``[lo, hi]``.
"""
from __future__ import annotations

import hashlib
import json
import math
from typing import Annotated, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, model_validator

from hvloc.geometry import CAMERA_MODELS, Camera, focal_from_hfov, focal_from_hfov_equidistant
from pad_design.errors import load_yaml_model
from pad_design.spec import PadSpec


# Bumped when a change to the generator changes what an existing spec renders (not a new field, whose
# default renders as before): a spec's identity (DatasetSpec.sha256) includes it, so cached datasets
# and frozen suites of the old renderer are not taken for the new one's.
#   2: distractors keep their whole footprint, not only their centre, keep_clear_m from the pad; the
#      drone's shadow no longer darkens a box's or the platform's shadow a second time; no glare on
#      a glossy pad where a shadow lies on it.
#   3: a wrinkled glossy pad's glare follows its facets' normals.  Only specs that can draw such a
#      pad render differently: every other spec keeps revision 2 in its identity (render_revision()).
#   4: a glossy or wrinkled pad's light reaches the pixels its edge crosses by their share (it was
#      all or nothing at the pixel's centre: a saturated unlit ring around a glaring pad), and the
#      subframe reference blur draws the pad's material too.  Only specs with such a pad move.
#   5: the sun's visibility over a glossy or wrinkled pad (the drone's and the boxes' shadows on it)
#      is computed in float32, 2x faster: a pixel within micrometres of a shadow's edge may change
#      side; and such a pad's light factor is multiplied into the ground detail's before the image
#      is (one pass less; the pixels both touch, at the pad's edge, may round differently).  Only
#      specs with such a pad move.
#   6: asphalt and concrete are pavement as real nadir frames show it at 3.5-52.5 mm per pixel
#      (stones of 3-18 mm in a lighter grey asphalt, grains and pores of 1.5-8 mm in concrete;
#      benchmarks/realism.py), not a scale-free mottle.  Only specs one of whose sequences draws
#      asphalt or concrete move.
#   7: the ground's detail is read as a camera sees it: two mipmap levels blended (trilinear, a
#      level finer by half: a pixel integrates a box, not a bilinear tent), where the finer level
#      alone made the ground up to twice as sharp as it should be and its detail jump where the
#      level changed; one octave more (0.125 m: detail down to 0.25 mm); grass, dry grass, asphalt
#      and concrete matched again to real frames at their own GSDs.  Every spec with ground detail
#      moves, and those without it that draw grass or dry grass (their rasterised texture).
#   8: asphalt is its aggregate alone: its detail's octaves of 1 m and more per tile, and the
#      coarse octaves of its rasterised texture, copied the aggregate as stones of 1-28 cm, which
#      gave field1080's camera 332 strong corners per 256 px patch from 15 m where real asphalt
#      shows 3; its finest octave weighs 1.6 (benchmarks/realism.py, eight draws).  Only specs one
#      of whose sequences draws asphalt move, with or without ground detail.
#   9: the drone's shadow past a platform's edge; a turning deck's platform shadow.
#  10: distractors drawn at random keep keep_clear_m from a moving platform's whole path, not only
#      from where the pad starts (the deck drove through a box, the pad under it).  Only specs with a
#      platform velocity and distractors drawn at random move.
#  11: distractors drawn at random keep clear of the platform's solid too (its half-diagonal from the
#      pad centre), where keep_clear_m was less: a box stood through the platform, a patch or a
#      marker under it.  Only specs with a platform, distractors drawn at random and keep_clear_m under
#      the platform's half-diagonal move (none of the shipped specs).
#  12: the whole chain mixes light by default (camera.mix_in_light, now true): textures, their mipmaps
#      and filtering, the pad's soft edge, shadows and the supersampled pixels average light, as a
#      camera's pixel sums it, where they averaged 8-bit display values (a far pad's fine pattern came
#      out darker than its light, its edges where the localizer's fits expected them).  Every spec
#      that does not ask for mix_in_light: false moves; one that does renders as its old revision did.
#  13: the camera's sharpening clips its undershoot at black, as a camera does: it was written as its
#      absolute value, a grey halo (38 of 255 beside white under a 0.5 mask) on the dark side of every strong
#      edge, the finder markers' black modules brighter along their white.  Only specs that sharpen move.
#  14: flights are joined from minimum-snap moves, not minimum-jerk ones: the body's rate follows the
#      jerk, which stepped at every join (keyframes, the end of a lateral move, the gusts' fade), so the
#      rate jumped by up to 4.7 rad/s between two IMU rows and one frame was smeared 30 px behind a
#      sharp one.  Every descent's height profile is such a move, so every spec moves,
#      and the per-spec revisions of 2-13 (each kept by the specs a change did not reach) are gone.
RENDER_REVISION = 14


def render_revision(spec: "DatasetSpec") -> int:
    """The last renderer revision that changed what ``spec`` renders (what its identity includes).
    Revision 14 changed every spec's flight; a later revision that moves only some specs returns 14
    for the others."""
    return RENDER_REVISION


def _range_ok(v):
    lo, hi = v
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ValueError("range bounds must be finite")
    if lo > hi:
        raise ValueError(f"range low end {lo} exceeds its high end {hi}")
    return (float(lo), float(hi))


Range = Annotated[tuple[float, float], AfterValidator(_range_ok)]


def _nonneg_range(v):
    if v[0] < 0:
        raise ValueError(f"range must be non-negative, got {list(v)}")
    return v


NonNegRange = Annotated[Range, AfterValidator(_nonneg_range)]


def _positive_range(v):
    if v[0] <= 0:
        raise ValueError(f"range must be positive, got {list(v)}")
    return v


PositiveRange = Annotated[Range, AfterValidator(_positive_range)]
IntRange = Annotated[tuple[int, int], AfterValidator(lambda v: tuple(int(x) for x in _range_ok(v)))]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, validate_default=True)


class MountSpec(_Model):
    """``T_B_C``: camera in the body frame (FLU).  Default: looking straight down, image top forward."""

    xyz_m: tuple[float, float, float] = (0.0, 0.0, -0.05)
    rpy_deg: tuple[float, float, float] = Field(
        (180.0, 0.0, -90.0), description="the camera's rotation in the body, R_B_C = Rz(yaw) Ry(pitch) Rx(roll); "
        "the default looks straight down with the image top forward; [180 + a, 0, -90] tilts the optical axis "
        "a degrees forward of nadir")

    def transform(self):
        """``T_B_C`` (4, 4): camera (OpenCV) to body (FLU)."""
        from hvloc.geometry import make_transform, so3_exp

        r, p, y = (math.radians(v) for v in self.rpy_deg)
        return make_transform(so3_exp([0, 0, y]) @ so3_exp([0, p, 0]) @ so3_exp([r, 0, 0]), self.xyz_m)


class CameraSpec(_Model):
    width: int = Field(800, ge=16, le=8192)
    height: int = Field(800, ge=16, le=8192)
    model: Literal["pinhole", "fisheye"] = Field(
        "pinhole", description="lens model: pinhole (OpenCV radial-tangential, dist k1 k2 p1 p2 k3) or fisheye "
        "(OpenCV fisheye / Kannala-Brandt, dist k1 k2 k3 k4; rays up to 80 degrees off the axis)")
    hfov_deg: float = Field(60.0, gt=1.0, lt=170.0, description="horizontal field of view that sets fx: of the "
                            "pinhole (fx = w/2 / tan(hfov/2)), or for fisheye of the equidistant projection "
                            "(fx = w/2 / (hfov/2 in radians)) before its k terms")
    fy_over_fx: float = Field(1.0, gt=0.2, lt=5.0)
    principal_offset_px: tuple[float, float] = Field((0.0, 0.0), description="(cx, cy) minus the image centre")
    dist: Annotated[tuple[float, ...], Field(min_length=4, max_length=5)] | None = Field(
        None, description="distortion coefficients of the model: pinhole k1 k2 p1 p2 k3, fisheye k1 k2 k3 k4 "
        "(none: no distortion)")
    fps: float = Field(30.0, gt=0.0, le=1000.0)
    exposure_s: float = Field(0.004, ge=0.0, description="shutter open time, centred on the frame time")
    supersample: int = Field(1, ge=1, le=4, description="render at this many times the resolution, then average, as a "
                             "camera's pixel sums light; at 1 the GPU reads a far pad's texture between two mipmap "
                             "levels instead, and a design fit's far heights move by up to 0.4 % with it (2 costs "
                             "1.3-1.5x the render time at 720p; README, \"What `supersample: 1` renders are not\")")
    mix_in_light: bool = Field(True, description="mix texels, edges and the supersampled pixels in linear light, "
                               "as a camera's pixel sums light (float textures and framebuffer); false: in 8-bit "
                               "display values, as revisions up to 11 did (a far pad's fine pattern darker than its "
                               "light, its edges moved): to reproduce an old dataset")
    rolling_shutter_line_s: float = Field(0.0, ge=0.0, description="time between the exposures of consecutive rows "
                                          "(0: global shutter); the frame's time and labels are those of its middle row")
    vignetting: NonNegRange = Field((0.0, 0.0), description="light lost at the image corners (0.3: 30 %, falling "
                                    "off with the square of the distance from the centre)")
    chromatic_aberration_px: NonNegRange = Field((0.0, 0.0), description="lateral chromatic aberration: red and "
                                                 "blue displaced by this much, outward and inward, at the corners")
    mono: bool = Field(False, description="a monochrome sensor (no colour filter array): one channel, the linear "
                       "light summed with Rec. 709's weights, written as grey RGB (R = G = B); its JPEG is grey")
    auto_exposure_lag_s: float | None = Field(None, gt=0.0, description="auto exposure: the gain follows the scene's "
                                              "brightness with this time constant (None: fixed exposure)")
    response_known: bool = Field(False, description="write the camera's photometric response into camera.json "
                                 "(`response`: its tone curve's exponent and in-camera sharpening, drawn per "
                                 "sequence), as a photometric calibration gives it: localizers may use it (hvloc's "
                                 "far-pad design fit does); false: a camera whose response is not known")
    mount: MountSpec = MountSpec()
    # timing as real systems have it
    frame_time_jitter_s: float = Field(0.0, ge=0.0, description="std of each frame's capture time around k / fps "
                                       "(clipped to 0.4 / fps); frames.csv's t is the true capture time")
    frame_drop_rate: float = Field(0.0, ge=0.0, le=0.5, description="share of frames lost (never the first or the "
                                   "last): their rows and images are missing, frame indices keep their gaps")

    @model_validator(mode="after")
    def _exposure(self):
        if self.exposure_s > 1.0 / self.fps:
            raise ValueError(f"exposure_s: {self.exposure_s} s is longer than a frame (1/fps = {1 / self.fps:.4f} s)")
        if self.rolling_shutter_line_s * self.height > 1.0 / self.fps:
            raise ValueError(f"rolling_shutter_line_s: {self.height} rows take longer than a frame to read")
        n = CAMERA_MODELS[self.model]
        if self.dist is None:
            object.__setattr__(self, "dist", (0.0,) * n)
        if len(self.dist) != n:
            raise ValueError(f"dist: the {self.model} model has {n} coefficients "
                             f"({'k1 k2 p1 p2 k3' if n == 5 else 'k1 k2 k3 k4'}), got {len(self.dist)}")
        if not all(math.isfinite(v) for v in self.dist):
            raise ValueError(f"dist: {list(self.dist)} has a value that is not finite")
        # the lens must map a ray to every pixel out to the image corners: its radial mapping may not
        # fold back before them (and a fisheye's corner ray must stay within 80 degrees of the axis,
        # so that the pinhole render it is resampled from stays practical)
        f = self.focal_px()
        r_corner = math.hypot(self.width / 2.0, self.height / 2.0) / f * max(1.0, 1.0 / self.fy_over_fx)
        if self.model == "fisheye":
            k1, k2, k3, k4 = self.dist
            th = [i * 0.001 for i in range(1, 1396)]  # up to 80 degrees
            r_d = [t * (1 + k1 * t**2 + k2 * t**4 + k3 * t**6 + k4 * t**8) for t in th]
            what = "fisheye distortion"
        else:
            k1, k2, _, _, k3 = self.dist
            r = [i * 0.01 for i in range(1, 1000)]
            r_d = [x * (1 + k1 * x**2 + k2 * x**4 + k3 * x**6) for x in r]
            what = "radial distortion"
        reach = 0.0
        for a, b in zip(r_d, r_d[1:]):
            if b <= a:
                break
            reach = b
        if reach < r_corner * 1.02:
            raise ValueError(f"dist: the {what} {list(self.dist)} does not reach the image corners with hfov_deg "
                             f"{self.hfov_deg} (it folds back or passes 80 degrees at r = {reach:.2f}, the corners "
                             f"need {r_corner:.2f}): not a lens that can be rendered")
        return self

    def focal_px(self) -> float:
        """fx of this camera (see ``hfov_deg``)."""
        h = math.radians(self.hfov_deg)
        return focal_from_hfov(self.width, h) if self.model == "pinhole" else focal_from_hfov_equidistant(self.width, h)

    def to_camera(self) -> Camera:
        """The :class:`hvloc.geometry.Camera` this spec describes."""
        f = self.focal_px()
        return Camera(self.width, self.height, f, f * self.fy_over_fx,
                      (self.width - 1) / 2.0 + self.principal_offset_px[0],
                      (self.height - 1) / 2.0 + self.principal_offset_px[1], tuple(self.dist), self.model)


DECK_CLEARANCE_M = 0.02  # a moving deck's top stays this far above the ground at its lowest


class PlatformSpec(_Model):
    height_m: float = Field(0.0, ge=0.0, le=50.0, description="pad surface above the ground")
    size_m: float = Field(1.2, gt=0.0, description="side of the platform's top (a box is drawn only where "
                          "height_m is above 0)")
    velocity_mps: tuple[float, float] = Field((0.0, 0.0), description="constant platform velocity (east, north)")
    # a ship's deck: each motion a sinusoid of its own period, its phase drawn per sequence; the
    # descent follows the heave (heights stay above the pad's centre), not the roll, pitch and yaw
    roll_deg: float = Field(0.0, ge=0.0, le=20.0, description="deck roll amplitude: the pad tilts about its x axis")
    pitch_deg: float = Field(0.0, ge=0.0, le=20.0, description="deck pitch amplitude: the pad tilts about its y axis")
    heave_m: float = Field(0.0, ge=0.0, le=5.0, description="deck heave amplitude (up and down)")
    yaw_deg: float = Field(0.0, ge=0.0, le=30.0, description="deck yaw amplitude: the pad turns about its normal "
                           "(a ship's yawing about its course)")
    roll_period_s: float = Field(8.0, ge=2.0, le=60.0, description="deck roll period")
    pitch_period_s: float = Field(6.0, ge=2.0, le=60.0, description="deck pitch period")
    heave_period_s: float = Field(7.0, ge=2.0, le=60.0, description="deck heave period")
    yaw_period_s: float = Field(12.0, ge=2.0, le=120.0, description="deck yaw period")

    def deck_moves(self) -> bool:
        return self.deck_turns() or self.heave_m > 0

    def deck_tilts(self) -> bool:
        """Whether the deck rolls or pitches (a flat pad's light then changes with its tilt to the sun)."""
        return self.roll_deg > 0 or self.pitch_deg > 0

    def deck_turns(self) -> bool:
        """Whether the deck rolls, pitches or yaws (the pad's light and the drone's shadow on it are
        then worked out in the pad's frame)."""
        return self.deck_tilts() or self.yaw_deg > 0

    def max_edge_drop_m(self) -> float:
        """How far the deck's motion may take the platform top's lowest point below its mean height."""
        return self.heave_m + (math.sin(math.radians(self.roll_deg)) + math.sin(math.radians(self.pitch_deg))) * self.size_m / 2

    @model_validator(mode="after")
    def _deck(self):
        if self.deck_moves() and self.max_edge_drop_m() >= self.height_m - DECK_CLEARANCE_M:
            # (a deck that only yaws drops nothing, but moves: it still stands clear of the ground)
            raise ValueError(f"platform: a moving deck (heave {self.heave_m} m, roll {self.roll_deg} deg, pitch "
                             f"{self.pitch_deg} deg, yaw {self.yaw_deg} deg) takes the edge of its {self.size_m} m top "
                             f"{self.max_edge_drop_m():.2f} m down and must stay {DECK_CLEARANCE_M} m above the ground: "
                             f"raise platform.height_m from {self.height_m} to more than "
                             f"{self.max_edge_drop_m() + DECK_CLEARANCE_M:.2f} m, or keep the deck still")
        return self


class AirframeSpec(_Model):
    """What of the drone itself the camera can see: landing legs under the body, motor arms and
    spinning propellers (FLU body frame).  A camera under the body looking down sees the legs; the
    arms and propellers, at or above the body's plane, come into view of a camera mounted lower
    than them at the front and pitched forward, or of a very wide lens."""

    legs: int = Field(0, ge=0, le=8, description="landing legs: vertical tubes spread evenly around the body centre")
    leg_length_m: float = Field(0.18, gt=0.0, le=1.0, description="from the body origin down")
    leg_diameter_m: float = Field(0.02, gt=0.0, le=0.2)
    leg_spread_m: float = Field(0.16, gt=0.0, le=1.0, description="horizontal distance of each leg from the body centre")
    leg_azimuth_deg: float = Field(45.0, description="azimuth of the first leg from the body's x axis (forward)")
    leg_color: tuple[int, int, int] = Field((34, 34, 38), description="sRGB colour of the legs")
    arms: int = Field(0, ge=0, le=8, description="motor arms: horizontal tubes from the body to a motor each, "
                      "spread evenly around the body centre, a spinning propeller over each motor")
    arm_length_m: float = Field(0.25, gt=0.0, le=2.0, description="from the body centre to a motor")
    arm_diameter_m: float = Field(0.02, gt=0.0, le=0.2)
    arm_azimuth_deg: float = Field(45.0, description="azimuth of the first arm from the body's x axis (forward)")
    arm_z_m: float = Field(0.0, ge=-0.5, le=0.5, description="height of the arms above the body origin")
    arm_color: tuple[int, int, int] = Field((34, 34, 38), description="sRGB colour of the arms")
    prop_diameter_m: float = Field(0.25, ge=0.0, le=2.0, description="disc a spinning propeller sweeps (0: none)")
    prop_z_m: float = Field(0.03, ge=-0.5, le=0.5, description="height of the propeller discs above the arms")
    prop_alpha: float = Field(0.3, ge=0.0, le=1.0, description="share of the light behind a propeller disc that "
                              "its blades take (a spinning propeller is a translucent disc)")
    prop_color: tuple[int, int, int] = Field((20, 20, 22), description="sRGB colour of the blades")


class PadMaterialSpec(_Model):
    """The printed pad as it really is: glossy and dirty (drawn per sequence)."""

    gloss: NonNegRange = Field((0.0, 0.0), description="specular glare of the sun on the pad: peak added light "
                               "relative to a sunlit white (0: matte)")
    gloss_roughness: Range = Field((0.15, 0.3), description="spread of the glare (Blinn-Phong, 0 mirror-like to 1)")
    dirt: NonNegRange = Field((0.0, 0.0), description="share of the pad's area covered by stains and wear")
    relief_m: NonNegRange = Field((0.0, 0.0), description="how far the printed pad departs from flat: the highest "
                                  "point of its wrinkles and sag above where it rests (0: flat). Labels stay on the "
                                  "ideal plane; meta.json's pad_relief says how far the features' images move")
    relief_wavelength_m: NonNegRange = Field((0.15, 0.5), description="wavelength of the wrinkles")

    @model_validator(mode="after")
    def _relief(self):
        if self.relief_m[1] > 0.1:
            raise ValueError(f"pad_material.relief_m: up to {self.relief_m[1]} m; a printed pad's wrinkles and sag "
                             "stay within 0.1 m")
        if self.relief_wavelength_m[0] < 0.03:
            raise ValueError(f"pad_material.relief_wavelength_m: from {self.relief_wavelength_m[0]} m; wrinkles "
                             "shorter than 0.03 m are creases, not relief")
        return self


Family = Literal["straight", "spiral", "hover_correct", "manoeuvres"]


class TrajectorySpec(_Model):
    families: list[Family] = Field(["straight", "spiral", "hover_correct", "manoeuvres"], min_length=1)
    start_height_m: float = Field(20.0, gt=0.2, description="camera height above the pad at t = 0")
    touchdown_height_m: float = Field(0.15, gt=0.01, description="camera height above the pad at contact")
    duration_s: Range = Field((30.0, 40.0), description="descent duration (manoeuvres add their own time); a "
                                "flight that would turn the drone over (a descent that falls faster than gravity) "
                                "is refused before anything is rendered")
    lateral_offset_m: NonNegRange = Field((0.0, 3.0), description="horizontal start offset from the pad")
    yaw_deg: Range = Field((-180.0, 180.0), description="initial heading")
    yaw_change_deg: Range = Field((-90.0, 90.0), description="heading change over the descent")
    spiral_turns: NonNegRange = (0.5, 1.5)
    hover_steps: IntRange = (2, 4)
    manoeuvre_height_m: NonNegRange = Field((1.5, 3.0), description="height of the manoeuvre set")
    manoeuvre_step_m: NonNegRange = (0.2, 0.5)
    gust_accel_mps2: NonNegRange = Field((0.0, 0.4), description="amplitude of smooth gust accelerations")
    final_offset_m: NonNegRange = Field((0.0, 0.1), description="touchdown point's distance from the pad centre")
    aim_camera: bool = Field(True, description="an off-nadir camera keeps its optical axis on the pad: the path "
                             "is moved back by where the axis meets the pad plane (no effect on a nadir camera)")

    @model_validator(mode="after")
    def _heights(self):
        if self.touchdown_height_m >= self.start_height_m:
            raise ValueError("touchdown_height_m: must be below start_height_m")
        if self.duration_s[0] <= 0:
            raise ValueError("duration_s: must be positive")
        return self


GroundKind = Literal["grass", "dry_grass", "gravel", "soil", "asphalt", "sand", "concrete", "snow"]


class PlacedBox(_Model):
    """A box at a chosen place (metres, world frame at t = 0: the pad's centre is the origin)."""

    xy_m: tuple[float, float]
    size_m: tuple[float, float, float]
    yaw_deg: float = 0.0

    @model_validator(mode="after")
    def _size(self):
        if min(self.size_m) <= 0:
            raise ValueError(f"size_m: every side must be positive, got {list(self.size_m)}")
        return self


class DistractorSpec(_Model):
    boxes: IntRange = Field((0, 6), description="buildings/boxes around the pad")
    boxes_at: list[PlacedBox] = Field(default_factory=list, description="boxes at chosen places, besides the "
                                      "random ones (scenes built to occlude)")
    decoy_patches: IntRange = Field((0, 2), description="flat patches of the pad's border colour")
    decoy_markers: IntRange = Field((0, 2), description="lone finder-like squares and ArUco markers")
    keep_clear_m: float = Field(2.5, ge=0.0, description="no distractor within this distance of the pad centre "
                                "(nor on the platform, whatever this is)")


class EnvironmentSpec(_Model):
    ground: list[GroundKind] = Field(["grass", "soil", "asphalt", "sand", "concrete"], min_length=1)
    distractors: DistractorSpec = DistractorSpec()
    sun_elevation_deg: Range = (35.0, 80.0)
    sun_azimuth_deg: Range = (0.0, 360.0)
    sun_intensity: NonNegRange = Field((2.5, 4.0), description="pyrender directional-light intensity")
    ambient: NonNegRange = Field((0.25, 0.45), description="ambient light level (0-1)")
    shadows: bool = Field(True, description="cast shadows (sun), including the drone's own on the pad")
    ground_detail: bool = Field(True, description="ground keeps showing finer structure as the camera descends "
                                "(world-fixed detail at scales from 8 mm to 0.25 mm, render/ground.py)")


class DegradationSpec(_Model):
    motion_blur: bool = Field(True, description="the frames smeared over camera.exposure_s; off, each frame is an "
                              "instant, and the dataset says so: camera.json's exposure_s and every blur_px are 0")
    blur_method: Literal["velocity", "subframes"] = Field(
        "velocity", description="velocity: the sharp render moved along each pixel's image motion (one render per "
        "frame); subframes: the exact reference, one render per sample time")
    blur_subframes: int | Literal["auto"] = Field(
        "auto", description="samples over the exposure: enough that any point's consecutive images are at most "
        "0.5 px apart; a number is the least used (a floor); the count used is written per frame")

    @model_validator(mode="after")
    def _samples(self):
        if isinstance(self.blur_subframes, int) and not 1 <= self.blur_subframes <= 256:
            raise ValueError(f"blur_subframes: {self.blur_subframes} is not in [1, 256] (or 'auto')")
        return self
    defocus_sigma_px: NonNegRange = (0.0, 0.6)
    shot_noise: NonNegRange = Field((0.0, 0.02), description="Poisson-like noise std at full scale, sqrt-scaled")
    read_noise: NonNegRange = Field((0.0, 0.008), description="Gaussian read noise std (0-1 scale)")
    exposure_gain: NonNegRange = Field((0.85, 1.15), description="global brightness gain")
    gamma: Range = Field((0.9, 1.1), description="tone curve exponent")
    sharpen: NonNegRange = Field((0.0, 0.0), description="in-camera sharpening (unsharp mask of luma and colour in "
                                 "display space, radius 1 px) as consumer cameras apply it; 1 doubles the detail")
    jpeg_quality: int | None = Field(None, ge=10, le=100, description="re-encode frames as JPEG at this quality")


class ImuSpec(_Model):
    rate_hz: float = Field(200.0, gt=0.0, le=2000.0)
    gyro_noise_rad_s: float = Field(0.003, ge=0.0, description="white noise std per sample")
    gyro_bias_rad_s: float = Field(0.002, ge=0.0, description="initial bias std")
    gyro_bias_walk_rad_s2: float = Field(0.0002, ge=0.0, description="bias random walk per sqrt(s)")
    accel_noise_mps2: float = Field(0.03, ge=0.0)
    accel_bias_mps2: float = Field(0.03, ge=0.0)
    accel_bias_walk_mps3: float = Field(0.001, ge=0.0)
    ahrs_roll_pitch_deg: float = Field(0.3, ge=0.0, description="AHRS attitude error std, roll and pitch")
    ahrs_yaw_deg: float = Field(1.0, ge=0.0, description="AHRS attitude error std, yaw")
    ahrs_drift_time_s: float = Field(20.0, gt=0.0, description="correlation time of the AHRS error (slow drift)")
    time_offset_s: float = Field(0.0, ge=-0.5, le=0.5, description="the IMU's clock minus the camera's: imu.csv's "
                                 "t is the sample's true time plus this (camera.json says it, as a calibration would)")
    vibration_accel_mps2: float = Field(0.0, ge=0.0, le=50.0, description="the airframe's vibration in each "
                                        "accelerometer sample, rms per axis (a multirotor's, after its flight "
                                        "computer's filter: 0.5-3)")
    vibration_gyro_rad_s: float = Field(0.0, ge=0.0, le=5.0, description="the same in each gyro sample, rms per "
                                        "axis (0.02-0.2)")
    vibration_hz: PositiveRange = Field((80.0, 160.0), description="the rotors' frequency, drawn per sequence; it wanders "
                                "5 % with the thrust and is sampled at rate_hz with no anti-alias filter")


class PhaseRuleSpec(_Model):
    min_module_px: float = Field(2.0, gt=0.0, description="adjustment needs marker modules at least this big")


class DatasetSpec(_Model):
    name: str = Field("dataset", pattern=r"^[A-Za-z0-9_.-]+$")
    seed: int = Field(0, ge=0)
    sequences: int = Field(1, ge=1, le=100000)
    camera: CameraSpec = CameraSpec()
    pad: PadSpec = PadSpec()
    pad_ppm: float = Field(2000.0, gt=100.0, le=10000.0, description="texture resolution of the pad")
    platform: PlatformSpec = PlatformSpec()
    pad_material: PadMaterialSpec = PadMaterialSpec()
    airframe: AirframeSpec = AirframeSpec()
    trajectory: TrajectorySpec = TrajectorySpec()
    environment: EnvironmentSpec = EnvironmentSpec()
    degradations: DegradationSpec = DegradationSpec()
    imu: ImuSpec = ImuSpec()
    phase_rule: PhaseRuleSpec = PhaseRuleSpec()

    @model_validator(mode="after")
    def _shutter(self):
        if self.camera.rolling_shutter_line_s > 0 and self.degradations.blur_method != "velocity":
            raise ValueError("camera.rolling_shutter_line_s: a rolling shutter is rendered by the velocity method "
                             "only (degradations.blur_method: velocity)")
        return self

    @model_validator(mode="after")
    def _deck_clear_at_touchdown(self):
        # the descent follows the heave, not the tilt: a tilted pad rises under a camera beside its centre
        pl, tr = self.platform, self.trajectory
        rise = (math.sin(math.radians(pl.roll_deg)) + math.sin(math.radians(pl.pitch_deg))) * (tr.final_offset_m[1] + 0.1)
        if rise >= 0.5 * tr.touchdown_height_m:
            raise ValueError(f"platform.roll_deg / pitch_deg: a deck tilting {pl.roll_deg} / {pl.pitch_deg} deg rises "
                             f"{rise:.2f} m under a camera up to {tr.final_offset_m[1]} m from the pad's centre, half or more "
                             f"of trajectory.touchdown_height_m ({tr.touchdown_height_m} m); raise it or tilt less")
        return self

    @model_validator(mode="after")
    def _pad_visible(self):
        # At the start height the whole pad must fit in the image with some room, else no
        # localizer could ever see it: a spec error, not a hard sequence.
        cam = self.camera
        f = cam.focal_px()
        # an off-nadir camera aimed at the pad sees it at the slant distance along its axis
        down = -float(cam.mount.transform()[2, 2]) if self.trajectory.aim_camera else 1.0
        if down < 0.2:
            raise ValueError("camera.mount: the optical axis is within 12 degrees of the horizon (or above it); "
                             "it cannot be aimed at the pad during a descent")
        slant = self.trajectory.start_height_m / down
        pad_px = self.pad.side_m * f / slant
        if pad_px < 4.0:
            raise ValueError(f"camera: the pad is only {pad_px:.1f} px wide at the start height "
                             f"{self.trajectory.start_height_m} m (needs >= 4 px); raise the resolution "
                             "or the field of view's focal length, or start lower")
        half_view = slant * math.tan(math.radians(cam.hfov_deg) / 2.0) * min(1.0, cam.height / cam.width)
        if self.trajectory.lateral_offset_m[1] + self.pad.side_m / 2 > half_view:
            raise ValueError(f"trajectory.lateral_offset_m: up to {self.trajectory.lateral_offset_m[1]} m puts the pad "
                             f"outside the camera's view at the start height (half-width {half_view:.2f} m)")
        return self

    def canonical_json(self) -> str:
        return json.dumps(self.model_dump(mode="json"), sort_keys=True, separators=(",", ":"))

    def sha256(self) -> str:
        """The spec's identity: a hash of the fields that differ from their defaults, so that adding an
        optional field (whose default renders as before) leaves every existing spec, cached dataset and
        frozen suite with the same hash.  The manifest keeps the full spec (``canonical_json``)."""
        d = self.model_dump(mode="json", exclude_defaults=True)
        cam = d.get("camera", {})
        if "dist" in cam and not any(cam["dist"]):  # no distortion: as the 5-zero default was before camera.model
            del cam["dist"]
            if not cam:
                del d["camera"]
        d["render_revision"] = render_revision(self)
        if self.pad.variant == "artwork":  # the image's pixels, not only its path, are the pad
            from pad_design.texture import artwork_sha256

            d["artwork_sha256"] = artwork_sha256(self.pad.artwork_image)
        ident = json.dumps(d, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(ident.encode()).hexdigest()


def load_dataset_spec(path) -> DatasetSpec:
    return load_yaml_model(DatasetSpec, path)
