"""The documentation stays a tool's documentation: a short README, no issue numbers or commit hashes outside the
provenance lines of result tables, and result tables that match their committed files."""
import re
from pathlib import Path

import pytest

from dcslam.report.provenance import PROVENANCE_PREFIX

ROOT = Path(__file__).parents[1]
PAGES = [ROOT / "README.md", ROOT / "RESULTS.md", *sorted((ROOT / "docs").glob("*.md"))]
SPLICED = [ROOT / "README.md", ROOT / "RESULTS.md"]
#: 7-40 hex digits with at least one letter and one digit: the form of an abbreviated or full commit hash.
COMMIT = re.compile(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b")
ISSUE = re.compile(r"\bissues?\s*#?\d+|#\d+\b", re.IGNORECASE)


def _offending_lines(path: Path) -> list[str]:
    found = []
    for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
        if line.lstrip("#*/ ").startswith(PROVENANCE_PREFIX):
            continue
        for pattern in (COMMIT, ISSUE):
            match = pattern.search(line)
            if match:
                found.append(f"{path.relative_to(ROOT)}:{number}: {match.group(0)!r}")
    return found


def test_readme_is_short():
    lines = (ROOT / "README.md").read_text().count("\n")
    assert lines <= 220, f"README.md has {lines} lines; move detail into docs/"


def test_the_pages_exist():
    assert [p.name for p in PAGES[2:]] == sorted(
        ["architecture.md", "benchmarks.md", "bring-your-own-completer.md", "extending.md", "formats.md",
         "getting-started.md", "metrics.md", "slam.md", "training.md", "usage.md"])
    assert (ROOT / "CHANGELOG.md").is_file()


@pytest.mark.parametrize("path", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_issue_numbers_or_commit_hashes_in_the_pages(path):
    assert _offending_lines(path) == []


def test_no_issue_numbers_or_commit_hashes_in_the_package():
    found = [line for path in sorted((ROOT / "dcslam").rglob("*.py")) for line in _offending_lines(path)]
    assert found == []


def test_the_patterns_catch_what_they_should():
    assert COMMIT.search("rerun at 1a2b3c4") and COMMIT.search("commit deadbee5 said")
    assert not COMMIT.search("frame 0000000005.png") and not COMMIT.search("seed 2026, 1242 x 375, facade")
    assert ISSUE.search("issue 99") and ISSUE.search("(issue #7)") and not ISSUE.search("no issue here")


@pytest.mark.parametrize("page", SPLICED, ids=lambda p: p.name)
def test_spliced_tables_match_the_committed_results(cli, page):
    if not any(p.is_file() for p in (ROOT / "results").rglob("*")):
        pytest.skip("results/ holds no result files yet: nothing to splice")
    result = cli("score", "page", str(page), "--check")
    assert result.exit_code == 0, result.output
