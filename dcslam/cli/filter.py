"""`dcslam filter`: filter a depth layer (sparse, dense, predicted or filtered) into a new layer
(options: dcslam.stages.filter; filters: dcslam.filters)."""
from __future__ import annotations

from dcslam.cli.app import app, summary
from dcslam.cli.options import stage_command
from dcslam.stages import filter as filter_stage

HELP = ("Filter a depth layer into a new layer filtered/<name>/<drive>.h5 (over the test drives by default); the "
        "chain is recorded in each layer file.")


def report(result: filter_stage.FilterResult) -> None:
    summary(f"filtered {result.source_layer} with {result.chain_name}: {len(result.layers)} layer(s) in "
            f"{result.out_dir}")


filter_command = stage_command(app, "filter", filter_stage.FilterConfig, filter_stage.run, report, help=HELP,
                               examples=("dcslam filter --run mse-dense --filter thesis-range --filter edges",
                                         "dcslam filter --depth sparse --filter outlier --name sparse-clean"))
