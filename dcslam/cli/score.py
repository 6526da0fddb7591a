"""`dcslam score`."""
from dcslam.cli.app import app, not_yet_built


@app.command("score", help="Not yet built (the filters-and-scores issue).")
def score_command() -> None:
    not_yet_built("score", "the filters-and-scores issue")
