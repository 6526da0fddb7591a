"""Completers, filters and datasets of installed packages (dcslam.plugins): a tiny package, installed by putting its
module and its ``.dist-info`` (METADATA, entry_points.txt) in a folder on the path, as pip would leave them, so the
shared environment is never touched. Its completer shows in ``dcslam predict --help`` and predicts; its filter
filters; its broken entries (an import error, a wrong object) are refused in one line and the other commands work."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

from dcslam.errors import DcslamError
from tests.fixtures import depth as depth_fixtures

ROOT = Path(__file__).parents[1]

MODULE = '''
from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class Constant:
    """Every pixel at the median of the measured ones."""

    def __call__(self, sparse_m):
        measured = sparse_m[sparse_m > 0]
        return np.full(sparse_m.shape, np.median(measured) if measured.size else 0, np.float32)


def constant():
    return Constant()


NOT_A_FACTORY = 3


@dataclass(frozen=True)
class FarFilter:
    max_m: float = 40.0
    name = "far"

    def apply(self, depth_m, K=None):
        return np.where(depth_m <= self.max_m, depth_m, np.float32(0)).astype(np.float32)

    def describe(self):
        return {"filter": self.name, **asdict(self)}


class NotAFilter:
    pass
'''

ENTRY_POINTS = '''[dcslam.completers]
constant-fill = demo_plugin:constant
broken-import = demo_plugin_missing:constant
not-a-factory = demo_plugin:NOT_A_FACTORY
ip-basic-fast = demo_plugin:constant

[dcslam.filters]
far = demo_plugin:FarFilter
not-a-filter = demo_plugin:NotAFilter
'''
BROKEN_DATASET = "[dcslam.datasets]\nbroken-data = demo_plugin_missing\n"


def install(site: Path, entry_points: str, name: str = "demo-plugin") -> Path:
    """The package ``name`` (the module demo_plugin and its dist-info) in the folder ``site``."""
    info = site / f"{name.replace('-', '_')}-0.1.dist-info"
    info.mkdir(parents=True)
    (site / "demo_plugin.py").write_text(MODULE)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(entry_points)
    return site


@pytest.fixture
def site(tmp_path):
    """A folder holding the installed package ``demo-plugin``: completers and filters, some broken."""
    return install(tmp_path / "site", ENTRY_POINTS)


@pytest.fixture
def installed(site, monkeypatch):
    """The package on this process's path, the entry points read again; both undone after the test."""
    from dcslam import plugins

    monkeypatch.syspath_prepend(str(site))
    plugins._installed.cache_clear()
    yield site
    plugins._installed.cache_clear()
    sys.modules.pop("demo_plugin", None)


def dcslam(site, *args, cwd):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(ROOT)]), "DCSLAM_PROGRESS": "0",
           "COLUMNS": "200"}
    return subprocess.run([sys.executable, "-m", "dcslam", *map(str, args)], env=env, cwd=cwd, capture_output=True,
                          text=True, timeout=300)


def test_a_completer_of_an_installed_package_is_a_choice_of_predict_and_predicts(site, tmp_path):
    ws = depth_fixtures.write_workspace(tmp_path / "ws", n=3)
    helped = dcslam(site, "predict", "--help", cwd=tmp_path)
    assert helped.returncode == 0, helped.stderr
    assert "constant-fill" in helped.stdout and helped.stderr == ""  # broken plugins cost nothing until used
    done = dcslam(site, "predict", "-w", ws, "--model", "constant-fill", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    from dcslam.io.drive import read_layer

    layer = read_layer(ws / "predictions" / "constant-fill" / "drive_d.h5")
    assert layer.made_by == "constant-fill" and layer.depth.shape == (3, 32, 64) and (layer.depth > 0).all()
    # the package's "ip-basic-fast" never replaces dcslam's own
    assert dcslam(site, "predict", "-w", ws, "--model", "ip-basic-fast", cwd=tmp_path).returncode == 0
    assert read_layer(ws / "predictions" / "ip-basic-fast" / "drive_d.h5").config["model"] == "ip-basic-fast"
    assert "max_depth" in read_layer(ws / "predictions" / "ip-basic-fast" / "drive_d.h5").config


@pytest.mark.parametrize("name, message", [
    ("broken-import", "cannot be loaded (ModuleNotFoundError: No module named 'demo_plugin_missing')"),
    ("not-a-factory", "is a int, not a factory"),
])
def test_a_broken_completer_is_refused_in_one_line(site, tmp_path, name, message):
    ws = depth_fixtures.write_workspace(tmp_path / "ws", n=2)
    done = dcslam(site, "predict", "-w", ws, "--model", name, cwd=tmp_path)
    assert done.returncode == 1
    assert done.stderr.count("\n") == 1 and message in done.stderr and "demo-plugin" in done.stderr
    assert not (ws / "predictions").exists()


def test_a_broken_dataset_costs_its_own_command_only(tmp_path):
    """A dataset's options are its module's: it is imported to make its command, and a broken one is said once."""
    site = install(tmp_path / "site", BROKEN_DATASET, "demo-data")
    done = dcslam(site, "synth", "--help", cwd=tmp_path)
    assert done.returncode == 0 and "Usage:" in done.stdout
    assert done.stderr == ("warning: dataset 'broken-data' (package demo-data, entry point demo_plugin_missing) "
                           "cannot be loaded (ModuleNotFoundError: No module named 'demo_plugin_missing'); fix or "
                           "uninstall the package (dcslam prepare-broken-data is not available)\n")


def test_filters_and_datasets_of_installed_packages(installed, tmp_path):
    from dcslam.filters import filter_help, parse_filter
    from dcslam.stages.datasets import dataset, installed as installed_datasets
    from dcslam.stages.filter import FilterConfig, run

    assert "from installed packages far, not-a-filter" in filter_help()
    far = parse_filter("far:max_m=12")
    assert type(far).__name__ == "FarFilter" and far.max_m == 12
    ws_root = depth_fixtures.write_workspace(tmp_path / "ws", n=2)
    from dcslam.workspace import Workspace

    result = run(Workspace(ws_root), FilterConfig(filters=["far:max_m=12"], depth="dense", name="near"))
    from dcslam.io.drive import read_layer

    depth = read_layer(result.layers[0]).depth
    assert depth.max() <= 12 and depth.max() > 0
    with pytest.raises(DcslamError, match="'not-a-filter' .*demo-plugin.* is not a filter"):
        parse_filter("not-a-filter")
    with pytest.raises(DcslamError, match="unknown filter 'nope'; expected one of .*far"):
        parse_filter("nope")
    assert installed_datasets() == ()
    install(installed, BROKEN_DATASET, "demo-data")
    from dcslam import plugins

    plugins._installed.cache_clear()
    assert installed_datasets() == ("broken-data",)
    with pytest.raises(DcslamError, match="dataset 'broken-data' .*cannot be loaded"):
        dataset("broken-data")
    assert dataset("kitti").__name__ == "dcslam.stages.prepare"


def test_without_plugins_the_registries_are_dcslams_own(monkeypatch):
    from dcslam import plugins
    from dcslam.depth.models import CLASSICAL

    assert all(plugins.plugins(group) == {} for group in plugins.GROUPS)
    assert all(target.startswith("dcslam.") for target in CLASSICAL.values())
    with pytest.raises(DcslamError, match="unknown plugin group"):
        plugins.plugins("dcslam.other")
