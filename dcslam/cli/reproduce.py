"""`dcslam reproduce`: the whole experiment in one command (what `make reproduce-table-5-2` runs)."""
from pathlib import Path
from typing import Annotated, Optional

import typer

from dcslam.cli.app import WorkspaceOption, app, known_errors, summary


@app.command("reproduce", help="Run the thesis's experiment end to end — synth (or a KITTI root), prepare-kitti, "
                               "train the four recipes, predict, filter, slam, score — and print Table 5.2 (or 5.1). "
                               "Stages whose outputs are up to date are skipped.")
@known_errors
def reproduce_command(
    table: Annotated[str, typer.Option(help="Table to print: 5.2 or 5.1 (5.1 stops after training).")] = "5.2",
    profile: Annotated[str, typer.Option(help="quick (about 30 min on 2 CPU cores), smoke (a few minutes; checks "
                                              "the stages, its numbers mean nothing) or thesis (15/4/5 drives of 200 "
                                              "frames; for a GPU).")] = "quick",
    kitti: Annotated[Optional[Path], typer.Option(help="Real KITTI root (raw/ and depth_completion/); default: "
                                                       "generate KITTI-format drives with `dcslam synth`.")] = None,
    seed: Annotated[int, typer.Option(help="Seed of the generated drives and of training.")] = 0,
    workspace: WorkspaceOption = None,
) -> None:
    import time

    from dcslam.errors import DcslamError
    from dcslam.reproduce import PROFILES, reproduce
    from dcslam.workspace import Workspace

    if profile not in PROFILES:
        raise DcslamError(f"unknown profile {profile!r}; expected one of {', '.join(PROFILES)}")
    start = time.perf_counter()
    log = lambda line: typer.echo(line, err=True)  # noqa: E731
    markdown = reproduce(Workspace.resolve(workspace), PROFILES[profile], table=table, kitti_root=kitti, seed=seed,
                         log=log)
    summary(markdown.read_text())
    log(f"done in {(time.perf_counter() - start) / 60:.1f} min; tables, CSV and PNGs in {markdown.parent}")
