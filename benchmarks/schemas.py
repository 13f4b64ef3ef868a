"""JSON Schemas of every file a user writes or a tool reads: dataset and pad specs, suites, the
localizer config, ``results.json``.  ``python -m benchmarks.schemas`` rewrites ``data_specs/schema/``.

The spec schemas come from the pydantic models the loaders validate with, rewritten in the
draft-07 form that editor extensions (the YAML language server of VS Code and others) implement:
fixed-length tuples as ``items: [...]`` instead of 2020-12's ``prefixItems``, ``definitions``
instead of ``$defs``; each has a ``$schema`` and an ``$id``.  The loaders validate as strictly as
these schemas (``pad_design.errors.validate_model``): ``"320"`` is not a number for either.
This module lives in ``benchmarks`` because the suite model does (it may import every package).
"""
from __future__ import annotations

import json
from pathlib import Path

from pad_design.errors import DRAFT, editor_schema, schema_id

REPO = Path(__file__).resolve().parent.parent
SCHEMA_DIR = REPO / "data_specs" / "schema"


def _metrics() -> dict:
    num = {"type": ["number", "null"]}
    return {"type": "object", "required": ["frames"],  # an empty scope has only its frame count
            "properties": {"frames": {"type": "integer", "minimum": 0},
                           "availability": {"type": ["number", "null"], "minimum": 0, "maximum": 1},
                           "false_accepts": {"type": "integer", "minimum": 0}},
            "additionalProperties": num}


def results_schema() -> dict:
    """``results.json`` of ``hvloc bench run`` (``hvloc-results/1``)."""
    from .suite import RESULTS_SCHEMA

    switch = {"type": "array", "items": [{"type": "string"}, {"type": "string"}, {"type": ["number", "null"]}],
              "additionalItems": False, "minItems": 3}
    return {
        "$schema": DRAFT, "$id": schema_id("results"), "title": "hvloc bench run: results.json",
        "type": "object",
        "required": ["schema", "suite", "suite_sha256", "provenance", "summary", "sequences", "localizers",
                     "localizer_setup"],
        "properties": {
            "schema": {"const": RESULTS_SCHEMA},
            "suite": {"type": "string"},
            "suite_sha256": {"type": "string", "pattern": "^[0-9a-f]{64}$"},
            "provenance": {"type": "object", "required": ["commit", "machine", "versions", "date"],
                           "properties": {"versions": {"type": "object"}, "date": {"type": "string"}}},
            "workers": {"type": "integer", "minimum": 1},
            "timing_s": {"type": "object", "additionalProperties": {"type": ["number", "null"]}},
            "summary": {"description": "per localizer: scopes all, gt:<phase>, <dataset>/<scope>, tier:<tier>/<scope>",
                        "type": "object", "additionalProperties": {
                            "type": "object", "required": ["all", "datasets"],
                            "properties": {"datasets": {"type": "array", "items": {"type": "string"}},
                                           "contact_pos_err_m_max": {"type": ["number", "null"]}},
                            "additionalProperties": {"$ref": "#/definitions/metrics"}}},
            "ci95": {"description": "per localizer and scope: 95 % bootstrap interval over descents [lo, hi]",
                     "type": "object", "additionalProperties": {"type": "object", "additionalProperties": {
                         "type": "object", "additionalProperties": {
                             "anyOf": [{"type": "null"}, {"type": "array", "items": {"type": "number"},
                                                          "minItems": 2, "maxItems": 2}]}}}},
            "sequences": {"description": "per <localizer>/<dataset>/<sequence>", "type": "object",
                          "additionalProperties": {
                              "type": "object", "required": ["all"],
                              "properties": {"family": {"type": "string"}, "switches": {"type": "array", "items": switch},
                                             "gt_boundaries": {"type": "array", "items": switch},
                                             "contact_pos_err_m": {"type": ["number", "null"]}},
                              "additionalProperties": {"$ref": "#/definitions/metrics"}}},
            "localizers": {"type": "object", "additionalProperties": {"type": "object"}},
            "localizer_setup": {"type": "object", "additionalProperties": {
                "type": "object", "required": ["kind", "use_imu", "datasets"],
                "properties": {"kind": {"type": "string"}, "use_imu": {"type": "boolean"},
                               "ahrs_error_scale": {"type": "number", "minimum": 0},
                               "datasets": {"type": "array", "items": {"type": "string"}}}}},
        },
        "definitions": {"metrics": _metrics()},
    }


def schemas() -> dict:
    """``{name: schema}`` of every schema ``data_specs/schema/`` holds."""
    from hvloc.config import LocalizerConfig
    from pad_design.spec import PadSpec
    from render.spec import DatasetSpec

    from .suite import Suite

    out = {"dataset_spec": editor_schema(DatasetSpec.model_json_schema(), "dataset_spec", "hvloc dataset spec"),
           "pad_spec": editor_schema(PadSpec.model_json_schema(), "pad_spec", "hvloc pad spec"),
           "localizer_config": editor_schema(LocalizerConfig.model_json_schema(), "localizer_config",
                                             "hvloc localizer config")}
    suite = editor_schema(Suite.model_json_schema(), "suite", "hvloc benchmark suite")
    # a localizer's config is a LocalizerConfig: an editor completes and checks it there too
    cfg = {k: v for k, v in out["localizer_config"].items() if not k.startswith("$") and k != "title"}
    suite.setdefault("definitions", {})
    suite["definitions"].update(cfg.pop("definitions", {}))
    suite["definitions"]["LocalizerConfig"] = cfg
    suite["definitions"]["LocalizerEntry"]["properties"]["config"] = {
        "$ref": "#/definitions/LocalizerConfig", "description": "fields of hvloc's LocalizerConfig"}
    out["suite"] = suite
    out["results"] = results_schema()
    return out


def export_schemas(out_dir=SCHEMA_DIR) -> list:
    """Write every schema as ``<name>.schema.json`` into ``out_dir``; returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, schema in schemas().items():
        p = out / f"{name}.schema.json"
        p.write_text(json.dumps(schema, indent=1) + "\n")
        paths.append(p)
    return paths


def validator(name: str):
    """A ``jsonschema`` validator of schema ``name`` as committed in ``data_specs/schema/``."""
    import jsonschema

    schema = json.loads((SCHEMA_DIR / f"{name}.schema.json").read_text())
    return jsonschema.Draft7Validator(schema, format_checker=jsonschema.FormatChecker())


if __name__ == "__main__":
    for p in export_schemas():
        print(p)
