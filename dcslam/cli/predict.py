"""`dcslam predict`."""
from dcslam.cli.app import app, not_yet_built


@app.command("predict", help="Not yet built (the depth-completion issue).")
def predict_command() -> None:
    not_yet_built("predict", "the depth-completion issue")
