"""Input errors shared by every hvloc package (this is the lowest package, so all may import it).

Library code raises :class:`InputError` for bad user input (specs, configs, datasets); the
CLI front door turns it into one line on stderr and exit code 2.  Nothing else prints.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import sys
from pathlib import Path

import yaml
from pydantic import BaseModel, ValidationError


class InputError(ValueError):
    """Bad user input: a spec, config or dataset that cannot be used.  The message names the field."""


def describe_validation_error(err: ValidationError, source: str = "") -> str:
    """One line naming the first offending field, e.g. ``spec.yaml: camera.fx: must be > 0``."""
    first = err.errors()[0]
    loc = ".".join(str(p) for p in first.get("loc", ())) or "(top level)"
    msg = first.get("msg", "invalid").removeprefix("Value error, ")
    if first.get("type") == "extra_forbidden":
        msg = "unknown key"
    more = len(err.errors()) - 1
    tail = f" (and {more} more problem{'s' if more > 1 else ''})" if more > 0 else ""
    prefix = f"{source}: " if source else ""
    if loc == "(top level)" and ":" in msg.split(" ")[0]:
        return f"{prefix}{msg}{tail}"  # a cross-field check that names its field itself
    return f"{prefix}{loc}: {msg}{tail}"


def validate_model(model: type[BaseModel], data, source: str = ""):
    """Validate ``data`` into ``model`` or raise :class:`InputError` with one clear line."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise InputError(f"{source or 'spec'}: expected a mapping at the top level, got {type(data).__name__}")
    try:
        text = json.dumps(data, allow_nan=True, default=_not_json)
    except _NotJson as err:
        raise InputError(f"{source or 'spec'}: {err}") from None
    try:
        # strict, as JSON: what the JSON Schemas in data_specs/schema/ accept and nothing more
        # ("320" is not a number, 1 is not true); arrays are tuples and integers are numbers
        return model.model_validate_json(text, strict=True)
    except ValidationError as err:
        raise InputError(describe_validation_error(err, source)) from None


class _NotJson(TypeError):
    pass


def _not_json(value):
    raise _NotJson(f"{value!r} ({type(value).__name__}) is not a number, string, boolean, list or mapping")


class _Yaml12Loader(yaml.SafeLoader):
    """PyYAML reads YAML 1.1, where ``1e-5`` is a string; editors and JSON Schema tools read YAML
    1.2, where it is a number.  Floats are resolved as YAML 1.2 does, so both agree."""


_Yaml12Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                    |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
                    |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
                    |[-+]?\.(?:inf|Inf|INF)
                    |\.(?:nan|NaN|NAN))$""", re.X),
    list("-+0123456789."))


def yaml_load(text: str):
    """YAML text -> Python data, numbers as YAML 1.2 reads them."""
    return yaml.load(text, Loader=_Yaml12Loader)  # noqa: S506  (a SafeLoader subclass)


def read_user_text(path, what: str = "YAML") -> str:
    """A user's text file; a file that cannot be read or is not UTF-8 text is an :class:`InputError`."""
    path = Path(path)
    try:
        return path.read_text(encoding="utf-8")
    except OSError as err:
        raise InputError(f"{path}: cannot read ({err.strerror or err})") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text file ({what} must be UTF-8 text)") from None


def load_yaml_model(model: type[BaseModel], path) -> BaseModel:
    """Read a YAML file into a validated pydantic model; every failure is an :class:`InputError`."""
    path = Path(path)
    text = read_user_text(path)
    try:
        data = yaml_load(text)
    except yaml.YAMLError as err:
        raise InputError(f"{path}: not valid YAML ({str(err).splitlines()[0]})") from None
    if data is None:
        raise InputError(f"{path}: the file is empty (write at least one field; every field has a default)")
    return validate_model(model, data, str(path))


# ----------------------------------------------------------------------------- JSON Schemas

DRAFT = "http://json-schema.org/draft-07/schema#"


def schema_id(name: str) -> str:
    return f"urn:hvloc:schema:{name}:1"


def editor_schema(schema: dict, name: str, title: str) -> dict:
    """A pydantic (JSON Schema 2020-12) schema in the draft-07 form that editor extensions (the
    YAML language server and others) implement: fixed-length tuples as ``items: [...]`` rather
    than ``prefixItems``, ``definitions`` rather than ``$defs``; with ``$schema`` and ``$id``."""

    def walk(o):
        if isinstance(o, list):
            return [walk(v) for v in o]
        if not isinstance(o, dict):
            return o
        out = {}
        for k, v in o.items():
            if k == "$defs":
                out["definitions"] = walk(v)
            elif k == "$ref" and isinstance(v, str):
                out[k] = v.replace("#/$defs/", "#/definitions/")
            elif k == "prefixItems":
                out["items"] = walk(v)
                out["additionalItems"] = False
            else:
                out[k] = walk(v)
        return out

    body = walk(schema)
    body.pop("title", None)
    return {"$schema": DRAFT, "$id": schema_id(name), "title": title, **body}


# ----------------------------------------------------------------------------- command lines

class ArgumentParser(argparse.ArgumentParser):
    """argparse with hvloc's error contract: a bad command line is one line on stderr and exit 2
    (argparse itself prints the usage first; ``--help`` still shows it)."""

    def error(self, message):  # noqa: D401  (argparse's hook)
        self.exit(2, f"{self.prog}: error: {message}\n")

    def add_argument(self, *args, **kwargs):
        """Every argument says what it is for: one without ``help`` is a bug, caught when the
        parser is built (a test builds every command's parser through ``--help``)."""
        if not kwargs.get("help") and not (args and args[0] in ("-h", "--help")):
            raise ValueError(f"{self.prog}: argument {'/'.join(args) or kwargs.get('dest')} has no help text")
        return super().add_argument(*args, **kwargs)

    def add_quiet(self) -> None:
        """``-q/--quiet``, the same on every command that shows progress."""
        self.add_argument("-q", "--quiet", action="store_true",
                          help="no progress bars (they are only drawn when stderr is a terminal anyway)")


def progress_bar(enabled: bool, total, desc: str, **kwargs):
    """A tqdm bar on stderr, or ``None`` when it is not wanted or stderr is not a terminal (a log
    file or CI gets no bar updates).  Callers pass ``bar.update if bar else None`` on.  ``total``:
    a number, or a function giving it (only called when a bar is drawn)."""
    if not enabled or not sys.stderr.isatty():
        return None
    from tqdm import tqdm

    return tqdm(total=total() if callable(total) else total, desc=desc, unit="frame", **kwargs)


def workers_arg(text: str) -> int:
    """argparse ``type`` for ``--workers``: an integer >= 1, the same on every command."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {n}")
    return n


def prepare_out_dir(path, flag: str = "--out") -> Path:
    """Create the output folder ``path`` (and its parents), or raise :class:`InputError` saying why
    it cannot be one: it exists and is not a folder, a parent is a file, no permission, a
    read-only file system.  Call it before anything is written."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise InputError(f"{flag} {p}: exists and is not a folder")
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(f"{flag} {p}: cannot create this folder ({err.strerror or err})") from None
    if not os.access(p, os.W_OK | os.X_OK):
        raise InputError(f"{flag} {p}: the folder is not writable")
    return p
