"""Stage configurations: one dataclass per command, declared once, read from TOML / YAML and written back.

A stage's options are the fields of its configuration dataclass. Each field carries, in ``metadata``, what the
command line needs and nothing else declares again: ``help``, and optionally ``choices`` (an unknown value is a usage
error), ``min`` / ``max``, ``flags`` (option names when they are not ``--field-name``), ``show_default``,
``metavar``, ``validate`` (a function that raises DcslamError on a bad value: a usage error on the command line) and
``internal`` (a field set by code, never an option or a config-file key). :func:`option` builds such a field.

A configuration file holds the same keys as the options (``map_frames``, not ``--map-frames``), in TOML (read with
:mod:`tomllib`) or YAML (read with PyYAML when it is installed). :func:`to_toml` writes the configuration a command
would run, so that it can be edited and given back with ``--config``.
"""
from __future__ import annotations

import dataclasses
import hashlib
import types
import typing
from pathlib import Path

from dcslam.errors import DcslamError

_MISSING = dataclasses.MISSING


def option(default=_MISSING, *, help: str, default_factory=_MISSING, **meta):
    """A configuration field with its help text (and ``choices``, ``min``, ``max``, ``flags``, ``show_default``,
    ``metavar``, ``validate``, ``aliases``: other spellings of the option, accepted but not shown in ``--help``)."""
    metadata = {"help": help, **meta}
    if default_factory is not _MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def options_of(cls) -> list[dataclasses.Field]:
    """The fields of a configuration class that are options (not ``internal``)."""
    return [f for f in dataclasses.fields(cls) if not f.metadata.get("internal")]


def field_type(cls, name: str):
    """The resolved annotation of field ``name`` of ``cls`` (``X | None`` kept as a union)."""
    return typing.get_type_hints(cls)[name]


def split_type(tp) -> tuple[object, bool, bool]:
    """``(base type, optional, is list)`` of an annotation such as ``int``, ``Path | None`` or ``list[str]``."""
    optional = False
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        optional, tp = True, args[0]
        origin = typing.get_origin(tp)
    if origin in (list, tuple):
        return typing.get_args(tp)[0], optional, True
    return tp, optional, False


def _convert(value, base, key: str, source: str):
    """A value from a configuration file as the field's type."""
    if base is Path:
        if not isinstance(value, (str, Path)):
            raise DcslamError(f"{source}: {key} must be a path (a string), got {value!r}")
        return Path(value)
    if base is bool:
        if not isinstance(value, bool):
            raise DcslamError(f"{source}: {key} must be true or false, got {value!r}")
        return value
    if base is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if base in (int, float, str) and not isinstance(value, base) or isinstance(value, bool) and base is not bool:
        raise DcslamError(f"{source}: {key} must be {base.__name__}, got {value!r}")
    return value


def from_mapping(cls, values: dict, source: str = "configuration"):
    """An instance of configuration class ``cls`` from plain values (a config file's table); unknown keys fail."""
    known = {f.name: f for f in options_of(cls)}
    unknown = sorted(set(values) - set(known))
    if unknown:
        raise DcslamError(f"{source}: unknown key {unknown[0]!r}; expected one of {', '.join(known)}")
    kwargs = {}
    for key, value in values.items():
        choices = known[key].metadata.get("choices")
        for item in (value if isinstance(value, list) else [value]) if choices is not None else []:
            if item is not None and item not in choices:
                raise DcslamError(f"{source}: {key} = {item!r} is not one of {', '.join(map(str, choices))}")
        base, optional, is_list = split_type(field_type(cls, key))
        if value is None:
            if not optional:
                raise DcslamError(f"{source}: {key} cannot be empty")
            kwargs[key] = None
        elif is_list:
            if not isinstance(value, list):
                raise DcslamError(f"{source}: {key} must be a list, got {value!r}")
            kwargs[key] = [_convert(v, base, key, source) for v in value]
        else:
            kwargs[key] = _convert(value, base, key, source)
    return cls(**kwargs)


def read_config_file(path: Path | str) -> dict:
    """The table of a ``.toml`` (or, with PyYAML installed, ``.yaml`` / ``.yml``) configuration file."""
    path = Path(path)
    if not path.is_file():
        raise DcslamError(f"configuration file {path} not found")
    if path.suffix in (".yaml", ".yml"):
        try:
            import yaml
        except ImportError:
            raise DcslamError(f"{path}: YAML needs PyYAML (pip install pyyaml); or write the file as TOML") from None
        try:
            values = yaml.safe_load(path.read_text()) or {}
        except yaml.YAMLError as exc:
            raise DcslamError(f"{path}: not valid YAML ({str(exc).splitlines()[0]})") from None
    else:
        import tomllib

        try:
            values = tomllib.loads(path.read_text())
        except tomllib.TOMLDecodeError as exc:
            raise DcslamError(f"{path}: not valid TOML ({exc}); expected key = value lines") from None
    if not isinstance(values, dict):
        raise DcslamError(f"{path}: expected a table of key = value, got {type(values).__name__}")
    return values


def to_dict(config) -> dict:
    """The options of a configuration as plain JSON / TOML values (paths as strings)."""
    return {f.name: to_dict_value(getattr(config, f.name)) for f in options_of(type(config))}


def changed(config) -> dict:
    """The options of a configuration that differ from their defaults (for a one-line description of a run)."""
    values = to_dict(config)
    out = {}
    for f in options_of(type(config)):
        default = f.default_factory() if f.default is _MISSING and f.default_factory is not _MISSING else f.default
        if values[f.name] != to_dict_value(default):
            out[f.name] = values[f.name]
    return out


def to_dict_value(value):
    """One option's value as a plain JSON / TOML value (paths as strings)."""
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, (list, tuple)):
        return [to_dict_value(v) for v in value]
    return value


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise DcslamError(f"cannot write {value!r} as TOML")


def to_toml(config, title: str | None = None) -> str:
    """The configuration as a TOML document (fields left unset are written as comments)."""
    lines = [f"# {title}"] if title else []
    for key, value in to_dict(config).items():
        lines.append(f"# {key} = (unset)" if value is None else f"{key} = {_toml_value(value)}")
    return "\n".join(lines) + "\n"


def code_version() -> str:
    """dcslam's version and a hash of its Python sources: changes when the code that makes outputs changes."""
    from dcslam import __version__

    root = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return f"{__version__}+{digest.hexdigest()[:16]}"
