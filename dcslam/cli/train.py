"""`dcslam train`."""
from dcslam.cli.app import app, not_yet_built


@app.command("train", help="Not yet built (the depth-completion issue).")
def train_command() -> None:
    not_yet_built("train", "the depth-completion issue")
