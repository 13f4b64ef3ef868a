"""Why a localizer fails on a dataset: per frame, what it returned and how wrong it was, with the
gates' inputs (the vision-only tilt against the IMU's gravity), summarised per ground-truth phase.

    python -m benchmarks.diagnose DATASET [--config CFG] [--frames N] [--show-false]
    python -m benchmarks.diagnose DATASET --corners [EVERY]   # the outline's corners against the labels

A development tool: it runs hvloc's localizer in process and keeps ``Estimate.extras``, which the
estimates files do not carry.
"""
from __future__ import annotations

import collections
import math
import re

import numpy as np

from hvloc.config import LocalizerConfig, load_config
from pad_design.errors import ArgumentParser
from hvloc.geometry import rotation_angle

from .metrics import FALSE_ACCEPT_DEG, FALSE_ACCEPT_REL
from .run import imu_since, make_localizer


def diagnose(root, config: LocalizerConfig | None = None, max_frames: int | None = None, use_imu: bool = True):
    """Rows ``(seq, k, phase_gt, height, status, method, pos_err, rot_err, wrong, reason, extras,
    height_err_pct)``: the last is the estimate's signed height error in % of the true height."""
    from render.dataset import Dataset

    rows = []
    for seq in Dataset(root):
        loc = make_localizer("hierarchical", seq, config or LocalizerConfig())
        G_all = seq.cam2pad
        for k in range(len(seq) if max_frames is None else min(len(seq), max_frames)):
            t = float(seq.t[k])
            t_last = float(seq.t[k - 1]) if k else None
            e = loc.process(seq.image(k), t, imu_since(seq.imu, t_last, t, seq.imu_time_offset_s) if use_imu else None)
            G = G_all[k]
            pe = re = dh = float("nan")
            h = float(G[2, 3])
            if e.cam2pad is not None:
                pe = float(np.linalg.norm(e.cam2pad[:3, 3] - G[:3, 3]))
                re = math.degrees(rotation_angle(e.cam2pad[:3, :3], G[:3, :3]))
                dh = float(e.cam2pad[2, 3] - h) / h * 100.0
            wrong = bool(e.cam2pad is not None and (pe > FALSE_ACCEPT_REL * h or re > FALSE_ACCEPT_DEG))
            rows.append((seq.id, k, str(seq.columns["phase_gt"][k]), h, e.status, e.method, pe, re, wrong, e.reason,
                         e.extras, dh))
    return rows


def reason_kind(reason: str, width: int = 80) -> str:
    """What kind of failure ``reason`` names, without its numbers: the first method's reason, and
    for a refused pose the first clause of why (``outline: rejected; the outline's corners are no
    square's``), so that frames refused for one cause count together however their numbers differ.
    Reads the localizer's reasons (methods joined by "; ", a refusal's verdict after ", ") and the
    estimates files' (every "," written as ";")."""
    parts = reason.replace(", ", "; ").split("; ")
    kind = parts[0]
    if kind.endswith(": rejected") and len(parts) > 1:
        kind += "; " + parts[1].split(": ")[0]
    return re.sub(r"\d+(\.\d+)?", "#", kind)[:width]


def summarise(rows, ahrs_sigma_deg: float = LocalizerConfig().ahrs_tilt_sigma_deg, pad_tilt_deg: float = 0.0) -> str:
    """The rows per ground-truth phase: statuses, the commonest reasons, the signed height bias, the
    tilt against the IMU; and how far off the AHRS's gravity is where the image can tell
    (:func:`ahrs_as_seen`), against ``ahrs_sigma_deg``, what the localizer was told; or, where the
    pad lay further from the IMU's up than any AHRS errs, that it tilts (:func:`deck_as_seen`)."""
    lines = []
    by = collections.defaultdict(list)
    for r in rows:
        by[r[2]].append(r)
    for ph, rs in by.items():
        st = collections.Counter(r[4] for r in rs)
        fa = sum(1 for r in rs if r[4] == "ok" and r[8])
        rej_right = sum(1 for r in rs if r[4] == "rejected" and not r[8])
        reasons = collections.Counter(reason_kind(r[9]) for r in rs if r[4] != "ok")
        lines.append(f"{ph:12s} n={len(rs):4d} ok={st['ok']:4d} rejected={st['rejected']:4d} "
                     f"(of them right {rej_right}) lost={st['lost']:4d} false_accepts={fa}")
        for why, n in reasons.most_common(5):
            lines.append(f"    {n:4d}  {why}")
        # bias, not noise: the signed height error of the right accepted poses (a scale error of the
        # features shows here first: a pad that looks 1 % too big puts the camera 1 % low)
        dh = np.array([r[11] for r in rs if r[4] == "ok" and not r[8] and len(r) > 11], float)
        dh = dh[np.isfinite(dh)]
        if len(dh):
            p10, p50, p90 = np.percentile(dh, [10, 50, 90])
            lines.append(f"    height error, right ok poses: median {p50:+.2f} % of height (p10 {p10:+.2f}, p90 {p90:+.2f})")
        tilt = np.array([[r[10].get("tilt_err_deg", np.nan), r[10].get("tilt_sigma_deg", np.nan), r[8]]
                         for r in rs if r[4] in ("ok", "rejected")], float).reshape(-1, 3)
        for lab, sel in (("right", tilt[:, 2] == 0), ("wrong", tilt[:, 2] == 1)):
            t = tilt[sel]
            if len(t) and np.isfinite(t[:, 0]).any():
                z = t[:, 0] / np.hypot(t[:, 1], 0.3)
                lines.append(f"    tilt vs IMU, {lab:5s} poses: err p50/p95/max {np.nanpercentile(t[:, 0], 50):.2f}/"
                             f"{np.nanpercentile(t[:, 0], 95):.2f}/{np.nanmax(t[:, 0]):.2f} deg, sigma p50 "
                             f"{np.nanpercentile(t[:, 1], 50):.2f}, z p50/p95/max {np.nanpercentile(z, 50):.1f}/"
                             f"{np.nanpercentile(z, 95):.1f}/{np.nanmax(z):.1f}")
    deck = deck_as_seen(rows, pad_tilt_deg)
    seen = "" if deck else ahrs_as_seen(rows, ahrs_sigma_deg)
    for line in (deck, seen):
        if line:
            lines.append(line)
    return "\n".join(lines)


SURE_TILT_SHARE = 0.25  # a pose whose image fixes the tilt to this share of the AHRS's stated sigma sees the AHRS's error
RAYLEIGH_P90 = math.sqrt(2.0 * math.log(10.0))  # the 90th percentile of a 2-D error's size, in its sigma per axis


DECK_SURE_TILT_DEG = 0.5  # a pose whose image fixes the pad's tilt to this sees the pad's tilt against the IMU's up
DECK_TILT_DEG = 2.5  # ... and a pad that lies further from it than this tilts: no AHRS in our scenes erred half as far


def deck_as_seen(rows, pad_tilt_deg: float = 0.0) -> str:
    """Whether the pad lay further from the IMU's up than an AHRS errs where the image fixed its tilt
    (poses accepted or refused, right by the labels, whose image-only tilt sigma is under
    :data:`DECK_SURE_TILT_DEG`): their 90th percentile past :data:`DECK_TILT_DEG` says the pad tilts, a
    ship's deck, and that the localizer takes it for level unless told (``pad_tilt_deg``).  The AHRS
    is not blamed for it (:func:`ahrs_as_seen` would: a deck_swell flight read "state
    ahrs_tilt_sigma_deg of at least 1.4").  ``""`` where nothing says so."""
    t = np.array([r[10].get("tilt_err_deg", np.nan) for r in rows
                  if r[4] in ("ok", "rejected") and not r[8] and r[10].get("tilt_sigma_deg", np.inf) < DECK_SURE_TILT_DEG],
                 float)
    t = t[np.isfinite(t)]
    if not len(t) or np.percentile(t, 90) <= DECK_TILT_DEG:
        return ""
    p50, p90, top = np.percentile(t, 50), np.percentile(t, 90), float(t.max())
    line = (f"the pad lay p50/p90/max {p50:.1f}/{p90:.1f}/{top:.1f} deg from the IMU's up where {len(t)} poses fixed its tilt "
            f"from the image (sigma under {DECK_SURE_TILT_DEG:g} deg): further than an AHRS errs")
    if pad_tilt_deg <= 0:
        line += (f"\n    a deck that rolls and pitches? The localizer takes the pad for level until its markers show it "
                 f"tilting, and its far poses until then are wrong: state pad_tilt_deg of at least {math.ceil(top)} "
                 f"(README: Landing on a ship)")
    return line


def ahrs_as_seen(rows, ahrs_sigma_deg: float) -> str:
    """How far off the AHRS's gravity was where the image fixed the pad's tilt far better than the
    AHRS is said to (right accepted poses whose image-only tilt sigma is under
    :data:`SURE_TILT_SHARE` of ``ahrs_sigma_deg``: markers and tracks near the ground), and whether
    that is further than ``ahrs_sigma_deg``, the localizer's ``ahrs_tilt_sigma_deg``, allows: the
    90th percentile of the disagreement past :data:`RAYLEIGH_P90` of it (an AHRS stated 0.5 degrees
    was 0.65-1.2 off on unseen48).  ``""`` where no pose fixed the tilt so well."""
    t = np.array([[r[10].get("tilt_err_deg", np.nan), r[10].get("tilt_sigma_deg", np.nan)]
                  for r in rows if r[4] == "ok" and not r[8]], float).reshape(-1, 2)
    t = t[np.isfinite(t).all(axis=1) & (t[:, 1] < SURE_TILT_SHARE * ahrs_sigma_deg)]
    if not len(t):
        return ""
    p50, p90 = np.percentile(t[:, 0], [50, 90])
    per_axis = math.sqrt(float(np.mean(t[:, 0] ** 2)) / 2.0)
    line = (f"AHRS gravity where {len(t)} right poses fixed the tilt from the image (sigma under "
            f"{SURE_TILT_SHARE * ahrs_sigma_deg:.2f} deg): off by p50/p90/max {p50:.2f}/{p90:.2f}/{t[:, 0].max():.2f} deg, "
            f"{per_axis:.2f} deg per axis; the localizer was told {ahrs_sigma_deg:g}")
    if p90 > RAYLEIGH_P90 * ahrs_sigma_deg:
        line += (f"\n    the AHRS is further off than the localizer is told: state ahrs_tilt_sigma_deg of at least "
                 f"{math.ceil(per_axis * 10.0) / 10.0:g} (far poses take their tilt from it; README: state the whole size of the error)")
    return line


CORNER_SIZES = (0.0, 25.0, 40.0, 80.0, float("inf"))  # pad sides (px) the corner report groups frames by
ELSEWHERE_SHARE = 0.5  # a found outline whose worst corner is this share of its side off is another quad than the pad


def outline_corners(root, max_frames: int | None = None, every: int = 1) -> list:
    """Rows ``(seq, k, height, side px, corners used, error px (4,) | None, reason)``: the outline
    :func:`hvloc.phases.find_outline` finds in the whole frame (no prior, no region), against the
    labels, in every ``every``-th frame whose pad is whole in view and hidden by nothing.  The
    corners it posed by: the white field's where it uses them (against the field's labelled
    corners), else the outline's.  Found corners are matched to the labelled ones by the cyclic
    order, either way round, that lies nearest (an outline is not named here)."""
    from hvloc.phases import find_outline
    from render.dataset import Dataset

    rows = []
    for seq in Dataset(root):
        geo = seq.pad.geometry
        n = len(seq) if max_frames is None else min(len(seq), max_frames)
        for k in range(0, n, max(1, every)):
            f = seq.frame(k)
            if not f.pad_fully_visible:
                continue
            found, why = find_outline(seq.image(k), geo, seq.camera)
            if found is None:
                rows.append((seq.id, k, f.height_above_pad, float("nan"), "", None, why))
                continue
            orders = [np.roll(np.arange(4), s)[::d] for s in range(4) for d in (1, -1)]
            best = min(orders, key=lambda o: float(np.linalg.norm(found.quad_px[o] - f.corners_px, axis=1).sum()))
            if found.field_px is not None:
                used, px, truth = "field", found.field_px[best], seq.camera.project_from(f.cam2pad, geo.field_corners)
            else:
                used, px, truth = "outline", found.quad_px[best], f.corners_px
            rows.append((seq.id, k, f.height_above_pad, float(found.side_px), used,
                         np.linalg.norm(px - truth, axis=1), "ok"))
    return rows


def summarise_corners(rows) -> str:
    """Per pad size: frames, found, the corners' error (median and p90, px and % of the side), the
    worst corner of each frame's (median, p90), which corners were used; then the outlines found
    elsewhere (another quad than the pad: a decoy, searched for with no prior, as a first frame is),
    kept out of the accuracy, and why the rest were lost."""
    lines = []
    elsewhere = [r for r in rows if r[5] is not None and not r[5].max() < ELSEWHERE_SHARE * r[3]]
    for lo, hi in zip(CORNER_SIZES[:-1], CORNER_SIZES[1:]):
        found = [r for r in rows if r[5] is not None and lo <= r[3] < hi and r[5].max() < ELSEWHERE_SHARE * r[3]]
        if not found:
            continue
        err = np.concatenate([r[5] for r in found])
        share = np.concatenate([r[5] / r[3] * 100.0 for r in found])
        worst = np.array([r[5].max() for r in found])
        used = collections.Counter(r[4] for r in found)
        lines.append(f"side {lo:3.0f}-{hi:3.0f} px: {len(found):4d} found ({used['field']} by the field); corner error "
                     f"median {np.median(err):.2f} px ({np.median(share):.1f} % of the side), p90 "
                     f"{np.percentile(err, 90):.2f} px; worst corner median {np.median(worst):.2f}, "
                     f"p90 {np.percentile(worst, 90):.2f} px")
    if elsewhere:
        lines.append(f"found elsewhere: {len(elsewhere)} (worst corner over {ELSEWHERE_SHARE:g} of the side off; "
                     f"median {np.median([r[5].max() for r in elsewhere]):.0f} px)")
    lost = [r for r in rows if r[5] is None]
    lines.append(f"lost: {len(lost)} of {len(rows)} frames with the pad whole in view")
    for why, n in collections.Counter(reason_kind(r[6]) for r in lost).most_common(5):
        lines.append(f"    {n:4d}  {why}")
    return "\n".join(lines)


def main(argv=None, prog: str = "python -m benchmarks.diagnose") -> int:
    p = ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    p.add_argument("dataset", help="dataset folder")
    p.add_argument("--config", help="localizer config YAML (fields of hvloc/config.py)")
    p.add_argument("--frames", type=int, help="at most this many frames per sequence")
    p.add_argument("--no-imu", action="store_true", help="do not give the localizer the AHRS attitude")
    p.add_argument("--show-false", action="store_true", help="list every false accept and wrongly rejected frame")
    p.add_argument("--corners", type=int, metavar="EVERY", nargs="?", const=1,
                   help="instead: the outline's corners against the labels, per pad size (every EVERY-th frame)")
    a = p.parse_args(argv)
    if a.corners is not None:
        print(summarise_corners(outline_corners(a.dataset, a.frames, a.corners)))
        return 0
    cfg = load_config(a.config) if a.config else LocalizerConfig()
    rows = diagnose(a.dataset, cfg, a.frames, not a.no_imu)
    print(summarise(rows, cfg.ahrs_tilt_sigma_deg, cfg.pad_tilt_deg))
    if a.show_false:
        for r in rows:
            if (r[4] == "ok" and r[8]) or (r[4] == "rejected" and not r[8]):
                ex = {k: (round(v, 2) if isinstance(v, float) else v) for k, v in r[10].items() if k != "traceback"}
                print(f"{r[0]} {r[1]:4d} {r[2]:11s} h={r[3]:5.2f} {r[4]:8s} {r[5]:8s} pos {r[6]:.3f} rot {r[7]:.2f} "
                      f"{r[9][:60]} {ex}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
