"""``dcslam filter``: filter a depth layer (any the workspace resolver knows: sparse, dense, sparse@<beams>, exact,
predicted, filtered, a layer folder or file) into ``filtered/<name>/``."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.filters import filter_help, parse_filter
from dcslam.stages.config import option
from dcslam.workspace import Workspace

#: --depth values that name a folder of layers and need --run to say which
LAYER_FOLDERS = ("predicted", "filtered")


@dataclass(frozen=True)
class FilterConfig:
    """Options of ``dcslam filter``."""

    filters: list[str] = option(default_factory=list, flags=("--filter", "-f"), metavar="SPEC", help=filter_help(),
                                validate=parse_filter)
    depth: str = option("predicted", help="Input: any depth layer: sparse, dense, sparse@<beams> (prepare-kitti "
                                          "--beams), exact (the drive files' own depth), predicted or filtered "
                                          "(with --run), predicted/<run>, filtered/<name>, or a layer folder or "
                                          "file path.")
    run: str | None = option(None, help="Run name (or folder of layer files) for --depth predicted or filtered.")
    name: str | None = option(None, help="Output name (default: <input>+<filters>, e.g. mse-dense+range).")
    drive: list[str] = option(default_factory=list, help="Drive name (repeatable); default: the test split.")
    out_dir: Path | None = option(None, flags=("--out",), aliases=("--out-dir",),
                                  help="Output folder (default: <workspace>/filtered/<name>).")

    def __post_init__(self) -> None:
        if not self.filters:
            raise DcslamError("give at least one --filter (or a filters list in the configuration file)")
        self.chain()
        if not self.depth:
            raise DcslamError("--depth is empty; name a depth layer, e.g. sparse, sparse@16 or predicted/<run>")
        if self.depth in LAYER_FOLDERS and not self.run:
            raise DcslamError(f"--depth {self.depth} needs --run NAME (a run or filter name, or a folder of layer "
                              "files)")
        if self.name is not None:
            from dcslam.workspace import plain_name

            plain_name(self.name, "--name")

    def chain(self):
        from dcslam.filters import FilterChain

        return FilterChain(tuple(parse_filter(spec) for spec in self.filters))


@dataclass
class FilterResult:
    source_layer: str
    chain_name: str
    out_dir: Path
    layers: list[Path]


def run(ws: Workspace, config: FilterConfig, *, force: bool = False) -> FilterResult:
    """Filter the input layer of every selected drive; writes ``<out>/<drive>.h5`` and ``<out>/config.json``."""
    from dcslam.filters import filter_drives
    from dcslam.stages.config import to_dict
    from dcslam.io.atomic import write_json_atomic
    from dcslam.workspace import layer_reference, plain_name, resolve_layer, select_drives, stage_config

    chain = config.chain()
    layer = resolve_layer(ws, layer_reference(config.depth, config.run))
    name = plain_name(config.name or f"{layer.name}+{chain.name}", "--name")
    out_dir = config.out_dir or ws.filtered / name
    drives = select_drives(ws, config.drive)
    jobs = [(ws.drives / f"{d}.h5", layer.source(d), out_dir / f"{d}.h5") for d in drives]
    settings = {"name": name, "source_layer": layer.name, "depth": config.depth, "drives": drives,
                "filters": chain.describe(), "options": to_dict(config)}
    from dcslam.io.lineage import MADE_FROM, check_layer_folder, made_from
    from dcslam.locks import output_lock

    check_layer_folder(layer.folder)  # a source layer made from an input that changed since is refused
    config_path = out_dir / "config.json"
    with output_lock(out_dir, "layer"):  # before anything is checked, removed or written: one writer at a time
        if config_path.exists() and not force:
            raise DcslamError(f"{config_path} exists; pass --force to overwrite it")
        written = filter_drives(jobs, chain, made_by=name, settings={"source_layer": layer.name}, force=force)
        record = stage_config("filter", settings)
        record[MADE_FROM] = made_from({drive: source if isinstance(source, Path) else None
                                       for drive, (_, source, _) in zip(drives, jobs)}, out_dir)
        write_json_atomic(config_path, record, force=True)
    return FilterResult(layer.name, chain.name, out_dir, written)
