"""Benchmark suites: datasets (spec, sequences, seed) x localizer configs, run and scored."""
from __future__ import annotations

import hashlib
import json
import math
import platform
import subprocess
import time
from pathlib import Path

import numpy as np
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from hvloc.config import LocalizerConfig
from pad_design.errors import InputError, load_yaml_model, progress_bar, validate_model, yaml_load

from . import metrics as M
from .run import localizer_class, pad_variants

RESULTS_SCHEMA = "hvloc-results/1"
REPO = Path(__file__).resolve().parent.parent


class DatasetEntry(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    spec: str = Field(description="dataset spec YAML, relative to the suite file or the repository")
    sequences: int | None = Field(None, ge=1)
    seed: int | None = Field(None, ge=0)
    overrides: dict = Field(default_factory=dict, description="spec fields to override (nested mapping)")
    tier: str | None = Field(None, pattern=r"^[A-Za-z0-9_-]+$", description="difficulty tier (nominal, hard, "
                             "extreme...): every score is also given per tier")
    pads: list[Literal["paper", "nested", "aruco", "apriltag", "aruco_nested"]] = Field(
        default_factory=list, description="the same descents again with these pad variants (datasets "
        "<name>_<variant>, same seed and tier): each localizer runs on those of the pad it needs")


class LocalizerEntry(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    name: str
    kind: str = Field("hierarchical", pattern=r"^[A-Za-z_][\w.]*(:[A-Za-z_][\w.]*)?$",
                      description="hierarchical, aruco (benchmarks/peers.py), a name registered under the "
                                  "hvloc.localizers entry point group, or an import path package.module:Class")
    gates: bool = Field(False, description="hvloc's false-pose gates (reprojection, motion, IMU tilt and "
                                           "rotation) in front of a peer; hvloc's own localizer has them built in")
    config: dict = Field(default_factory=dict, description="fields of hvloc's LocalizerConfig")
    use_imu: bool = True
    ahrs_error_scale: float = Field(1.0, ge=0.0, le=10.0, description="give the localizer an AHRS whose attitude "
                                    "error is this many times the dataset's (the benchmark knows the truth): "
                                    "what a better (under 1) or worse AHRS would buy on the same frames")
    datasets: list[str] | None = Field(None, description="names of the suite's datasets it runs on (default: all "
                                       "of the pad variant it needs)")


class Suite(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    name: str
    datasets: list[DatasetEntry] = Field(min_length=1)
    localizers: list[LocalizerEntry] = Field(min_length=1)


def _deep_update(d: dict, u: dict) -> dict:
    out = dict(d)
    for k, v in u.items():
        out[k] = _deep_update(out.get(k, {}), v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def load_suite(path) -> tuple:
    path = Path(path)
    if not path.exists():
        cand = REPO / "data_specs" / "suites" / f"{path.name}.yaml"
        if cand.exists():
            path = cand
    suite = load_yaml_model(Suite, path)
    from render.spec import DatasetSpec

    specs, entries = [], []
    for i, d in enumerate(suite.datasets):
        sp = (path.parent / d.spec) if (path.parent / d.spec).exists() else (REPO / d.spec)
        if not sp.exists():
            raise InputError(f"{path}: datasets.{i}.spec: {d.spec} not found")
        raw = yaml_load(sp.read_text()) or {}
        raw = _deep_update(raw, d.overrides)
        if d.sequences is not None:
            raw["sequences"] = d.sequences
        if d.seed is not None:
            raw["seed"] = d.seed
        spec = validate_model(DatasetSpec, raw, f"{path}: datasets.{i} ({d.spec})")
        specs.append(spec)
        entries.append(d.model_copy(update={"pads": []}))
        for v in d.pads:  # the same descents with another pad: one entry each, as if written out
            over = _deep_update(d.overrides, {"name": f"{spec.name}_{v}", "pad": {"variant": v}})
            specs.append(validate_model(DatasetSpec, _deep_update(raw, over), f"{path}: datasets.{i}.pads ({v})"))
            entries.append(d.model_copy(update={"pads": [], "overrides": over}))
    suite = suite.model_copy(update={"datasets": entries})
    configs = []
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        raise InputError(f"{path}: datasets: two datasets are named alike ({', '.join(names)}); "
                         "give one another name with overrides: {name: ...}")
    for i, loc in enumerate(suite.localizers):
        try:
            localizer_class(loc.kind)
        except InputError as err:
            raise InputError(f"{path}: localizers.{i}.kind: {err}") from None
        configs.append((loc, validate_model(LocalizerConfig, loc.config, f"{path}: localizers.{i}.config")))
        for n in loc.datasets or []:
            if n not in names:
                raise InputError(f"{path}: localizers.{i}.datasets: no dataset named {n!r} (the suite has "
                                 f"{', '.join(names)})")
        if not any(runs_on(loc, s) for s in specs):
            raise InputError(f"{path}: localizers.{i} ({loc.name}): no dataset of the pad variant it needs "
                             f"({', '.join(pad_variants(loc.kind))})")
    h = hashlib.sha256(json.dumps([s.sha256() for s in specs] + [_config_identity(c) for _, c in configs]
                                  + [_entry_identity(l) for l, _ in configs]
                                  ).encode()).hexdigest()
    return suite, specs, configs, h


# LocalizerConfig fields added after suites were first hashed, with the default that behaves as before
# the field existed: left out of the hash at that default, so adding one leaves every suite as it was
CONFIG_FIELDS_ADDED = {"pad_relief_m": 0.0, "imu_rows": True,  # fields added after suites were frozen, at their defaults
                       "ahrs_tilt_sigma_deg": 0.5, "pad_tilt_deg": 0.0}
# the same for a localizer entry's own fields
ENTRY_FIELDS_ADDED = {"gates": False, "ahrs_error_scale": 1.0}


def _config_identity(c: LocalizerConfig) -> str:
    return c.model_dump_json(exclude={k for k, v in CONFIG_FIELDS_ADDED.items() if getattr(c, k) == v} or None)


def _entry_identity(loc: LocalizerEntry) -> str:
    return loc.model_dump_json(exclude={k for k, v in ENTRY_FIELDS_ADDED.items() if getattr(loc, k) == v} or None)


def runs_on(loc: LocalizerEntry, spec) -> bool:
    """Whether a suite's localizer runs on a dataset: the ones it names, else those of its pad variant."""
    if loc.datasets is not None:
        return spec.name in loc.datasets
    return spec.pad.variant in pad_variants(loc.kind)


def provenance() -> dict:
    from render.dataset import package_versions

    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True,
                                timeout=5).stdout.strip() or None
        dirty = bool(subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=REPO,
                                    capture_output=True, text=True, timeout=5).stdout.strip())
    except (OSError, subprocess.SubprocessError):
        commit, dirty = None, None
    import os

    return {"commit": commit, "dirty": dirty, "machine": {"platform": platform.platform(),
            "processor": platform.processor() or platform.machine(), "cpus": os.cpu_count()},
            "versions": package_versions(), "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def run_suite(suite_path, out, workers: int = 1, show_progress: bool = True, executor: str = "local",
              ray_address: str | None = None, verify: bool = True) -> dict:
    """Generate (or reuse) the suite's datasets, run each localizer, score, write results.
    ``verify``: refuse datasets whose files differ from their checksums (as they are read)."""
    from render.dataset import FolderLock

    suite, specs, configs, suite_hash = load_suite(suite_path)
    out = Path(out)
    with FolderLock(out, "writing results into"):
        return _run_suite(suite, specs, configs, suite_hash, out, workers, show_progress, executor, ray_address,
                          verify)


def _run_suite(suite, specs, configs, suite_hash, out, workers, show_progress, executor, ray_address, verify):
    from render.dataset import Dataset
    from render.executor import run_units
    from render.generate import generate

    from .run import read_estimates

    data_root = out / "datasets"
    tiers = {spec.name: entry.tier for spec, entry in zip(specs, suite.datasets)}
    rows, per_seq, fes_by_loc, fes_by_ds = [], {}, {}, {}
    timing = {}
    for spec in specs:
        droot = data_root / f"{spec.name}-{spec.sha256()[:10]}"
        t0 = time.time()
        generate(spec, droot, workers=workers, show_progress=show_progress, executor=executor, ray_address=ray_address)
        timing[f"generate:{spec.name}"] = time.time() - t0
        ds = Dataset(droot, verify=verify)
        here = [(loc, cfg) for loc, cfg in configs if runs_on(loc, spec)]
        if not here:
            continue
        t0 = time.time()
        bar = progress_bar(show_progress, sum(len(s) for s in ds), f"localize x{len(here)} {spec.name}")
        setups = [(cfg.model_dump(), loc.use_imu, loc.kind, loc.gates, loc.ahrs_error_scale) for loc, cfg in here]
        lengths = {sid: s["frames"] for sid, s in ((s["id"], s) for s in ds.manifest["sequences"])}
        jobs = [(str(droot), sid, setups, [str(out / "estimates" / loc.name / droot.name / sid) for loc, _ in here],
                 verify) for sid in sorted(ds.sequence_ids, key=lambda s: -lengths[s])]  # longest first
        for n in run_units(_localize_unit, jobs, workers, executor, ray_address, progress=bar.update if bar else None):
            if bar and executor == "ray":
                bar.update(n)
        if bar:
            bar.close()
        timing[f"localize:{spec.name}"] = time.time() - t0
        for loc, cfg in here:
            rdir = out / "estimates" / loc.name / droot.name
            for seq in ds:
                est = read_estimates(rdir / seq.id / "estimates.csv")
                fe = M.frame_errors(seq.columns, est)
                key = f"{loc.name}/{spec.name}/{seq.id}"
                per_seq[key] = M.score_sequence(fe)
                per_seq[key]["family"] = seq.meta.get("family")
                fes_by_loc.setdefault(loc.name, []).append(fe)
                fes_by_ds.setdefault((loc.name, spec.name), []).append(fe)
                for k in range(len(fe["status"])):
                    rows.append([loc.name, spec.name, seq.id, k, float(fe["t_s"][k]), float(fe["height_m"][k]),
                                 str(fe["phase_gt"][k]), str(fe["phase_est"][k]), str(fe["status"][k]),
                                 float(fe["pos_err_m"][k]), float(fe["rot_err_deg"][k]), float(fe["ms"][k])])
    summary = {}
    for name, fes in fes_by_loc.items():
        fe = M.concat(fes)
        summary[name] = M.phase_scopes(fe)
        summary[name]["datasets"] = [d for (n, d) in fes_by_ds if n == name]
        for (n, d), dfes in fes_by_ds.items():  # per dataset, e.g. to set a peer beside hvloc on the same descents
            if n == name:
                summary[name].update({f"{d}/{k}": v for k, v in M.phase_scopes(M.concat(dfes)).items()})
        for tier in dict.fromkeys(t for t in tiers.values() if t):  # per difficulty tier, in suite order
            tfes = [f for (n, d), dfes in fes_by_ds.items() if n == name and tiers[d] == tier for f in dfes]
            if tfes:
                summary[name].update({f"tier:{tier}/{k}": v for k, v in M.phase_scopes(M.concat(tfes)).items()})
        contact = [per_seq[k]["contact_pos_err_m"] for k in per_seq if k.startswith(name + "/")]
        contact = [c for c in contact if c is not None]
        summary[name]["contact_pos_err_m_max"] = max(contact) if contact else None
    ci95 = {}  # bootstrap over descents (benchmarks/metrics.py: bootstrap_ci), per localizer and scope
    for name, fes in fes_by_loc.items():
        groups = {"all": fes}
        for tier in dict.fromkeys(t for t in tiers.values() if t):
            groups[f"tier:{tier}"] = [f for (n, d), dfes in fes_by_ds.items() if n == name and tiers[d] == tier
                                      for f in dfes]
        ci95[name] = {}
        for g, gfes in groups.items():
            for scope in ("all", *(f"gt:{p}" for p in M.PHASES)):
                key = scope if g == "all" else f"{g}/{scope}"
                stats = [M.sufficient_stats(f, None if scope == "all" else f["phase_gt"] == scope[3:]) for f in gfes]
                ci95[name][key] = M.bootstrap_ci(stats)
    results = {"schema": RESULTS_SCHEMA, "suite": suite.name, "suite_sha256": suite_hash,
               "provenance": provenance(), "workers": workers, "summary": summary, "ci95": ci95, "sequences": per_seq,
               "timing_s": timing,
               "localizers": {l.name: c.model_dump() for l, c in configs},
               "localizer_setup": {l.name: {"kind": l.kind, "use_imu": l.use_imu, "ahrs_error_scale": l.ahrs_error_scale,
                                            "datasets": [s.name for s in specs if runs_on(l, s)]} for l, _ in configs}}
    from render.dataset import atomic_write_text, write_csv

    atomic_write_text(out / "results.json", json.dumps(_clean(results), indent=1) + "\n")
    write_csv(out / "results.csv", ["localizer", "dataset", "sequence", "frame", "t", "height_m", "phase_gt",
                                    "phase_est", "status", "pos_err_m", "rot_err_deg", "ms"], rows)
    from .report import write_report

    write_report(out, results, fes_by_loc, data_root)
    return results


def _localize_unit(droot: str, seq_id: str, setups: list, dirs: list, verify: bool, share_work: bool = True) -> int:
    """Every setup over one sequence (each image read once), estimates written; returns the frame
    count.  A unit of work for :func:`render.executor.run_units`."""
    from render.dataset import Dataset
    from render.executor import report_progress

    from .run import localize_sequence_many, write_estimates

    seq = Dataset(droot, verify=verify)[seq_id]
    ests = localize_sequence_many(seq, [(LocalizerConfig.model_validate(s[0]), *s[1:]) for s in setups],
                                  report_progress, share_work=share_work)
    for d, est in zip(dirs, ests):
        write_estimates(Path(d), est, seq.columns["frame"])
    return len(seq)


def _clean(o):
    if isinstance(o, dict):
        return {k: _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    if isinstance(o, (np.floating, float)):
        return None if not np.isfinite(o) else float(o)
    if isinstance(o, np.integer):
        return int(o)
    return o


def load_results(path) -> dict:
    p = Path(path)
    if p.is_dir():
        p = p / "results.json"
    try:
        r = json.loads(p.read_text())
    except (OSError, ValueError) as err:
        raise InputError(f"{p}: cannot read results ({err})") from None
    if r.get("schema") != RESULTS_SCHEMA:
        raise InputError(f"{p}: results schema {r.get('schema')!r}, expected {RESULTS_SCHEMA!r}")
    return r


# metric -> (direction, absolute tolerance): "lower" is better or "higher" is better, or "one": nearer 1
TOLERANCES = {
    "availability": ("higher", 0.01),
    "pos_err_m_rmse": ("lower", 0.002),
    "pos_err_pct_median": ("lower", 0.05),
    "rot_err_deg_rmse": ("lower", 0.05),
    "false_accepts": ("lower", 0),
    "longest_gap_s": ("lower", 0.2),
    "beyond_cov_3sigma": ("lower", 0.01),
    # how many times its stated sigma the error is: nearer 1 is better either way (ln units: 10 %)
    "pos_cov_scale": ("one", 0.1),
    # the height's bias (signed median, % of the height): nearer 0 is better either way
    "height_err_pct_median": ("zero", 0.05),
}


def _worse(direction: str, tol: float, base: float, new: float) -> bool:
    if direction == "lower":
        return new > base + tol
    if direction == "higher":
        return new < base - tol
    if direction == "zero":
        return abs(new) > abs(base) + tol
    off = lambda v: abs(math.log(max(v, 1e-9)))  # "one": how far from 1, by ratio
    return off(new) > off(base) + tol


def compare(new: dict, base: dict, tolerances: dict = TOLERANCES, significant: bool = False) -> list:
    """Rows (localizer, scope, metric, baseline, new) of everything that got worse beyond tolerance.
    ``significant``: where the baseline has a 95 % interval over descents for the metric (``ci95``),
    only a new value beyond that interval counts (a change the descents' spread cannot explain)."""
    worse = []
    cis = base.get("ci95", {})
    for loc, scopes in base["summary"].items():
        if loc not in new["summary"]:
            worse.append((loc, "-", "missing in new results", None, None))
            continue
        for scope, metrics in scopes.items():
            if not isinstance(metrics, dict):
                continue
            for m, (direction, tol) in tolerances.items():
                b = M.metric(metrics, m)
                n = M.metric(new["summary"][loc].get(scope, {}), m)
                if b is None:
                    continue
                if n is None:
                    worse.append((loc, scope, m, b, n))
                elif _worse(direction, tol, b, n):
                    ci = cis.get(loc, {}).get(scope, {}).get(m) if significant else None
                    if ci is not None and ci[0] <= n <= ci[1]:
                        continue
                    worse.append((loc, scope, m, b, n))
    return worse
