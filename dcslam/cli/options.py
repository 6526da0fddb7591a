"""Command-line options generated from a stage's configuration dataclass, so that each option is declared once.

:func:`stage_command` registers a Typer command whose options are the configuration's fields (name, type, default,
help, choices, bounds from the field's ``metadata``) plus what every command shares: ``--workspace``, ``--config
FILE`` (TOML, or YAML with PyYAML; options given on the command line override it), ``--print-config`` (print the
configuration the command would run, as TOML, and exit 0) and, where the stage writes files, ``--force``.
"""
from __future__ import annotations

import dataclasses
import enum
import inspect
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Optional

import typer

from dcslam.cli.app import ForceOption, WorkspaceOption, known_errors, summary

ConfigOption = Annotated[Optional[Path], typer.Option(
    "--config", metavar="PATH", help="Read the options from this TOML (or YAML) file; options given here override it.")]
PrintConfigOption = Annotated[bool, typer.Option(
    "--print-config", help="Print the configuration this command would run, as TOML, and exit.")]


def _choice_enum(name: str, choices) -> type[enum.Enum]:
    return enum.Enum(name, [(c, c) for c in choices], type=str)


def _parameter(cls, field) -> inspect.Parameter:
    from dcslam.stages.config import field_type, split_type

    meta = field.metadata
    base, optional, is_list = split_type(field_type(cls, field.name))
    if "choices" in meta:
        base = _choice_enum(f"{cls.__name__}_{field.name}", meta["choices"])
    annotation = list[base] if is_list else base
    if optional or is_list:
        annotation = Optional[annotation]
    flags = meta.get("flags", (f"--{field.name.replace('_', '-')}",))
    if base is bool and field.default is True and "flags" not in meta:   # on by default: it needs an off switch
        flags = (f"{flags[0]}/--no-{flags[0][2:]}",)
    extra = {k: meta[k] for k in ("min", "max", "show_default", "metavar") if k in meta}
    if "choices" not in meta and "metavar" not in meta and base is not bool:  # FLOAT, not Typer's <float range>
        extra["metavar"] = "PATH" if base is Path else base.__name__.upper()
    if "validate" in meta:
        extra["callback"] = _usage_check(meta["validate"], flags[0])
    default = None if field.default is dataclasses.MISSING else field.default
    if "choices" in meta and default is not None:
        default = base(default)
    if meta.get("argument"):  # a positional argument (``dcslam score page PAGE``)
        return inspect.Parameter(field.name, inspect.Parameter.KEYWORD_ONLY, default=default,
                                 annotation=Annotated[annotation, typer.Argument(help=meta.get("help"), **extra)])
    return inspect.Parameter(field.name, inspect.Parameter.KEYWORD_ONLY, default=default,
                             annotation=Annotated[annotation, typer.Option(*flags, help=meta.get("help"), **extra)])


ALIAS_SUFFIX = "__alias"


def _alias_parameter(cls, field) -> inspect.Parameter:
    """A hidden option under a field's other spellings (``metadata["aliases"]``, e.g. ``--output`` for ``--out``):
    they still work, and ``--help`` shows the one name."""
    from dcslam.stages.config import field_type, split_type

    base, _, _ = split_type(field_type(cls, field.name))
    return inspect.Parameter(field.name + ALIAS_SUFFIX, inspect.Parameter.KEYWORD_ONLY, default=None,
                             annotation=Annotated[Optional[base], typer.Option(*field.metadata["aliases"],
                                                                                hidden=True)])


def _usage_check(validate: Callable, hint: str) -> Callable:
    """A Typer callback that runs ``validate`` on each value and turns its DcslamError into a usage error (exit 2)."""
    def callback(value):
        from dcslam.errors import DcslamError

        for item in (value if isinstance(value, list) else [value]) if value is not None else []:
            try:
                validate(item)
            except DcslamError as exc:
                raise typer.BadParameter(str(exc), param_hint=hint) from None
        return value

    return callback


def examples_help(examples: tuple[str, ...]) -> str:
    """The examples block of a command's help: one unwrapped paragraph (click's ``\\b``) of command lines."""
    if not examples:
        return ""
    return "\n\nExamples:\n\n\b\n" + "\n".join(f"  {line}" for line in examples)


def _plain(value):
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, list):
        return [_plain(v) for v in value]
    return value


def _given_values(ctx: typer.Context, fields: list, kwargs: dict) -> tuple[dict, str]:
    """(the configuration's values, where they come from): the ``--config`` file's, overridden by the options given
    on the command line (under their own flag or an alias, not both)."""
    from dcslam.stages.config import config_key, read_config_file

    values = {}
    source = "the command line"
    if kwargs.get("config_file") is not None:
        source = str(kwargs["config_file"])
        values.update(read_config_file(kwargs["config_file"]))
    for field in fields:
        given = ctx.get_parameter_source(field.name)
        if given is not None and given.name != "DEFAULT":
            values[config_key(field)] = _plain(kwargs[field.name])
        if kwargs.get(field.name + ALIAS_SUFFIX) is not None:
            flag = field.metadata.get("flags", (f"--{field.name.replace('_', '-')}",))[0]
            if given is not None and given.name != "DEFAULT":
                raise typer.BadParameter(f"give {flag} once (also spelt {', '.join(field.metadata['aliases'])})",
                                         param_hint=flag)
            values[config_key(field)] = _plain(kwargs[field.name + ALIAS_SUFFIX])
    return values, source


def _command_parameters(config_cls, fields: list, force: bool) -> list[inspect.Parameter]:
    """The command's signature: the context, one option per field (and per alias), then ``--workspace``,
    ``--config``, ``--print-config`` and, with ``force``, ``--force``."""
    parameters = [inspect.Parameter("ctx", inspect.Parameter.POSITIONAL_OR_KEYWORD, annotation=typer.Context)]
    parameters += [_parameter(config_cls, f) for f in fields]
    parameters += [_alias_parameter(config_cls, f) for f in fields if f.metadata.get("aliases")]
    parameters += [inspect.Parameter("workspace", inspect.Parameter.KEYWORD_ONLY, default=None,
                                     annotation=WorkspaceOption),
                   inspect.Parameter("config_file", inspect.Parameter.KEYWORD_ONLY, default=None,
                                     annotation=ConfigOption),
                   inspect.Parameter("print_config", inspect.Parameter.KEYWORD_ONLY, default=False,
                                     annotation=PrintConfigOption)]
    if force:
        parameters.append(inspect.Parameter("force", inspect.Parameter.KEYWORD_ONLY, default=False,
                                            annotation=ForceOption))
    return parameters


# one line per command for the command lists of `dcslam --help` and `dcslam score --help`, short enough that an
# 80-column terminal shows it whole (click would cut the first sentence of the help mid-phrase)
SUMMARIES = {
    "synth": "Generate KITTI-format drives (or ICL-NUIM rooms)",
    "prepare-kitti": "KITTI raw + depth folders -> drive files",
    "prepare-tum": "TUM RGB-D / ICL-NUIM sequences -> drive files",
    "train": "Train a completer (MSE, chamfer or pose loss)",
    "predict": "Complete drives with a run or a classical completer",
    "filter": "Filter a depth layer into a new layer",
    "slam": "Dense SLAM over drives; trajectories, maps, verdicts",
    "reproduce": "Run an experiment end to end (Tables 5.1/5.2, beams)",
    "demo-icl": "Appendix C.2: a DnCNN learns to denoise from maps",
    "import": "KITTI devkit PNGs (another method's) -> a layer",
    "export": "A depth layer -> KITTI devkit PNGs",
    "view": "Open a SLAM recording in the Rerun viewer",
    "depth": "Depth errors of layers (devkit and surface)",
    "trajectory": "Trajectory scores of SLAM runs",
    "map": "Chamfer distance of SLAM maps to the exact map",
    "tables": "An experiment's tables from the workspace",
    "page": "Refresh a page's result tables from results/",
    "collect": "Copy a workspace's results into results/NAME/",
}


def stage_command(parent: typer.Typer, name: str, config_cls, run: Callable, report: Callable[[object], None],
                  *, help: str, force: bool = True, prepare: Callable | None = None,
                  examples: tuple[str, ...] = (), describe: Callable | None = None) -> Callable:
    """Register ``name`` on ``parent``: options → ``config_cls`` → ``run(workspace, config, force=)`` → ``report``.

    ``prepare(config, workspace)`` (optional) may return a changed configuration before it is printed or run.
    ``examples``: command lines shown at the end of ``--help``. ``describe(workspace, config)`` (optional): more
    TOML that ``--print-config`` prints after the configuration (e.g. the configurations of the stages it runs).
    """
    from dcslam.stages.config import options_of

    fields = [f for f in options_of(config_cls) if not f.metadata.get("file_only")]  # the command's options

    def command(ctx: typer.Context, **kwargs):
        from dcslam.stages.config import from_mapping, to_toml
        from dcslam.workspace import Workspace

        values, source = _given_values(ctx, fields, kwargs)
        config = from_mapping(config_cls, values, source)
        ws = Workspace.resolve(kwargs.get("workspace"))
        if prepare is not None:
            config = prepare(config, ws)
        if kwargs.get("print_config"):
            text = to_toml(config, f"dcslam {name} configuration")
            summary(text if describe is None else text + "\n" + describe(ws, config))
            return None
        result = run(ws, config, force=kwargs.get("force", False)) if force else run(ws, config)
        report(result)
        return result

    parameters = _command_parameters(config_cls, fields, force)
    wrapped = known_errors(command)
    wrapped.__signature__ = inspect.Signature(parameters)
    wrapped.__annotations__ = {p.name: p.annotation for p in parameters}
    del wrapped.__wrapped__
    wrapped.__name__ = f"{name.replace('-', '_')}_command"
    parent.command(name, help=help + examples_help(examples), short_help=SUMMARIES.get(name))(wrapped)
    return wrapped
