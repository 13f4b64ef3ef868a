"""The JSON Schemas and the loaders agree: every shipped YAML names its schema and passes both,
and the same bad files fail both.  The schemas are draft-07, as editor extensions implement it."""
import json
import re
import tempfile
from pathlib import Path

import jsonschema
import pytest
import yaml

from benchmarks.schemas import SCHEMA_DIR, export_schemas, validator
from hvloc.config import LocalizerConfig
from pad_design.errors import InputError, load_yaml_model, yaml_load
from pad_design.spec import PadSpec
from render.spec import DatasetSpec

REPO = Path(__file__).parent.parent
MODELINE = re.compile(r"^# yaml-language-server: \$schema=(\S+)$")


def _load_suite(path):
    from benchmarks.suite import load_suite

    return load_suite(path)


LOADERS = {"dataset_spec": lambda p: load_yaml_model(DatasetSpec, p), "pad_spec": lambda p: load_yaml_model(PadSpec, p),
           "localizer_config": lambda p: load_yaml_model(LocalizerConfig, p), "suite": _load_suite}


def test_schemas_are_current_and_draft7_with_ids():
    with tempfile.TemporaryDirectory() as d:
        for new in export_schemas(d):
            committed = SCHEMA_DIR / new.name
            assert committed.exists() and committed.read_text() == new.read_text(), \
                f"{committed} is stale: run python -m benchmarks.schemas"
    for p in SCHEMA_DIR.glob("*.schema.json"):
        s = json.loads(p.read_text())
        jsonschema.Draft7Validator.check_schema(s)
        assert s["$schema"] == "http://json-schema.org/draft-07/schema#" and s["$id"].startswith("urn:hvloc:schema:")
        text = p.read_text()
        assert "prefixItems" not in text and "$defs" not in text, p  # 2020-12 forms editors do not read


def test_every_shipped_yaml_names_its_schema_and_passes_schema_and_loader():
    shipped = sorted((REPO / "data_specs").glob("*.yaml")) + sorted((REPO / "data_specs" / "suites").glob("*.yaml"))
    shipped += sorted((REPO / "data_specs" / "localizer").glob("*.yaml"))  # localizer configs
    assert len(shipped) >= 6
    for p in shipped:
        first = p.read_text().splitlines()[0]
        m = MODELINE.match(first)
        assert m, f"{p}: no yaml-language-server modeline"
        schema_path = (p.parent / m.group(1)).resolve()
        assert schema_path.is_file(), p
        name = schema_path.name.removesuffix(".schema.json")
        errors = list(validator(name).iter_errors(yaml_load(p.read_text())))
        assert not errors, (p, errors[0].message)
        LOADERS[name](p)


# (schema, YAML, a word the loader's one-line error must contain): both must refuse each
BAD = [
    ("dataset_spec", "name: a\ncamera: {width: '320'}\n", "camera.width"),
    ("dataset_spec", "name: a\ncamera: {fps: '10'}\n", "camera.fps"),
    ("dataset_spec", "name: a\nsequences: 2.5\n", "sequences"),
    ("dataset_spec", "name: a\nseed: true\n", "seed"),
    ("dataset_spec", "name: a\ncamera: {width: -3}\n", "camera.width"),
    ("dataset_spec", "name: a\ncamera: {dist: [0.1, 0.2]}\n", "camera.dist"),
    ("dataset_spec", "name: a\ncamera: {dist: [0.1, 0.2, 0, 0, 0, 0.3]}\n", "camera.dist"),
    ("dataset_spec", "name: a\ncamera: {widht: 320}\n", "widht"),
    ("dataset_spec", "name: a\ntrajectory: {duration_s: ['10', 12]}\n", "trajectory.duration_s"),
    ("dataset_spec", "name: a\nimu: {rate_hz: 0}\n", "imu.rate_hz"),
    ("dataset_spec", "name: a\nenvironment: {ground: [grass, lava]}\n", "environment.ground"),
    ("pad_spec", "side_m: '0.85'\n", "side_m"),
    ("pad_spec", "variant: round\n", "variant"),
    ("localizer_config", "adjust_height_m: 'high'\n", "adjust_height_m"),
    ("localizer_config", "use_flow: 'yes'\n", "use_flow"),
    ("localizer_config", "max_reprojection_px: 2\nunknown_knob: 1\n", "unknown_knob"),
    ("suite", "name: s\ndatasets: []\nlocalizers: [{name: h}]\n", "datasets"),
    ("suite", "name: s\ndatasets: [{spec: data_specs/tiny.yaml, sequences: '2'}]\nlocalizers: [{name: h}]\n", "sequences"),
    ("suite", "name: s\ndatasets: [{spec: data_specs/tiny.yaml}]\nlocalizers: [{name: h, kind: 'two words'}]\n", "kind"),
    ("suite", "name: s\ndatasets: [{spec: data_specs/tiny.yaml}]\nlocalizers: [{name: h, config: {use_imu_gate: 1}}]\n",
     "use_imu_gate"),
]
GOOD = [
    ("dataset_spec", "name: a\ncamera: {width: 320, height: 240, fps: 10}\nimu: {gyro_noise_rad_s: 3e-3}\n"),
    ("dataset_spec", "name: a\ncamera: {exposure_s: 1e-3, dist: [-0.1, 0.01, 0, 0, 0]}\n"),
    ("pad_spec", "side_m: 1\n"),  # an integer is a number
    ("localizer_config", "adjust_height_m: 6\nuse_flow: false\n"),
    ("suite", "name: s\ndatasets: [{spec: data_specs/tiny.yaml, sequences: 1}]\nlocalizers: [{name: h, config: {adjust_height_m: 5}}]\n"),
]


@pytest.mark.parametrize("name,text,word", BAD, ids=[f"{n}:{w}:{i}" for i, (n, _, w) in enumerate(BAD)])
def test_the_same_bad_file_fails_schema_and_loader(name, text, word, tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text(text)
    assert list(validator(name).iter_errors(yaml_load(text))), f"the schema accepts {text!r}"
    with pytest.raises(InputError) as err:
        LOADERS[name](p)
    assert word in str(err.value), str(err.value)


@pytest.mark.parametrize("name,text", GOOD)
def test_the_same_good_file_passes_schema_and_loader(name, text, tmp_path):
    p = tmp_path / "good.yaml"
    p.write_text(text)
    data = yaml_load(text)
    errors = list(validator(name).iter_errors(data))
    assert not errors, errors[0].message
    if name == "suite":  # relative to the repository, like the shipped suites
        p = REPO / "data_specs" / "suites" / ".test_good_suite.yaml"
        p.write_text(text)
        try:
            LOADERS[name](p)
        finally:
            p.unlink()
    else:
        LOADERS[name](p)
    assert yaml.safe_load("a: 1e-3")["a"] == "1e-3" and data  # what plain PyYAML would have made of it


def test_committed_baseline_results_validate():
    r = json.loads((REPO / "benchmarks" / "baselines" / "smoke.json").read_text())
    errors = list(validator("results").iter_errors(r))
    assert not errors, errors[0].message
    r["summary"]["hierarchical"]["all"]["frames"] = "many"
    assert list(validator("results").iter_errors(r))
