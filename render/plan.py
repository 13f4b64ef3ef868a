"""Everything drawn for one sequence before rendering, reproducible from the dataset seed and the
sequence index alone: trajectory, scene, lighting, degradations, IMU; and the spec's camera."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hvloc.geometry import Camera, focal_from_hfov

from .relief import PadRelief
from .spec import DatasetSpec


def sequence_seed(dataset_seed: int, index: int) -> int:
    """Per-sequence seed derived from the dataset seed and the index alone (regenerable alone)."""
    return int(np.random.SeedSequence([int(dataset_seed), int(index)]).generate_state(1, np.uint64)[0] % (2**63))


def camera_from_spec(cam) -> Camera:
    return cam.to_camera()


def mount_from_spec(mount) -> np.ndarray:
    """``T_B_C`` from the spec: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    return mount.transform()


_PAD_CACHE = {}


def pad_for(spec: DatasetSpec, texture_png=None):
    """The spec's pad.  With ``texture_png`` (a dataset's ``pad.png``) its texture is read from there,
    so that every sequence of a dataset shows the very same pixels whatever draws pads today."""
    from pad_design import make_pad

    key = (spec.pad.model_dump_json(), spec.pad_ppm, str(texture_png))
    if key not in _PAD_CACHE:
        if texture_png is None:
            _PAD_CACHE[key] = make_pad(spec.pad, spec.pad_ppm)
        else:
            from pad_design.errors import InputError
            from pad_design.layout import build_geometry
            from pad_design.pad import Pad

            from .dataset import read_image

            rgb = read_image(texture_png)
            n = int(round(spec.pad.side_m * spec.pad_ppm))
            if rgb.shape != (n, n, 3):
                raise InputError(f"{texture_png}: a {rgb.shape[1]}x{rgb.shape[0]} texture, the spec's pad needs {n}x{n}")
            _PAD_CACHE[key] = Pad(spec.pad, build_geometry(spec.pad), rgb, n / spec.pad.side_m)
    return _PAD_CACHE[key]


@dataclass
class SequencePlan:
    """Everything drawn for one sequence before rendering (reproducible from the seed alone)."""

    index: int
    seed: int
    family: str
    trajectory: object
    scene_draw: object
    imaging: object
    frame_times: np.ndarray
    imu: np.ndarray = field(repr=False)
    material: dict = field(default_factory=dict)  # the pad's gloss, glare spread and dirt drawn for it
    frame_index: np.ndarray | None = None  # each kept frame's index k (gaps where frames were dropped)

    def __post_init__(self):
        if self.frame_index is None:
            self.frame_index = np.arange(len(self.frame_times))


def _scene_draw(spec: DatasetSpec, rng: np.random.Generator, duration_s: float = 0.0):
    """The sequence's scene (ground, sun, distractors), drawn from its generator after the trajectory's
    seed; the distractors clear of the platform and of where a moving platform takes the pad within
    ``duration_s``."""
    from .scene import draw_scene

    view_radius = spec.trajectory.start_height_m * math.tan(math.radians(spec.camera.hfov_deg) / 2) * 1.5 + \
        spec.trajectory.lateral_offset_m[1]
    return draw_scene(spec.environment, np.random.default_rng(rng.integers(2**63)), view_radius,
                      np.asarray(spec.platform.velocity_mps, np.float64) * duration_s, platform_side(spec))


def platform_side(spec: DatasetSpec) -> float:
    """The side (m) of the platform's solid the pad stands on, 0 where the pad lies on the ground."""
    return float(spec.platform.size_m) if spec.platform.height_m > 0 else 0.0


def _sequence_trajectory(spec: DatasetSpec, index: int) -> tuple:
    """``(rng, family, trajectory)`` of sequence ``index``: its generator after the trajectory's draw."""
    from .scene import PAD_THICKNESS_M
    from .trajectory import DeckMotion, make_trajectory

    rng = np.random.default_rng(sequence_seed(spec.seed, index))
    pl = spec.platform
    deck = None
    if pl.deck_moves():  # phases from a generator of their own: every other draw stays as it was
        # (roll, pitch and heave drawn first: a deck that does not yaw draws as it did before yaw was added)
        draw = np.random.default_rng([sequence_seed(spec.seed, index), 0xDEC])
        phases = np.append(draw.uniform(0, 2 * np.pi, 3), draw.uniform(0, 2 * np.pi))
        deck = DeckMotion(math.radians(pl.roll_deg), math.radians(pl.pitch_deg), pl.heave_m,
                          (pl.roll_period_s, pl.pitch_period_s, pl.heave_period_s, pl.yaw_period_s),
                          tuple(float(v) for v in phases), math.radians(pl.yaw_deg))
    fams = spec.trajectory.families
    family = fams[index % len(fams)]
    T_B_C = mount_from_spec(spec.camera.mount)
    body_above_cam = -float(T_B_C[2, 3])
    pad_surface = spec.platform.height_m + PAD_THICKNESS_M
    traj = make_trajectory(spec.trajectory, np.random.default_rng(rng.integers(2**63)), family, body_above_cam,
                           pad_surface, spec.platform.velocity_mps, optical_axis_B=T_B_C[:3, 2], deck=deck)
    return rng, family, traj


def check_flyable(spec: DatasetSpec, indices=None) -> None:
    """Raise InputError when a sequence's planned flight would turn the body over (tilt it past
    :data:`render.trajectory.MAX_TILT_DEG`): a descent from ``start_height_m`` in too short a
    ``duration_s``, or gusts too strong, asks to accelerate downward faster than gravity, which the
    thrust-follows-acceleration model flies upside down (a flip, not a landing), and its labels and
    IMU would describe that flight."""
    from pad_design.errors import InputError

    from .trajectory import MAX_TILT_DEG, steepest_tilt

    for i in range(spec.sequences) if indices is None else indices:
        _, family, traj = _sequence_trajectory(spec, i)
        tilt, t = steepest_tilt(traj)
        if tilt > MAX_TILT_DEG:
            tr = spec.trajectory
            raise InputError(
                f"{spec.name}: sequence {i} ({family}) would tilt the drone {tilt:.0f} degrees at t = {t:.1f} s "
                f"(past {MAX_TILT_DEG:g} it flies upside down: the flight accelerates downward faster than "
                f"gravity): lengthen trajectory.duration_s (now {list(tr.duration_s)}) or lower "
                f"trajectory.start_height_m ({tr.start_height_m}), gust_accel_mps2 ({list(tr.gust_accel_mps2)}) "
                f"or lateral_offset_m ({list(tr.lateral_offset_m)})")


def plan_sequence(spec: DatasetSpec, index: int) -> SequencePlan:
    from .imaging import ImagingParams
    from .imu import synthesize_imu

    seed = sequence_seed(spec.seed, index)
    rng, family, traj = _sequence_trajectory(spec, index)
    cam = spec.camera
    draw = _scene_draw(spec, rng, traj.duration)
    d = spec.degradations
    r2 = np.random.default_rng(rng.integers(2**63))
    u = lambda r: float(r2.uniform(r[0], r[1])) if r[1] > r[0] else float(r[0])  # noqa: E731
    imaging = ImagingParams(u(d.exposure_gain), u(d.gamma), u(d.defocus_sigma_px), u(d.shot_noise),
                            u(d.read_noise), d.jpeg_quality, u(d.sharpen), u(cam.vignetting),
                            u(cam.chromatic_aberration_px), cam.mono)
    n = int(math.floor(traj.duration * cam.fps + 1e-9)) + 1
    times = np.arange(n) / cam.fps
    imu = synthesize_imu(traj, spec.imu, np.random.default_rng(rng.integers(2**63)), times[-1])
    r3 = np.random.default_rng(rng.integers(2**63))  # drawn after everything older: their draws stay as they were
    m = spec.pad_material
    u3 = lambda r: float(r3.uniform(r[0], r[1])) if r[1] > r[0] else float(r[0])  # noqa: E731
    material = {"gloss": u3(m.gloss), "gloss_roughness": u3(m.gloss_roughness), "dirt": u3(m.dirt),
                "dirt_seed": int(r3.integers(2**31))}
    relief = u3(m.relief_m)  # drawn after the older fields: their draws stay as they were
    material["relief"] = None if relief <= 0 else PadRelief.draw(relief, m.relief_wavelength_m, spec.pad.side_m, r3)
    times, kept = frame_timing(cam, n, np.random.default_rng(rng.integers(2**63)))  # drawn last, as r3
    imu[:, 0] += spec.imu.time_offset_s  # on the IMU's own clock
    return SequencePlan(index, seed, family, traj, draw, imaging, times, imu, material, kept)


def frame_timing(cam, n: int, rng: np.random.Generator) -> tuple:
    """``(times, frame indices)`` of the frames kept: frame ``k`` captured at ``k / fps`` plus its
    jitter (Gaussian, ``cam.frame_time_jitter_s``, clipped to 0.4 / fps so the order holds), and each
    frame but the first and the last lost with probability ``cam.frame_drop_rate``.  No draw is made
    for a camera with neither, so such sequences are as they always were."""
    k = np.arange(n)
    if cam.frame_time_jitter_s <= 0 and cam.frame_drop_rate <= 0:
        return k / cam.fps, k
    jitter = np.clip(rng.normal(0.0, cam.frame_time_jitter_s, n), -0.4 / cam.fps, 0.4 / cam.fps)
    jitter[0] = 0.0  # the sequence starts at t = 0 and ends within the trajectory
    jitter[-1] = min(jitter[-1], 0.0)
    keep = rng.random(n) >= cam.frame_drop_rate
    keep[0] = keep[-1] = True
    return (k / cam.fps + jitter)[keep], k[keep]
