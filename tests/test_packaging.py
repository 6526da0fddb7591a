"""The package's metadata: torch is a floor, never a pin (installing dcslam keeps a lab's own CUDA build of torch);
the exact version is `make setup`'s."""
import re
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).parents[1]

METADATA = """
import sys
from importlib.metadata import PathDistribution
from pathlib import Path

from setuptools import build_meta

out = sys.argv[1]  # the hook rewrites sys.argv
name = build_meta.prepare_metadata_for_build_wheel(out)
print("\\n".join(PathDistribution(Path(out) / name).requires))
"""


def _torch(requirements: list[str]) -> str:
    found = [r for r in requirements if re.match(r"torch(?![-_\w])", r.strip())]
    assert len(found) == 1, requirements
    return found[0]


def test_torch_is_not_pinned_in_the_package_metadata(tmp_path):
    """The metadata pip would install, built from this checkout by setuptools' own hook (into tmp_path), read with
    importlib.metadata: the installed copy of the environment may be an older checkout's until `make setup`."""
    built = subprocess.run([sys.executable, "-c", METADATA, str(tmp_path)], cwd=ROOT, capture_output=True, text=True,
                           timeout=300)
    assert built.returncode == 0, built.stderr
    requirement = _torch([r for r in built.stdout.splitlines() if r and "extra ==" not in r])
    assert "==" not in requirement and "~=" not in requirement and ">=" in requirement, requirement


def test_torch_is_a_floor_in_pyproject_and_make_setup_pins_it():
    requirement = _torch(tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"])
    assert re.fullmatch(r"torch>=2\.\d+", requirement), requirement
    recipe = (ROOT / "Makefile").read_text().replace("\\\n", " ")  # continued lines joined
    assert re.search(r"uv pip install -q .*[ \t]torch==\d+\.\d+\.\d+[ \n]", recipe)
