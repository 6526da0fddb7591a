"""`dcslam reproduce`: a registered experiment end to end in one command (options: dcslam.stages.reproduce)."""
from __future__ import annotations

import time

import typer

from dcslam.cli.app import app, summary
from dcslam.cli.options import stage_command
from dcslam.stages import reproduce
from dcslam.stages.reproduce_plan import stage_configs_toml

HELP = ("Run the thesis's experiment end to end — synth (or a KITTI root), prepare-kitti, train the four recipes, "
        "predict, filter, slam, score — and print Table 5.2 (or 5.1; or, with --table beams, the beams experiment: "
        "every input at 64/32/16/8 LiDAR beams). Stages whose outputs are up to date (same configuration, same "
        "dcslam) are skipped.")


def _log(line: str) -> None:
    typer.echo(line, err=True)


def run(ws, config: reproduce.ReproduceConfig):
    if config.calibrate:  # the unit costs measured here first, so that the plan below is estimated with them
        from dcslam.stages.experiments import experiment
        from dcslam.stages.reproduce_plan import camera_profile
        from dcslam.stages.reproduce_probe import calibrate

        profile = experiment("5.2").profile(config.profile)
        calibrate(ws, camera_profile(profile, config.camera), log=_log)
    if config.dry_run:  # the plan and its cost on stdout, nothing run or written
        from dcslam.stages.reproduce_cost import plan_text

        typer.echo(plan_text(ws, config))
        return None
    start = time.perf_counter()
    markdown = reproduce.run(ws, config, log=_log)
    return markdown, time.perf_counter() - start


#: The columns of the experiment's table printed at the end, by header, most wanted first: as many as the terminal
#: holds are shown, in the table's order (the Markdown file holds every column). Table 5.1's, Table 5.2's and the
#: beams table's headline figures.
COMPACT_HEADERS = ("recipe", "run", "method", "beams", "input", "localisation accuracy", "localisation", "vs sparse",
                   "failed", "ATE RMSE (m)", "MAE (mm)", "chamfer (m²)", "MSE (m²)", "best epoch", "drives")
#: Characters a printed column takes beyond its cells: a space of padding on each side and a separator.
GAP = 3


def read_markdown_table(path):
    """The first table of a Markdown file written by :meth:`dcslam.report.tables.Table.to_markdown` →
    (title, headers, rows of cells)."""
    title, headers, rows = "", [], []
    for line in path.read_text().splitlines():
        if line.startswith("### ") and not headers:
            title = line[4:]
        elif line.startswith("|"):
            cells = [c.strip() for c in line.strip().strip("|").split(" | ")]
            if not headers:
                headers = cells
            elif set(cells) != {"---"}:
                rows.append(cells)
        elif headers:
            break
    return title, headers, rows


def compact_columns(headers: list[str], rows: list[list[str]], width: int) -> list[int]:
    """The indices of the columns to print within ``width`` characters: those of :data:`COMPACT_HEADERS` (a table
    with none of them: all its columns), most wanted first while they fit (a column as wide as its widest cell or
    its header's longest word), in table order."""
    def need(i: int) -> int:
        return max([len(r[i]) for r in rows if i < len(r)] + [len(w) for w in headers[i].split()]) + GAP

    wanted = [headers.index(h) for h in COMPACT_HEADERS if h in headers] or list(range(len(headers)))
    chosen, used = [], 0
    for i in wanted:
        if used + need(i) <= width:
            chosen.append(i)
            used += need(i)
    return sorted(chosen)


def print_compact(path) -> int:
    """The headline columns of the table in the Markdown file ``path`` on stdout, within the terminal's width (at
    most :data:`dcslam.cli.score.WIDTH`), cells unwrapped -> the number of columns left out."""
    import shutil

    from rich import box
    from rich.console import Console
    from rich.table import Table as RichTable

    from dcslam.cli.score import WIDTH

    width = min(WIDTH, shutil.get_terminal_size().columns)
    title, headers, rows = read_markdown_table(path)
    shown = compact_columns(headers, rows, width - 1) or list(range(len(headers)))
    table = RichTable(title=title, box=box.SIMPLE_HEAD, pad_edge=False, padding=(0, 1))
    for i in shown:
        table.add_column(headers[i], width=max([len(r[i]) for r in rows if i < len(r)]
                                               + [len(w) for w in headers[i].split()]))
    for row in rows:
        table.add_row(*(row[i] if i < len(row) else "" for i in shown))
    Console(width=width).print(table)
    return len(headers) - len(shown)


def more(left_out: int) -> str:
    return "" if not left_out else f" ({left_out} more column{'s' if left_out > 1 else ''})"


def report(result) -> None:
    if result is None:
        return
    markdown, seconds = result
    left_out = print_compact(markdown)
    summary(f"full table{more(left_out)}: {markdown}")
    ranks = markdown.with_name(f"{markdown.stem}_correlation.md")  # written with the table (Table 5.2, beams)
    if ranks.exists():
        left_out = print_compact(ranks)
        summary(f"rank correlations{more(left_out)}, with their notes: {ranks}")
    _log(f"done in {seconds / 60:.1f} min; tables, CSV and PNGs in {markdown.parent}")


reproduce_command = stage_command(app, "reproduce", reproduce.ReproduceConfig, run, report, help=HELP, force=False,
                                  examples=("dcslam reproduce --profile smoke -w /tmp/check    # a few minutes",
                                            "dcslam reproduce --table beams --jobs 2 --print-config   # its stages, "
                                            "then drop --print-config to run it (make reproduce-beams)",
                                            "dcslam reproduce --profile study --dry-run --calibrate   # what 3 seeds x "
                                            "8 drives will run, its cost measured on this machine"),
                                  describe=stage_configs_toml)
