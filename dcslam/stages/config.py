"""Stage configurations: one dataclass per command, declared once, read from TOML / YAML and written back.

A stage's options are the fields of its configuration dataclass. Each field carries, in ``metadata``, what the
command line needs and nothing else declares again: ``help``, and optionally ``choices`` (an unknown value is a usage
error), ``min`` / ``max``, ``flags`` (option names when they are not ``--field-name``), ``show_default``,
``metavar``, ``validate`` (a function that raises DcslamError on a bad value: a usage error on the command line),
``key`` (the configuration-file key when it is not the field's name), ``internal`` (a field set by code, never an
option or a config-file key) and ``file_only`` (a table of the configuration file, e.g. ``[slurm]``, never a
command-line option). :func:`dcslam.settings.option` builds such a field.

A configuration file holds the same keys as the options (``map_frames``, not ``--map-frames``), in TOML (read with
:mod:`tomllib`) or YAML (read with PyYAML when it is installed). :func:`to_toml` writes the configuration a command
would run, so that it can be edited and given back with ``--config``. :class:`Options` holds some fields of a
configuration (a profile's or a recipe's share of it), checked against the dataclass's fields when made.
"""
from __future__ import annotations

import dataclasses
import functools
import hashlib
import os
import time
import types
import typing
from collections.abc import Mapping
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.settings import option  # noqa: F401  (the stages declare their own options with it)

_MISSING = dataclasses.MISSING


def options_of(cls) -> list[dataclasses.Field]:
    """The fields of a configuration class that are options (not ``internal``)."""
    return [f for f in dataclasses.fields(cls) if not f.metadata.get("internal")]


def config_key(field: dataclasses.Field) -> str:
    """The configuration-file key of an option: its ``key`` metadata, else the field's name."""
    return field.metadata.get("key", field.name)


def field_type(cls, name: str):
    """The resolved annotation of field ``name`` of ``cls`` (``X | None`` kept as a union)."""
    return _type_hints(cls)[name]


@functools.cache
def _type_hints(cls) -> dict:
    """``typing.get_type_hints(cls)``, resolved once per class: every option checked resolved them all again, a third
    of a second of every command's start."""
    return typing.get_type_hints(cls)


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
    known = {config_key(f): f.name for f in options_of(cls)}
    unknown = sorted(set(values) - set(known))
    if unknown:
        raise DcslamError(f"{source}: unknown key {unknown[0]!r}; expected one of {', '.join(known)}")
    kwargs = {}
    for key, value in values.items():
        name = known[key]
        choices = next(f for f in options_of(cls) if f.name == name).metadata.get("choices")
        for item in (value if isinstance(value, list) else [value]) if choices is not None else []:
            if item is not None and item not in choices:
                raise DcslamError(f"{source}: {key} = {item!r} is not one of {', '.join(map(str, choices))}")
        base, optional, is_list = split_type(field_type(cls, name))
        if value is None:
            if not optional:
                raise DcslamError(f"{source}: {key} cannot be empty")
            kwargs[name] = None
        elif is_list:
            if not isinstance(value, list):
                raise DcslamError(f"{source}: {key} must be a list, got {value!r}")
            kwargs[name] = [_convert(v, base, key, source) for v in value]
        else:
            kwargs[name] = _convert(value, base, key, source)
    return cls(**kwargs)


def read_config_file(path: Path | str) -> dict:
    """The table of a ``.toml`` (or, with PyYAML installed, ``.yaml`` / ``.yml``) configuration file."""
    path = Path(path)
    text = _config_text(path)
    if path.suffix in (".yaml", ".yml"):
        try:
            import yaml
        except ImportError:
            raise DcslamError(f"{path}: YAML needs PyYAML (pip install pyyaml); or write the file as TOML") from None
        try:
            values = yaml.safe_load(text) or {}
        except yaml.YAMLError as exc:
            raise DcslamError(f"{path}: not valid YAML ({str(exc).splitlines()[0]})") from None
    else:
        import tomllib

        try:
            values = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise DcslamError(f"{path}: not valid TOML ({exc}); expected key = value lines") from None
    if not isinstance(values, dict):
        raise DcslamError(f"{path}: expected a table of key = value, got {type(values).__name__}")
    return values


def _config_text(path: Path) -> str:
    """The text of a configuration file, or one line naming the file: missing, a directory, unreadable, not UTF-8."""
    if path.is_dir():
        raise DcslamError(f"configuration file {path} is a directory; give a .toml or .yaml file")
    if not path.exists():
        raise DcslamError(f"configuration file {path} not found")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise DcslamError(f"could not read configuration file {path}: {exc.strerror or exc}") from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise DcslamError(f"configuration file {path} is not UTF-8 text (byte {exc.start}: {data[exc.start]:#04x}); "
                          "save it as UTF-8") from None


def to_dict(config) -> dict:
    """The options of a configuration as plain JSON / TOML values (paths as strings), by configuration-file key."""
    return {config_key(f): to_dict_value(getattr(config, f.name)) for f in options_of(type(config))}


def changed(config) -> dict:
    """The options of a configuration that differ from their defaults (for a one-line description of a run)."""
    values = to_dict(config)
    out = {}
    for f in options_of(type(config)):
        default = f.default_factory() if f.default is _MISSING and f.default_factory is not _MISSING else f.default
        if values[config_key(f)] != to_dict_value(default):
            out[config_key(f)] = values[config_key(f)]
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
    if isinstance(value, dict):  # an inline table: {key = value, ...}
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()) + "}"
    raise DcslamError(f"cannot write {value!r} as TOML")


def _toml_key(key: str) -> str:
    bare = key.replace("_", "").replace("-", "").isalnum() and key.isascii()
    return key if bare else _toml_value(str(key))


def to_toml(config, title: str | None = None) -> str:
    """The configuration as a TOML document (fields left unset are written as comments)."""
    lines = [f"# {title}"] if title else []
    for key, value in to_dict(config).items():
        lines.append(f"# {key} = (unset)" if value is None else f"{key} = {_toml_value(value)}")
    return "\n".join(lines) + "\n"


#: The last :func:`code_version`: the sources it hashed (path, size, modification time) and what it gave.
_VERSION: tuple[tuple, str] | None = None
#: Nanoseconds after its last change before a source is taken as settled: a file changed again within its
#: timestamp's granularity (a few ms) keeps its size and time, so a recent one is read every time.
SETTLED_NS = 2_000_000_000


def code_version() -> str:
    """dcslam's version and a hash of its Python and C sources (dcslam.native): changes when the code that makes
    outputs changes. The hash is kept while no source's path, size or time changes (every stage's stamp asks for it:
    reading and hashing the sources each time cost 11 ms a call, hundreds of calls a reproduction)."""
    from dcslam.version import __version__

    global _VERSION
    root = Path(__file__).resolve().parents[1]
    paths = sorted(Path(folder) / name for folder, _, names in os.walk(root) for name in names
                   if name.endswith((".py", ".c")))
    stats = [path.stat() for path in paths]
    sources = tuple((str(path), stat.st_size, stat.st_mtime_ns) for path, stat in zip(paths, stats))
    if _VERSION is not None and _VERSION[0] == sources:
        return _VERSION[1]
    digest = hashlib.sha256()
    for path in paths:
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    version = f"{__version__}+{digest.hexdigest()[:16]}"
    settled = time.time_ns() - SETTLED_NS
    if all(stat.st_mtime_ns < settled for stat in stats):
        _VERSION = (sources, version)
    return version


class Options(Mapping):
    """Some fields of a stage's configuration dataclass ``config`` (a profile's or a recipe's share of a
    ``dcslam train`` / ``dcslam slam`` configuration), checked against the dataclass's fields when made, so that a
    misspelt or mistyped option fails where it is written, not when the stage runs.

    A read-only mapping of field name → value; ``a | b`` is ``a`` with ``b``'s fields set (``b`` checked too);
    :meth:`build` makes the configuration itself (whose own checks then run).
    """

    __slots__ = ("config", "_values")

    def __init__(self, config: type, values: Mapping | None = None, /, **more) -> None:
        if not dataclasses.is_dataclass(config):
            raise DcslamError(f"options of {config!r}: expected a configuration dataclass")
        merged = {**(values or {}), **more}
        fields = {f.name for f in options_of(config)}
        for key, value in merged.items():
            if key not in fields:
                import difflib

                close = difflib.get_close_matches(key, sorted(fields), n=1)
                hint = f"did you mean {close[0]!r}?" if close else f"expected one of {', '.join(sorted(fields))}"
                raise DcslamError(f"{config.__name__} has no option {key!r}; {hint}")
            _check_type(config, key, value)
        object.__setattr__(self, "config", config)
        object.__setattr__(self, "_values", merged)

    def __setattr__(self, name, value):
        raise AttributeError(f"{type(self).__name__} is read-only")

    def __getitem__(self, key: str):
        return self._values[key]

    def __iter__(self):
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def __or__(self, other: Mapping) -> "Options":
        return Options(self.config, {**self._values, **other})

    def __repr__(self) -> str:
        return f"Options({self.config.__name__}, {self._values!r})"

    def build(self, **more):
        """The configuration: these fields, then ``more`` (checked as fields too), the others at their defaults."""
        return self.config(**(self | more))


def _check_type(config: type, key: str, value) -> None:
    """Fail unless ``value`` has the type of field ``key`` of ``config`` (as a configuration file's value would)."""
    base, optional, is_list = split_type(field_type(config, key))
    source = f"{config.__name__} option"
    if value is None:
        if not optional:
            raise DcslamError(f"{source} {key} cannot be None")
    elif is_list:
        if not isinstance(value, (list, tuple)):
            raise DcslamError(f"{source} {key} must be a list, got {value!r}")
        for item in value:
            _convert(item, base, key, source)
    elif base in (int, float, str, bool, Path):
        _convert(value, base, key, source)
