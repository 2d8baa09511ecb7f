"""Configuration dataclasses shared by the cores, the nodes and the offline tools (no ROS here).

Every algorithm core describes its constants as a dataclass whose fields are made with
:func:`param`: the default (the paper's value where the paper gives one), a one-line description,
and a valid range or set of choices. The nodes turn these fields into ROS 2 parameters with
descriptors and ranges (``node_base.PerceptionNode.declare_config``); the offline tools turn them
into command-line options and read the same ``config/*.yaml`` files; so there is one list of
constants, one set of defaults, and one validation.
"""
from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence, TypeVar

import yaml

T = TypeVar("T")


class ConfigError(ValueError):
    """A configuration value outside its declared range or choices, or a broken cross-field rule.

    ``fields`` names the fields the error is about (one for a range, two for ``min_size <= max_size``),
    so that a node can refuse exactly those values and keep the rest of a parameter file.
    """

    def __init__(self, message: str, fields: Sequence[str] = ()):
        super().__init__(message)
        self.fields = tuple(fields)


@dataclass(frozen=True)
class ParamSpec:
    """What a configuration field promises: description, range or choices."""

    description: str
    low: float | None = None
    high: float | None = None
    choices: tuple | None = None
    read_only: bool = False

    def check(self, name: str, value: Any) -> None:
        """Raise ConfigError with a reason when ``value`` breaks the spec."""
        if self.choices is not None and value not in self.choices:
            raise ConfigError(f"{name}={value!r} is not one of {list(self.choices)}", (name,))
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            if value != value:  # NaN
                raise ConfigError(f"{name} is NaN", (name,))
            if isinstance(value, float) and math.isinf(value) and self.low is None and self.high is None:
                raise ConfigError(f"{name}={value} is not finite", (name,))
            if self.low is not None and value < self.low:
                raise ConfigError(f"{name}={value} is below its minimum {self.low}", (name,))
            if self.high is not None and value > self.high:
                raise ConfigError(f"{name}={value} is above its maximum {self.high}", (name,))


def param(default: Any, description: str, *, low: float | None = None, high: float | None = None,
          choices: Sequence | None = None, read_only: bool = False) -> Any:
    """A dataclass field carrying a ParamSpec (use for every tunable constant of a core)."""
    spec = ParamSpec(description, low, high, tuple(choices) if choices is not None else None, read_only)
    if isinstance(default, (list, dict)):
        return field(default_factory=lambda: type(default)(default), metadata={"spec": spec})
    return field(default=default, metadata={"spec": spec})


def spec_of(f: dataclasses.Field) -> ParamSpec:
    return f.metadata.get("spec") or ParamSpec(description=f.name)


def _kind(default: Any) -> str:
    if isinstance(default, bool):
        return "a boolean"
    if isinstance(default, int):
        return "an integer"
    if isinstance(default, float):
        return "a number"
    if isinstance(default, str):
        return "a string"
    if isinstance(default, (list, tuple)):
        return "a list of numbers"
    return type(default).__name__


def check_field(f: dataclasses.Field, value: Any, default: Any) -> None:
    """One field's rules: the default's type (an int is fine for a float), finite numbers (lists
    too), then the spec's range or choices. Raises ConfigError naming the field."""
    name = f.name
    ok = True
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, int):
        ok = isinstance(value, numbers.Integral) and not isinstance(value, bool)
    elif isinstance(default, float):
        ok = isinstance(value, numbers.Real) and not isinstance(value, bool)
    elif isinstance(default, str):
        ok = isinstance(value, str)
    elif isinstance(default, (list, tuple)):
        items = value.tolist() if hasattr(value, "tolist") else value
        ok = isinstance(items, (list, tuple)) and all(
            isinstance(v, numbers.Real) and not isinstance(v, bool) for v in items)
        if ok and not all(math.isfinite(v) for v in items):
            raise ConfigError(f"{name}={list(items)} has a value that is not a finite number", (name,))
    if not ok:
        raise ConfigError(f"{name}={value!r} must be {_kind(default)}", (name,))
    spec_of(f).check(name, value)


def validate(config: Any) -> Any:
    """Check every field of a config dataclass against its type and spec, then the config's own
    cross-field rules (its ``validate()`` method, if any); return it unchanged.

    This is the one validation every configuration goes through: node start-up
    (``node_base.PerceptionNode.declare_config``), ``ros2 param set`` and the offline tools.
    """
    defaults = type(config)()
    for f in dataclasses.fields(config):
        check_field(f, getattr(config, f.name), getattr(defaults, f.name))
    post = getattr(config, "validate", None)
    if callable(post):
        post()
    return config


def from_mapping(cls: type[T], values: Mapping[str, Any], *, strict: bool = True) -> T:
    """Build a config dataclass from a mapping, coercing ints to floats where the default is float.

    Unknown keys raise ConfigError when ``strict``; every value is validated against its spec.
    """
    names = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(values) - set(names))
    if unknown and strict:
        raise ConfigError(f"unknown {cls.__name__} parameter(s): {', '.join(unknown)}", unknown)
    kwargs = {}
    defaults = cls()
    for name, value in values.items():
        if name not in names:
            continue
        default = getattr(defaults, name)
        if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if isinstance(default, tuple) and isinstance(value, list):
            value = tuple(value)
        kwargs[name] = value
    return validate(cls(**kwargs))


def load_yaml_parameters(path: str | Path, node_name: str | None = None) -> dict[str, Any]:
    """Read a ROS 2 parameter file (``node: {ros__parameters: {...}}``) into a flat dict.

    With ``node_name``, merges every section that applies to that node, as rcl does: ``/**``, then
    ``/**/node_name``, then ``node_name`` or ``/some/namespace/node_name`` (later ones win).
    Without, takes the first section.
    """
    try:
        data = yaml.safe_load(Path(path).read_text()) or {}
    except OSError as exc:
        raise ConfigError(f"cannot read parameter file {path}: {exc.strerror or exc}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path} is not valid YAML: {str(exc).splitlines()[0] if str(exc) else exc}") from None
    if not isinstance(data, dict) or not all(isinstance(v, dict) or v is None for v in data.values()):
        raise ConfigError(f"{path}: not a ROS 2 parameter file (node: {{ros__parameters: {{...}}}})")
    sections = {str(k).lstrip("/"): (v or {}) for k, v in data.items()}
    if node_name is None:
        chosen = [next(iter(sections.values()), {})]
    else:
        def rank(key: str) -> int | None:
            if key == "**":
                return 0
            if key == f"**/{node_name}":
                return 1
            if key == node_name or key.endswith(f"/{node_name}"):
                return 2
            return None
        matching = sorted((rank(k), k) for k in sections if rank(k) is not None)
        chosen = [sections[k] for _, k in matching]
    params: dict[str, Any] = {}
    for section in chosen:
        tree = section.get("ros__parameters", {}) or {}
        if not isinstance(tree, Mapping):
            raise ConfigError(f"{path}: ros__parameters must be a mapping of names to values")
        params.update(_flatten(tree))
    return params


def tool_parameters(path: str | Path | None, default_file: str, node_name: str) -> dict[str, Any]:
    """An offline tool's parameters: ``path`` if given (it must exist: a mistyped ``--params-file``
    is an error, not silently the defaults), else the package's ``config/<default_file>`` if present."""
    if path is not None and str(path):
        if not Path(path).is_file():
            raise ConfigError(f"parameter file {path} not found")
        return load_yaml_parameters(path, node_name)
    default = package_config_dir() / default_file
    return load_yaml_parameters(default, node_name) if default.is_file() else {}


def _flatten(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(_flatten(value, name + "."))
        else:
            out[name] = value
    return out


def package_config_dir() -> Path:
    """The installed ``share/aircraft_docking_tracker/config`` folder, else the source tree's."""
    try:
        from ament_index_python.packages import get_package_share_directory  # noqa: PLC0415

        candidate = Path(get_package_share_directory("aircraft_docking_tracker")) / "config"
        if candidate.is_dir():
            return candidate
    except Exception:  # ament index absent (plain pip install) or package not registered
        pass
    return Path(__file__).resolve().parent.parent / "config"


TRUE_WORDS, FALSE_WORDS = ("1", "true", "yes", "on"), ("0", "false", "no", "off")


def parse_bool(text: str) -> bool:
    """A boolean option's value: 1 / true / yes / on or 0 / false / no / off (any case); anything else is a
    ValueError (argparse reports it as an invalid value)."""
    word = text.strip().lower()
    if word not in TRUE_WORDS + FALSE_WORDS:
        raise ValueError(f"{text!r} is not a boolean ({'/'.join(TRUE_WORDS)} or {'/'.join(FALSE_WORDS)})")
    return word in TRUE_WORDS


def add_config_arguments(parser, cls: type, prefix: str = "") -> None:
    """Add one ``--name`` option per config field to an argparse parser (offline tools)."""
    for f in dataclasses.fields(cls):
        spec = spec_of(f)
        default = getattr(cls(), f.name)
        opt = "--" + (prefix + f.name).replace("_", "-")
        description = spec.description.replace("%", "%%")  # argparse formats help with %
        kind = type(default)
        if isinstance(default, bool):
            parser.add_argument(opt, type=parse_bool, default=None,
                                metavar="BOOL", help=f"{description} (default {default})")
        elif kind in (int, float, str):
            parser.add_argument(opt, type=kind, default=None, choices=spec.choices,
                                help=f"{description} (default {default})")


def config_from_arguments(cls: type[T], args, prefix: str = "", base: Mapping[str, Any] | None = None) -> T:
    """Build a config from a YAML-derived mapping ``base`` overridden by parsed ``--name`` options."""
    values = dict(base or {})
    for f in dataclasses.fields(cls):
        value = getattr(args, (prefix + f.name), None)
        if value is not None:
            values[f.name] = value
    return from_mapping(cls, values, strict=False)
