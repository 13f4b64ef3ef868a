"""Every leaf field of the dataset spec, with what the tests need to know about it.

``FIELDS[path] = (draw, perturb, context)``:

* ``draw(rng) -> value``: a random valid value, from a domain that renders quickly (the property
  test draws every field of a spec from here);
* ``perturb`` a value different from the base one whose effect shows in the first frames of
  sequence 0, and ``context``: other fields set alike in the base and the perturbed spec so that
  it can show (a spiral's turns need the spiral family).

A field of :class:`render.spec.DatasetSpec` that is missing here fails ``test_spec_space``: a new
field must say how it is drawn and how its effect is seen, or it is not rendered.
"""
from __future__ import annotations

import numpy as np


def _rng_range(lo, hi, nonneg=True):
    def draw(rng):
        a, b = sorted(rng.uniform(lo, hi, 2))
        return [float(a), float(b)]
    return draw


def _choice(values):
    return lambda rng: values[int(rng.integers(len(values)))]


def _aside(values):
    """A choice drawn without advancing ``rng``, for a field that changes what a dataset says but
    not its pixels: adding it leaves every random spec's other fields as they were drawn."""
    return lambda rng: values[int(np.random.default_rng(rng.bit_generator.state["state"]["state"]).integers(len(values)))]


def _uniform(lo, hi):
    return lambda rng: float(rng.uniform(lo, hi))


def _int(lo, hi):
    return lambda rng: int(rng.integers(lo, hi + 1))


def _artwork_files() -> tuple:
    """Two small artwork images (an artwork pad's spec names a file), made once per machine."""
    import os
    import tempfile
    from pathlib import Path

    import cv2

    out = []
    for i, colour in enumerate(((40, 120, 20), (200, 40, 40))):
        p = Path(tempfile.gettempdir()) / f"hvloc_spec_space_artwork_{i}.png"
        if not p.is_file():  # written whole, then renamed: the test workers import this at once
            img = np.full((256, 256, 3), 230, np.uint8)
            cv2.rectangle(img, (0, 0), (255, 255), colour, 24)
            cv2.circle(img, (128, 128), 60, (30, 30, 30), -1)
            part = p.with_name(f"{p.stem}.{os.getpid()}.png")
            cv2.imwrite(str(part), img)
            os.replace(part, p)
        out.append(str(p))
    return tuple(out)


ARTWORK = _artwork_files()
ART = {"pad.variant": "artwork", "pad.artwork_image": ARTWORK[0]}
TILTED = {"camera.mount.rpy_deg": [200.0, 0.0, -90.0]}
WIDE = {"camera.hfov_deg": 110.0}  # the legs are in view of a wide lens
# arms and propellers come into view of a camera pitched forward, mounted above them
ARMS = {"camera.mount.rpy_deg": [180.0, 60.0, -90.0], "airframe.arms": 4, "airframe.arm_azimuth_deg": 0.0,
        "airframe.arm_z_m": -0.1, "airframe.prop_z_m": -0.06}
BLUR = {"camera.exposure_s": 0.02, "trajectory.gust_accel_mps2": [0.8, 0.8]}
DISTRACTORS = {"environment.distractors.boxes": [2, 2], "environment.distractors.decoy_patches": [1, 1],
               "environment.distractors.decoy_markers": [1, 1]}

FIELDS = {
    "name": (_choice(["a", "b"]), "other_name", {}),
    "seed": (_int(0, 1000), 4242, {}),
    "sequences": (_int(1, 3), 3, {}),
    "camera.width": (_int(160, 224), 72, {}),
    "camera.height": (_int(160, 224), 72, {}),
    "camera.hfov_deg": (_uniform(55, 95), 75.0, {}),
    "camera.fy_over_fx": (_uniform(0.95, 1.05), 1.1, {}),
    "camera.principal_offset_px": (lambda r: [float(v) for v in r.uniform(-4, 4, 2)], [3.0, -2.0], {}),
    # a draw of the wrong length for the drawn model is redrawn (random_spec): both models come up
    "camera.model": (_choice(["pinhole", "pinhole", "fisheye"]), "fisheye", {}),
    "camera.dist": (_choice([[0, 0, 0, 0, 0], [-0.12, 0.02, 0.0005, -0.0003, 0.0], [-0.25, 0.07, 0, 0, -0.008],
                             [0.0, 0.0, 0.0, 0.0], [0.03, -0.01, 0.002, -0.0002]]),
                    [-0.1, 0.01, 0.0, 0.0, 0.0], {}),
    "camera.fps": (_uniform(2.0, 4.0), 3.0, {}),
    "camera.exposure_s": (_choice([0.0, 0.004, 0.01]), 0.002, {}),
    "camera.supersample": (_int(1, 2), 2, {}),
    "camera.mix_in_light": (_choice([True, True, False]), False, {}),
    "camera.rolling_shutter_line_s": (_choice([0.0, 0.0, 3e-5]), 4e-5, {"trajectory.yaw_change_deg": [300.0, 300.0]}),
    "camera.vignetting": (_rng_range(0.0, 0.4), [0.4, 0.4], {}),
    "camera.chromatic_aberration_px": (_rng_range(0.0, 1.0), [1.5, 1.5], {"camera.width": 160, "camera.height": 160}),
    "camera.mono": (_choice([False, False, True]), True, {}),
    "camera.auto_exposure_lag_s": (_choice([None, 0.3]), 0.4, {}),
    "camera.frame_time_jitter_s": (_choice([0.0, 0.0, 0.02]), 0.05, {}),
    "camera.frame_drop_rate": (_choice([0.0, 0.0, 0.2]), 0.3, {}),
    "camera.mount.xyz_m": (lambda r: [0.0, 0.0, float(r.uniform(-0.1, -0.02))], [0.05, 0.0, -0.08], {}),
    "camera.mount.rpy_deg": (lambda r: [float(180 + r.uniform(-25, 25)), 0.0, -90.0], [195.0, 0.0, -90.0], {}),
    "pad.variant": (_choice(["paper", "nested", "aruco", "apriltag", "aruco_nested"]), "aruco", {}),
    "pad.aruco_nested_ids": (_choice([[16, 1], [45, 7]]), [45, 7], {"pad.variant": "aruco_nested"}),
    "pad.aruco_nested_dictionary": (_choice(["DICT_5X5_50", "DICT_6X6_50"]), "DICT_6X6_50",
                                    {"pad.variant": "aruco_nested"}),
    "pad.apriltag_ids": (_choice([[0, 1], [2, 5]]), [2, 5], {"pad.variant": "apriltag"}),
    "pad.apriltag_total_m": (_choice([None, 0.5]), 0.45, {"pad.variant": "apriltag"}),
    "pad.side_m": (_uniform(0.7, 1.2), 1.0, {}),
    "pad.border_m": (_uniform(0.08, 0.14), 0.12, {}),
    "pad.border_color": (_choice(["#ff30e0", "#3050ff", "#c020ff"]), "#3050ff", {}),
    "pad.border_dark_factor": (_uniform(0.0, 0.3), 0.3, {}),
    "pad.border_checker_m": (_choice([0.0125, 0.02, 0.025]), 0.02, {}),
    "pad.cue_color": (_choice(["#ffd200", "#20e040"]), "#20e040", {}),
    "pad.marker_size_m": (_uniform(0.10, 0.14), 0.14, {}),
    "pad.quiet_zone_modules": (_uniform(1.0, 1.5), 1.5, {}),
    "pad.nested_marker_size_m": (_uniform(0.03, 0.04), 0.04, {"pad.variant": "nested"}),
    "pad.aruco_dictionary": (_choice(["DICT_4X4_50", "DICT_5X5_50"]), "DICT_5X5_50", {"pad.variant": "aruco"}),
    "pad.aruco_ids": (_choice([[0, 1, 2], [3, 7, 9]]), [3, 7, 9], {"pad.variant": "aruco"}),
    # an artwork pad needs its image: random specs draw hvloc's variants (their draws are None / {})
    "pad.artwork_image": (_choice([None]), ARTWORK[1], ART),
    "pad.artwork_points": (_choice([{}]), {"dot": [0.1, -0.2]}, ART),
    "pad.texture_seed": (_int(0, 100), 99, {}),
    "pad.texture_min_feature_m": (_uniform(0.004, 0.006), 0.006, {}),
    "pad.texture_max_feature_m": (_uniform(0.02, 0.04), 0.04, {}),
    "pad.texture_density": (_uniform(0.15, 0.3), 0.15, {}),
    "pad_material.gloss": (_rng_range(0.0, 0.8), [0.8, 0.8], {"environment.sun_elevation_deg": [85.0, 85.0]}),
    "pad_material.gloss_roughness": (_rng_range(0.1, 0.4), [0.05, 0.05], {"pad_material.gloss": [0.8, 0.8],
                                                                        "environment.sun_elevation_deg": [85.0, 85.0]}),
    "pad_material.dirt": (_rng_range(0.0, 0.4), [0.4, 0.4], {}),
    "pad_material.relief_m": (_rng_range(0.0, 0.02), [0.03, 0.03], {}),
    "pad_material.relief_wavelength_m": (_rng_range(0.15, 0.5), [0.08, 0.08], {"pad_material.relief_m": [0.02, 0.02]}),
    "airframe.legs": (_choice([0, 0, 2, 4]), 4, WIDE),
    "airframe.leg_length_m": (_uniform(0.15, 0.25), 0.3, {**WIDE, "airframe.legs": 4}),
    "airframe.leg_diameter_m": (_uniform(0.015, 0.03), 0.04, {**WIDE, "airframe.legs": 4}),
    "airframe.leg_spread_m": (_uniform(0.12, 0.2), 0.12, {**WIDE, "airframe.legs": 4}),
    "airframe.leg_azimuth_deg": (_uniform(0.0, 90.0), 10.0, {**WIDE, "airframe.legs": 4}),
    "airframe.leg_color": (_choice([[34, 34, 38], [200, 40, 40]]), [220, 220, 60], {**WIDE, "airframe.legs": 4}),
    "airframe.arms": (_choice([0, 0, 4]), 4, {k: v for k, v in ARMS.items() if k != "airframe.arms"}),
    "airframe.arm_length_m": (_uniform(0.2, 0.3), 0.35, ARMS),
    "airframe.arm_diameter_m": (_uniform(0.015, 0.03), 0.04, ARMS),
    "airframe.arm_azimuth_deg": (_uniform(0.0, 90.0), 20.0, ARMS),
    "airframe.arm_z_m": (_uniform(-0.05, 0.05), -0.14, ARMS),
    "airframe.arm_color": (_choice([[34, 34, 38], [200, 40, 40]]), [220, 220, 60], ARMS),
    "airframe.prop_diameter_m": (_uniform(0.15, 0.3), 0.0, ARMS),
    "airframe.prop_z_m": (_uniform(0.0, 0.05), -0.03, ARMS),
    "airframe.prop_alpha": (_uniform(0.2, 0.4), 0.6, ARMS),
    "airframe.prop_color": (_choice([[20, 20, 22], [90, 90, 90]]), [200, 40, 40], ARMS),
    "pad_ppm": (_choice([500.0, 700.0]), 600.0, {}),
    "platform.height_m": (_choice([0.0, 0.5]), 0.3, {}),
    "platform.size_m": (_uniform(1.0, 1.6), 1.5, {}),
    "platform.velocity_mps": (lambda r: [float(v) for v in r.uniform(-1, 1, 2) * (r.random() < 0.5)], [0.6, 0.3], {}),
    "platform.roll_deg": (_choice([0.0, 0.0, 6.0]), 5.0, {}),
    "platform.pitch_deg": (_choice([0.0, 0.0, 4.0]), 5.0, {}),
    "platform.heave_m": (_choice([0.0, 0.0, 0.2]), 0.2, {}),
    "platform.roll_period_s": (_uniform(4.0, 10.0), 5.0, {"platform.roll_deg": 5.0}),
    "platform.pitch_period_s": (_uniform(4.0, 10.0), 5.0, {"platform.pitch_deg": 5.0}),
    "platform.heave_period_s": (_uniform(4.0, 10.0), 5.0, {"platform.heave_m": 0.2}),
    "platform.yaw_deg": (_choice([0.0, 0.0, 5.0]), 5.0, {}),
    "platform.yaw_period_s": (_uniform(6.0, 14.0), 5.0, {"platform.yaw_deg": 5.0}),
    "trajectory.families": (lambda r: [["straight", "spiral", "hover_correct", "manoeuvres"][int(r.integers(4))]],
                            ["spiral"], {}),
    "trajectory.start_height_m": (_uniform(3.0, 5.0), 4.5, {}),
    "trajectory.touchdown_height_m": (_uniform(0.15, 0.4), 0.3, {}),
    "trajectory.duration_s": (_rng_range(6.0, 9.0), [7.0, 7.0], {}),
    "trajectory.lateral_offset_m": (_rng_range(0.0, 1.0), [0.5, 0.5], {}),
    "trajectory.yaw_deg": (_rng_range(-180, 180), [30.0, 30.0], {}),
    "trajectory.yaw_change_deg": (_rng_range(-90, 90), [40.0, 40.0], {}),
    "trajectory.spiral_turns": (_rng_range(0.3, 1.5), [1.2, 1.2], {"trajectory.families": ["spiral"]}),
    "trajectory.hover_steps": (lambda r: [int(r.integers(1, 3))] * 2, [3, 3], {"trajectory.families": ["hover_correct"]}),
    "trajectory.manoeuvre_height_m": (_rng_range(1.0, 2.0), [1.2, 1.2], {"trajectory.families": ["manoeuvres"]}),
    "trajectory.manoeuvre_step_m": (_rng_range(0.1, 0.3), [0.45, 0.45], {"trajectory.families": ["manoeuvres"]}),
    "trajectory.gust_accel_mps2": (_rng_range(0.0, 0.8), [0.7, 0.7], {}),
    "trajectory.final_offset_m": (_rng_range(0.0, 0.1), [0.2, 0.2], {}),
    "trajectory.aim_camera": (_choice([True, False]), False, TILTED),
    "environment.ground": (lambda r: [["grass", "dry_grass", "gravel", "soil", "asphalt", "sand", "concrete", "snow"][int(r.integers(8))]],
                           ["sand"], {}),
    "environment.distractors.boxes": (lambda r: [0, int(r.integers(0, 4))], [3, 3], {}),
    "environment.distractors.boxes_at": (lambda r: [{"xy_m": [float(r.uniform(0.8, 1.5)), float(r.uniform(-1, 1))],
                                                     "size_m": [0.3, 1.0, float(r.uniform(0.3, 1.5))]}]
                                         if r.random() < 0.5 else [],
                                         [{"xy_m": [0.9, 0.0], "size_m": [0.3, 1.0, 0.8]}], {}),
    "environment.distractors.decoy_patches": (lambda r: [0, int(r.integers(0, 3))], [2, 2], {}),
    "environment.distractors.decoy_markers": (lambda r: [0, int(r.integers(0, 3))], [2, 2], {}),
    "environment.distractors.keep_clear_m": (_uniform(0.8, 3.0), 1.2, DISTRACTORS),
    "environment.sun_elevation_deg": (_rng_range(25, 85), [30.0, 30.0], {}),
    "environment.sun_azimuth_deg": (_rng_range(0, 360), [100.0, 100.0], {}),
    "environment.sun_intensity": (_rng_range(2.0, 4.0), [2.0, 2.0], {}),
    "environment.ambient": (_rng_range(0.2, 0.5), [0.5, 0.5], {}),
    # the drone's own shadow lies in view when the sun is high
    "environment.ground_detail": (_choice([True, False]), False, {"trajectory.start_height_m": 1.5,
                                                                   "trajectory.lateral_offset_m": [0.0, 0.0]}),
    "environment.shadows": (_choice([True, False]), False, {"environment.sun_elevation_deg": [80.0, 80.0]}),
    "degradations.motion_blur": (_choice([True, False]), False, BLUR),
    "degradations.blur_method": (_choice(["velocity", "subframes"]), "subframes", BLUR),
    "degradations.blur_subframes": (_choice(["auto", 2, 4]), 40, BLUR),
    "degradations.defocus_sigma_px": (_rng_range(0.0, 0.6), [0.8, 0.8], {}),
    "degradations.shot_noise": (_rng_range(0.0, 0.02), [0.03, 0.03], {}),
    "degradations.read_noise": (_rng_range(0.0, 0.008), [0.01, 0.01], {}),
    "degradations.exposure_gain": (_rng_range(0.85, 1.15), [0.7, 0.7], {}),
    "degradations.gamma": (_rng_range(0.9, 1.1), [1.2, 1.2], {}),
    "degradations.sharpen": (_rng_range(0.0, 1.0), [0.8, 0.8], {}),
    "degradations.jpeg_quality": (_choice([None, 60, 90]), 50, {}),
    "imu.rate_hz": (_choice([100.0, 200.0]), 150.0, {}),
    "imu.gyro_noise_rad_s": (_uniform(0.0, 0.005), 0.01, {}),
    "imu.gyro_bias_rad_s": (_uniform(0.0, 0.003), 0.01, {}),
    "imu.gyro_bias_walk_rad_s2": (_uniform(0.0, 0.0003), 0.001, {}),
    "imu.accel_noise_mps2": (_uniform(0.0, 0.05), 0.1, {}),
    "imu.accel_bias_mps2": (_uniform(0.0, 0.05), 0.1, {}),
    "imu.accel_bias_walk_mps3": (_uniform(0.0, 0.002), 0.01, {}),
    "imu.ahrs_roll_pitch_deg": (_uniform(0.1, 0.5), 1.0, {}),
    "imu.ahrs_yaw_deg": (_uniform(0.5, 2.0), 3.0, {}),
    "imu.ahrs_drift_time_s": (_uniform(10.0, 30.0), 5.0, {}),
    "imu.time_offset_s": (_choice([0.0, -0.01, 0.02]), 0.05, {}),
    "imu.vibration_accel_mps2": (_choice([0.0, 0.0, 1.0]), 2.0, {}),
    "imu.vibration_gyro_rad_s": (_choice([0.0, 0.0, 0.1]), 0.15, {}),
    "imu.vibration_hz": (_rng_range(60.0, 180.0), [30.0, 40.0], {"imu.vibration_accel_mps2": 1.0}),
    # adjustment frames need a camera that resolves the markers
    "phase_rule.min_module_px": (_uniform(1.5, 3.0), 40.0, {"camera.width": 200, "camera.height": 200}),
    "camera.response_known": (_aside([False, True]), True, {}),  # (camera.json's response, not its pixels)
}

# the spec the effect test perturbs: small, quick, every effect visible in sequence 0's first frames
BASE = {"name": "base", "seed": 11, "sequences": 1, "pad_ppm": 500.0,
        "camera": {"width": 64, "height": 64, "hfov_deg": 60.0, "fps": 2.0, "exposure_s": 0.004},
        "platform": {"height_m": 0.5},
        "trajectory": {"families": ["straight"], "start_height_m": 4.0, "duration_s": [6.0, 6.0],
                       "lateral_offset_m": [0.2, 0.2], "yaw_deg": [10.0, 10.0], "yaw_change_deg": [20.0, 20.0],
                       "gust_accel_mps2": [0.2, 0.2], "final_offset_m": [0.05, 0.05]},
        "environment": {"distractors": {"boxes": [0, 0], "decoy_patches": [0, 0], "decoy_markers": [0, 0]}}}


def leaf_paths(model=None, prefix: str = "") -> list:
    """Dotted paths of every leaf field of a pydantic model (default: the dataset spec)."""
    from pydantic import BaseModel

    from render.spec import DatasetSpec

    model = model or DatasetSpec
    out = []
    for name, f in model.model_fields.items():
        ann = f.annotation
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            out += leaf_paths(ann, prefix + name + ".")
        else:
            out.append(prefix + name)
    return out


def set_path(d: dict, path: str, value) -> dict:
    cur = d
    keys = path.split(".")
    for k in keys[:-1]:
        cur = cur.setdefault(k, {})
    cur[keys[-1]] = value
    return d


def random_spec(rng: np.random.Generator) -> dict:
    """A spec with every field drawn from its domain (redrawn until valid)."""
    from pad_design.errors import InputError, validate_model
    from render.spec import DatasetSpec

    for _ in range(200):
        d: dict = {}
        for path, (draw, _, _) in FIELDS.items():
            set_path(d, path, draw(rng))
        d["sequences"] = 1
        try:
            validate_model(DatasetSpec, d)
            return d
        except InputError:
            continue
    raise RuntimeError("no valid random spec in 200 draws: a domain in FIELDS is too wide")
