"""`dcslam filter`."""
from dcslam.cli.app import app, not_yet_built


@app.command("filter", help="Not yet built (the filters-and-scores issue).")
def filter_command() -> None:
    not_yet_built("filter", "the filters-and-scores issue")
