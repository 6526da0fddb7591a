"""Completers, filters and datasets from installed packages, found through entry points.

A package registers an extension in its ``pyproject.toml``, one line each, under the group of its registry::

    [project.entry-points."dcslam.completers"]   # → dcslam.depth.models.CLASSICAL: "module:factory"
    nearest-fill = "mypkg.nearest_fill:nearest_fill"
    [project.entry-points."dcslam.filters"]      # → dcslam.filters.FILTERS: "module:FilterClass"
    far = "mypkg.far:FarFilter"
    [project.entry-points."dcslam.datasets"]     # → dcslam.stages.datasets.DATASETS: "module"
    npz = "mypkg.npz_frames"

An entry point's value is the ``"module:attribute"`` string the registries already hold. Only the package metadata
is read when a registry looks up a name (once per process); the plugin's module is imported when it is used, so a
broken plugin fails only the command that uses it, in one line. A name dcslam itself registers is never replaced.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

from dcslam.errors import DcslamError

COMPLETERS = "dcslam.completers"
FILTERS = "dcslam.filters"
DATASETS = "dcslam.datasets"
GROUPS = (COMPLETERS, FILTERS, DATASETS)


@dataclass(frozen=True)
class Plugin:
    """One entry point: its ``name`` in the registry, ``target`` (``"module:attribute"`` or ``"module"``) and the
    distribution (``package``) that declared it."""

    name: str
    target: str
    package: str

    def describe(self) -> str:
        return f"{self.name!r} (package {self.package}, entry point {self.target})"


def plugins(group: str) -> dict[str, Plugin]:
    """The entry points of ``group`` in the installed packages, by name (the first package's when two declare one
    name)."""
    if group not in GROUPS:
        raise DcslamError(f"unknown plugin group {group!r}; expected one of {', '.join(GROUPS)}")
    return _installed()[group]


@functools.lru_cache(maxsize=1)
def _installed() -> dict[str, dict[str, Plugin]]:
    """Every group's entry points, read in one pass over the installed packages (only those whose
    ``entry_points.txt`` mentions dcslam are parsed: the pass costs a fraction of a second, once per process)."""
    from importlib.metadata import distributions

    found: dict[str, dict[str, Plugin]] = {group: {} for group in GROUPS}
    for distribution in distributions():
        try:
            text = distribution.read_text("entry_points.txt")
            if not text or "dcslam." not in text:
                continue
            points, package = distribution.entry_points, distribution.metadata["Name"] or "?"
        except Exception:  # a broken installation's metadata: it declares nothing dcslam can use
            continue
        for point in points:
            if point.group in found and point.name not in found[point.group]:
                found[point.group][point.name] = Plugin(point.name, point.value, package)
    return found


def targets(group: str, builtin) -> dict[str, str]:
    """``{name: target}`` of the plugins of ``group`` whose names ``builtin`` (a registry) does not hold."""
    return {name: plugin.target for name, plugin in plugins(group).items() if name not in builtin}


def find(group: str, name: str) -> Plugin | None:
    """The plugin of ``group`` called ``name``, or None."""
    return plugins(group).get(name)


def load(group: str, name: str, target: str | None = None):
    """The object ``target`` names (``"module:attribute"`` or ``"module"``, default: the plugin's own); an import
    that fails, or an attribute the module lacks, is a :class:`DcslamError` naming the plugin and its package."""
    import importlib

    plugin = find(group, name)
    target = target or (plugin.target if plugin else name)
    module, _, attribute = target.partition(":")
    try:
        loaded = importlib.import_module(module.strip())
        for part in filter(None, attribute.strip().split(".")):
            loaded = getattr(loaded, part)
    except Exception as exc:  # anything a third-party module raises while it is imported
        raise DcslamError(f"{_what(group)} {plugin.describe() if plugin else repr(name)} cannot be loaded "
                          f"({reason(exc)}); fix or uninstall the package") from None
    return loaded


def refuse(group: str, name: str, problem: str) -> DcslamError:
    """The one-line error of a plugin that loaded but is not what its group takes."""
    plugin = find(group, name)
    return DcslamError(f"{_what(group)} {plugin.describe() if plugin else repr(name)} {problem}; fix or uninstall "
                       "the package")


def reason(exc: BaseException) -> str:
    """An exception on one line: its type and the first line of its message."""
    first = (str(exc).strip().splitlines() or [""])[0]
    return f"{type(exc).__name__}: {first}" if first else type(exc).__name__


def _what(group: str) -> str:
    return {COMPLETERS: "completer", FILTERS: "filter", DATASETS: "dataset"}[group]
