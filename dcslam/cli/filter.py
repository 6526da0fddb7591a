"""`dcslam filter`: filter a depth layer (sparse, dense, predicted or filtered) into a new layer."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from dcslam.cli.app import ForceOption, WorkspaceOption, app, known_errors, summary

FILTER_HELP = (
    "A filter, repeatable and applied in order: NAME or NAME:key=value,... with NAME one of "
    "range (min, max in m), bilateral (d, sigma_color, sigma_space, ignore_holes), "
    "outlier (nb_neighbors, std_ratio), hidden (radius_factor), edges (max_jump_m, max_relative_jump), "
    "or a preset: thesis-range (5-15 m), thesis-bilateral (d=5, 80, 80). "
    "Example: --filter range:min=1,max=60 --filter bilateral:d=5,sigma_color=2")
ALIASES = {"min": "min_m", "max": "max_m"}


def filter_classes() -> dict:
    """Filter names of the command line → filter classes (the one place strings become objects)."""
    from dcslam.filters import (BilateralFilter, DiscontinuityFilter, HiddenPointFilter, RangeFilter,
                                StatisticalOutlierFilter)

    return {"range": RangeFilter, "bilateral": BilateralFilter, "outlier": StatisticalOutlierFilter,
            "hidden": HiddenPointFilter, "edges": DiscontinuityFilter}


def _convert(text: str, default):
    if isinstance(default, bool):
        if text.lower() in ("1", "true", "yes", "on"):
            return True
        if text.lower() in ("0", "false", "no", "off"):
            return False
        raise ValueError(f"expected true or false, got {text!r}")
    if text.lower() in ("none", "off") and not isinstance(default, int):
        return None
    return int(text) if isinstance(default, int) else float(text)


def parse_filter(spec: str):
    """``NAME`` or ``NAME:key=value,...`` (or a preset name) → a filter object. Raises typer.BadParameter."""
    import dataclasses

    from dcslam.errors import DcslamError
    from dcslam.filters import PRESETS

    if spec in PRESETS:
        return PRESETS[spec]
    name, _, args = spec.partition(":")
    classes = filter_classes()
    if name not in classes:
        raise typer.BadParameter(f"unknown filter {name!r}; expected one of {', '.join([*classes, *PRESETS])}",
                                 param_hint="--filter")
    fields = {f.name: f.default for f in dataclasses.fields(classes[name])}
    kwargs = {}
    for item in filter(None, args.split(",")):
        key, eq, value = item.partition("=")
        key = ALIASES.get(key.strip(), key.strip())
        if not eq or key not in fields:
            raise typer.BadParameter(f"{spec!r}: expected key=value with key one of {', '.join(fields)}",
                                     param_hint="--filter")
        try:
            kwargs[key] = _convert(value.strip(), fields[key])
        except ValueError as exc:
            raise typer.BadParameter(f"{spec!r}: {key}: {exc}", param_hint="--filter") from None
    try:
        return classes[name](**kwargs)
    except DcslamError as exc:
        raise typer.BadParameter(f"{spec!r}: {exc}", param_hint="--filter") from None


@app.command("filter", help="Filter a depth layer into a new layer filtered/<name>/<drive>.h5 (over the test "
                            "drives by default); the chain is recorded in each layer file.")
@known_errors
def filter_command(
    filters: Annotated[list[str], typer.Option("--filter", "-f", help=FILTER_HELP)],
    depth: Annotated[str, typer.Option(help="Input: sparse, dense (from the drive files), predicted "
                                            "(predictions/<run>/) or filtered (filtered/<run>/).")] = "predicted",
    run: Annotated[Optional[str], typer.Option(help="Run name (or folder of layer files) for --depth predicted "
                                                    "or filtered.")] = None,
    name: Annotated[Optional[str], typer.Option(help="Output name (default: <input>+<filters>, "
                                                     "e.g. mse-dense+range).")] = None,
    drive: Annotated[Optional[list[str]], typer.Option(help="Drive name (repeatable); default: the test "
                                                            "split.")] = None,
    out_dir: Annotated[Optional[Path], typer.Option(help="Output folder (default: <workspace>/filtered/<name>).")] = None,
    workspace: WorkspaceOption = None,
    force: ForceOption = False,
) -> None:
    from dcslam.errors import DcslamError
    from dcslam.eval.layers import select_drives
    from dcslam.filters import FilterChain, filter_drives
    from dcslam.workspace import Workspace, stage_config, write_json_atomic

    chain = FilterChain(tuple(parse_filter(spec) for spec in filters))
    ws = Workspace.resolve(workspace)
    if depth in ("sparse", "dense"):
        source_name, folder = depth, None
    elif depth in ("predicted", "filtered"):
        if not run:
            raise DcslamError(f"--depth {depth} needs --run NAME (a run or filter name, or a folder of layer files)")
        base = ws.predictions if depth == "predicted" else ws.filtered
        folder = Path(run) if Path(run).is_dir() else base / run
        if not folder.is_dir():
            made_by = "dcslam predict" if depth == "predicted" else "dcslam filter"
            raise DcslamError(f"{folder} not found; run `{made_by}` first")
        source_name = folder.name
    else:
        raise typer.BadParameter(f"{depth!r} is not one of sparse, dense, predicted, filtered", param_hint="--depth")
    name = name or f"{source_name}+{chain.name}"
    out_dir = out_dir or ws.filtered / name
    drives = select_drives(ws, drive)
    jobs = [(ws.drives / f"{d}.h5", depth if folder is None else folder / f"{d}.h5", out_dir / f"{d}.h5")
            for d in drives]
    settings = {"name": name, "source_layer": source_name, "depth": depth, "drives": drives,
                "filters": chain.describe()}
    config_path = out_dir / "config.json"
    if config_path.exists() and not force:
        raise DcslamError(f"{config_path} exists; pass --force to overwrite it")
    written = filter_drives(jobs, chain, made_by=name, settings={"source_layer": source_name}, force=force)
    write_json_atomic(config_path, stage_config("filter", settings), force=True)
    summary(f"filtered {source_name} with {chain.name}: {len(written)} layer(s) in {out_dir}")
