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
        from dcslam.stages.reproduce_probe import calibrate

        calibrate(ws, experiment("5.2").profile(config.profile), log=_log)
    if config.dry_run:  # the plan and its cost on stdout, nothing run or written
        from dcslam.stages.reproduce_cost import plan_text

        typer.echo(plan_text(ws, config))
        return None
    start = time.perf_counter()
    markdown = reproduce.run(ws, config, log=_log)
    return markdown, time.perf_counter() - start


def report(result) -> None:
    if result is None:
        return
    markdown, seconds = result
    summary(markdown.read_text())
    ranks = markdown.with_name(f"{markdown.stem}_correlation.md")  # written with the table (Table 5.2, beams)
    if ranks.exists():
        summary(ranks.read_text())
    _log(f"done in {seconds / 60:.1f} min; tables, CSV and PNGs in {markdown.parent}")


reproduce_command = stage_command(app, "reproduce", reproduce.ReproduceConfig, run, report, help=HELP, force=False,
                                  examples=("dcslam reproduce --profile smoke -w /tmp/check    # a few minutes",
                                            "dcslam reproduce --table beams --jobs 2 --print-config   # its stages, "
                                            "then drop --print-config to run it (make reproduce-beams)",
                                            "dcslam reproduce --profile study --dry-run   # what 3 seeds x 8 drives "
                                            "will run and cost",
                                            "dcslam reproduce --profile study --dry-run --calibrate   # its cost "
                                            "measured on this machine"),
                                  describe=stage_configs_toml)
