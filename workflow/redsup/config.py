"""Configuration: JSON-schema validation (additionalProperties: false) and size profiles.

`config.yaml` holds the base values of every section and, under `profiles`, partial overrides per size
profile (`tiny`, `default`, `paper`). `resolve(raw)` validates the raw file, checks that every override
names an existing key, merges the chosen profile onto the base and validates the result again.
"""
from __future__ import annotations

import copy
import hashlib
import json
from pathlib import Path
from typing import Any

import yaml

from redsup.fileio import yaml_dump, yaml_load

SCHEMA_DIR = Path(__file__).resolve().parents[1] / "schemas"
PROFILES = ("tiny", "default", "paper")


class ConfigError(ValueError):
    """A configuration problem, with the offending key path in the message."""


def load_schema(schema_dir: Path = SCHEMA_DIR) -> dict:
    """The top-level schema with every `{"$ref": "<file>.schema.yaml"}` replaced by that file."""

    def inline(node: Any) -> Any:
        if isinstance(node, dict):
            ref = node.get("$ref")
            if isinstance(ref, str) and ref.endswith(".yaml"):
                return inline(yaml_load((schema_dir / ref).read_text()))
            return {k: inline(v) for k, v in node.items()}
        if isinstance(node, list):
            return [inline(v) for v in node]
        return node

    return inline(yaml_load((schema_dir / "config.schema.yaml").read_text()))


def _path(error) -> str:   # a jsonschema.ValidationError
    return ".".join(str(p) for p in error.absolute_path) or "<top level>"


def _message(error) -> str:   # a jsonschema.ValidationError
    """The error's message; for a value that fits none of a oneOf / anyOf's shapes (e.g. a table section of a
    stage with several table shapes), the errors of the shape it comes closest to: the one whose required keys
    it has, with the fewest errors, so a misspelled key inside it is still named."""
    if error.validator not in ("oneOf", "anyOf") or not error.context:
        return error.message
    branches: dict = {}
    for sub in error.context:
        branches.setdefault(sub.relative_schema_path[0], []).append(sub)
    closest = min(branches.values(), key=lambda errs: (
        any(e.validator == "required" and not e.relative_path for e in errs), len(errs)))
    return "fits none of its shapes; closest: " + "; ".join(f"{_path(e)}: {e.message}" for e in closest)


def validate(cfg: dict, schema: dict, where: str = "config.yaml") -> None:
    """Raise ConfigError listing every schema violation with its key path."""
    import jsonschema   # here: every job imports this module (config_hash) and never validates

    validator = jsonschema.Draft202012Validator(schema)
    errors = sorted(validator.iter_errors(cfg), key=lambda e: list(e.absolute_path))
    if errors:
        lines = [f"  - {_path(e)}: {_message(e)}" for e in errors]
        raise ConfigError(f"{where}: invalid configuration:\n" + "\n".join(lines))


def _check_override_keys(base: dict, override: dict, prefix: str) -> None:
    for key, value in override.items():
        here = f"{prefix}.{key}"
        if key not in base:
            raise ConfigError(f"config.yaml: {here} is not a known key (known here: {sorted(base)})")
        if isinstance(value, dict) and isinstance(base[key], dict) and base[key]:
            _check_override_keys(base[key], value, here)


def deep_merge(base: dict, override: dict) -> dict:
    """A new dict: `override` merged onto `base`, recursing into dicts, replacing everything else."""
    out = copy.deepcopy(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def resolve(raw: dict, schema: dict | None = None) -> dict:
    """Validate `raw`, apply `profiles[raw['profile']]`, validate again; returns the effective config.

    The effective config has no `profiles` key; `profile` names the one applied.
    """
    schema = schema or load_schema()
    validate(raw, schema)
    profile = raw["profile"]
    profiles = raw.get("profiles", {})
    if profile not in profiles:
        raise ConfigError(f"config.yaml: profile '{profile}' is not defined (have {sorted(profiles)})")
    base = {k: v for k, v in raw.items() if k != "profiles"}
    merged = {}
    for name, override in profiles.items():
        _check_override_keys(base, override or {}, f"profiles.{name}")
        merged[name] = deep_merge(base, override or {})
        validate({**merged[name], "profiles": profiles}, schema,
                 where=f"config.yaml with profile '{name}'")
    return merged[profile]


def load(path: str | Path, overrides: dict | None = None) -> dict:
    """Read a YAML config file, apply command-line style overrides, resolve the profile."""
    path = Path(path)
    try:
        raw = yaml_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML: {exc}") from exc
    return resolve(deep_merge(raw, overrides or {}))


def config_hash(cfg: dict) -> str:
    """Short stable hash of a (resolved) config, for run tags."""
    blob = json.dumps(cfg, sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()[:12]


def save(cfg: dict, path: str | Path) -> None:
    """Write the config beside a checkpoint or metrics file."""
    Path(path).write_text(yaml_dump(cfg))
