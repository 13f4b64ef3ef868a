"""Localizer configuration: plain values (the benchmark sweeps the switching heights)."""
from __future__ import annotations

import math
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from pad_design.errors import load_yaml_model


class LocalizerConfig(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, validate_default=True)

    # phase switching (heights above the pad, metres)
    adjust_height_m: float = Field(8.0, gt=0.0, description="below this, finder markers are tried")
    touchdown_height_m: float = Field(1.0, gt=0.0, description="below this, the flow tracker takes over "
                                      "when markers are lost")
    hysteresis_m: float = Field(0.3, ge=0.0, description="margin before switching back")
    prior_timeout_s: float = Field(1.0, gt=0.0, description="an accepted pose older than this no longer "
                                   "steers the phase choice (every method is tried again)")
    use_outline: bool = True
    use_markers: bool = True
    use_flow: bool = True
    use_texture: bool = Field(True, description="near the ground, when the flow tracker's chain has broken and "
                              "no markers or outline are seen, find the pad by its own printed texture (ORB "
                              "matches to pad.png) and anchor the tracker again; only with use_flow")
    anchor_once: bool = Field(False, description="the flow-only ablation: the pad detectors run only until "
                              "the flow tracker has its first keyframe (from a pad pose); from then on only "
                              "the flow tracker, at every height, never re-anchored")
    imu_rows: bool = Field(True, description="read the IMU's rows since the last frame when the caller gives "
                           "them (the gyro's mean over the readout, the accelerations since the shutter's velocity "
                           "was read); false: the block's last row alone, as a flight stack that forwards one "
                           "sample a frame gives it (the one_imu_row ablation)")
    # detection
    binarization: Literal["otsu", "adaptive"] = "otsu"
    roi_margin: float = Field(0.6, ge=0.0, description="ROI around the predicted pad, relative to its size")
    # false-pose detection
    false_pose_detection: bool = True
    imu_jump_deg: float = Field(4.0, gt=0.0, description="reject when vision-vs-IMU rotation jumps by more")
    imu_drift_rate: float = Field(0.05, gt=0.0, le=1.0, description="how fast the vision-IMU offset may drift "
                                  "(EMA weight per accepted frame)")
    max_reprojection_px: float = Field(3.0, gt=0.0)
    max_outline_rms_share: float = Field(0.02, gt=0.0, description="reject an outline pose whose reprojection "
                                         "RMS is more than this share of the pad's side in pixels (four corners "
                                         "leave two checks on the pose: a corner off by a tenth of the side shows "
                                         "only as a few percent of it, with the height as far off)")
    max_tilt_error_deg: float = Field(3.0, gt=0.0, description="reject a pose whose pad normal is further than "
                                      "this from the IMU's up (the pad lies level; the AHRS knows roll and pitch "
                                      "to a fraction of a degree, a vision pose off by more is wrong)")
    max_speed_mps: float = Field(15.0, gt=0.0, description="reject poses implying faster motion")
    ahrs_tilt_sigma_deg: float = Field(0.5, gt=0.0, le=10.0, description="how far the AHRS's roll and pitch "
                                       "may be off (one sigma, degrees), as its maker or the user knows it: the "
                                       "gravity prior of every pose is weighed by it.  0.5 (the default) suits a "
                                       "hobby flight controller; an INS aided by GNSS or a tuned EKF is nearer "
                                       "0.1, and where its error is that small, Approaching and Adjustment poses "
                                       "are that much better (README)")
    pad_tilt_deg: float = Field(0.0, ge=0.0, le=30.0, description="how far the pad may tilt from level (degrees): "
                                "a ship's deck rolling and pitching, as the user knows its sea state; 0 (the "
                                "default): a level pad.  The IMU's up is then the pad's normal only to within this: "
                                "until the markers show the deck's tilt, the gravity prior is weighed by the tilt's "
                                "RMS over a swell (this over sqrt 2, with the AHRS's error) and the tilt gate allows "
                                "this more; then the tilt is tracked (hvloc.localizer.DeckTilt) and the prior follows "
                                "it.  The vision-IMU offset is checked on its heading alone; far poses whose tilt the "
                                "image cannot fix are refused (README: Landing on a ship)")
    ahrs_bias_time_s: float = Field(0.0, ge=0.0, description="learn the AHRS's slow roll/pitch error from "
                                    "image-only tilts of marker and texture poses with a Kalman filter whose "
                                    "error drifts over about this long (10 s works), and take it out of the attitude "
                                    "the gravity prior and the gates use; "
                                    "0 (the default): off (README: it helps most scenes, not yet every one)")
    pad_relief_m: float = Field(0.0, ge=0.0, description="how far the pad's surface may stand above the plane it "
                                "lies on (a paper pad's sag and wrinkles), as the user knows it: every pose is "
                                "measured to the surface the camera sees, so each pose from the pad carries half "
                                "this as a standard deviation on each axis of its position, and the tilt its "
                                "wrinkles may give the patch seen is solved for beside the pose "
                                "(hvloc.pose.relief_tilt_rad; the tracker's poses inherit both from their "
                                "keyframe); 0 (the default): a flat pad")
    design_fit: bool = Field(True, description="with the IMU, place a far pad (20-64 px across) by fitting "
                             "its printed design, drawn in light and blurred, to the frame's luma (position, yaw "
                             "and blur; the tilt held) instead of by its outline's step edges; the outline's "
                             "corners are then those of the fitted pose (hvloc.texfit).  On frames that sum light, "
                             "as a camera's do, it halves the small outlines' height bias (README); false: the "
                             "outline's edges alone, 15-50 ms less per such frame")
    # tracker
    flow_reanchor_scale: float = Field(1.15, gt=1.0, description="new keyframe when the scale changes by more")
    flow_min_tracks: int = Field(30, ge=8)

    def up_sigma_deg(self) -> float:
        """How far the pad's normal may be from the IMU's up, one sigma (degrees): the AHRS's error and
        a tilting deck's RMS tilt, together.  What the gravity prior of every pose is weighed by."""
        return math.hypot(self.ahrs_tilt_sigma_deg, self.pad_tilt_deg / math.sqrt(2.0))

    @model_validator(mode="after")
    def _order(self):
        if self.pad_tilt_deg > 0 and self.ahrs_bias_time_s > 0:
            raise ValueError("ahrs_bias_time_s: cannot learn the AHRS's error from the pad's tilt on a tilting deck "
                             "(pad_tilt_deg > 0): the deck's roll would be learnt as the AHRS's; set one of them to 0")
        if self.touchdown_height_m >= self.adjust_height_m:
            raise ValueError("touchdown_height_m: must be below adjust_height_m")
        if not (self.use_outline or self.use_markers or self.use_flow):
            raise ValueError("use_outline: at least one of use_outline, use_markers, use_flow must be on")
        if self.anchor_once and not self.use_flow:
            raise ValueError("anchor_once: needs use_flow (after the anchor only the flow tracker runs)")
        return self


def load_config(path) -> LocalizerConfig:
    return load_yaml_model(LocalizerConfig, path)
