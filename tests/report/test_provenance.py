"""Committed results: a workspace's results copied with their provenance record; the record read back and written
as one line; the processor a record names by default."""
import json
import platform
import subprocess

import pytest

from dcslam.errors import DcslamError
from dcslam.report.provenance import collect_results, cpu_name, default_machine, provenance_line, read_provenance


def _workspace_results(root):
    results = root / "ws" / "results"
    results.mkdir(parents=True)
    (results / "table_5_2.md").write_text("| a |\n| --- |\n| 1 |\n")
    (results / "table_5_2.csv").write_text("a\n1\n")
    (results / "plot.png").write_bytes(b"\x89PNG")
    (results / "score-tables.json").write_text(json.dumps({"written": "2026-11-30T10:00:00+0000"}))
    return results


def test_collect_copies_results_with_provenance(tmp_path):
    source = _workspace_results(tmp_path)
    done = collect_results(source, tmp_path / "repo" / "results" / "t52", profile="quick",
                           command="make reproduce-table-5-2", machine="2 CPU cores", commit="0123abc")
    assert sorted(p.name for p in done.files) == ["table_5_2.csv", "table_5_2.md"]
    record = read_provenance(done.dest)
    assert record == {"commit": "0123abc", "modified": False, "date": "2026-11-30", "profile": "quick",
                      "command": "make reproduce-table-5-2", "machine": "2 CPU cores",
                      "files": ["table_5_2.csv", "table_5_2.md"]}
    assert (done.dest / "table_5_2.md").read_text() == (source / "table_5_2.md").read_text()
    assert provenance_line(record) == ("Provenance: commit 0123abc, 2026-11-30, profile quick, "
                                       "`make reproduce-table-5-2`, machine: 2 CPU cores.")


def test_collect_refuses_to_replace_without_force_and_prunes_with_it(tmp_path):
    source = _workspace_results(tmp_path)
    dest = tmp_path / "results" / "t52"
    collect_results(source, dest, commit="0123abc")
    with pytest.raises(DcslamError, match="holds results already; pass --force"):
        collect_results(source, dest, commit="0123abc")
    (source / "table_5_2.csv").unlink()
    collect_results(source, dest, commit="4567def", force=True)
    assert sorted(p.name for p in dest.iterdir()) == ["provenance.json", "table_5_2.md"]
    assert read_provenance(dest)["commit"] == "4567def"


def test_collect_reads_the_commit_of_the_checkout(tmp_path):
    source = _workspace_results(tmp_path)
    repo = tmp_path / "repo"
    repo.mkdir()
    git = ["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t"]
    try:
        subprocess.run([*git, "init", "-q"], check=True)
        (repo / "f.txt").write_text("x")
        subprocess.run([*git, "add", "f.txt"], check=True)
        subprocess.run([*git, "commit", "-q", "-m", "m"], check=True)
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("git is not available")
    head = subprocess.run([*git, "rev-parse", "--short=12", "HEAD"], capture_output=True, text=True).stdout.strip()
    record = collect_results(source, repo / "results" / "t52").provenance
    assert record["commit"] == head and record["modified"] is False
    (repo / "f.txt").write_text("changed")
    record = collect_results(source, repo / "results" / "t52", force=True).provenance
    assert record["modified"] is True and "(with uncommitted changes)" in provenance_line(record)


def test_collect_outside_a_checkout_asks_for_the_commit(tmp_path):
    source = _workspace_results(tmp_path)
    with pytest.raises(DcslamError, match="not inside a git checkout; pass --commit"):
        collect_results(source, tmp_path / "results" / "t52")


def test_collect_needs_results(tmp_path):
    with pytest.raises(DcslamError, match="no results folder; run `dcslam score tables`"):
        collect_results(tmp_path / "nope", tmp_path / "out", commit="0123abc")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DcslamError, match="no results files matching"):
        collect_results(tmp_path / "empty", tmp_path / "out", commit="0123abc")


def test_provenance_line_with_a_note_and_without_optional_fields():
    record = {"commit": "0123abc", "date": "2026-12-01", "note": "transcribed by hand."}
    assert provenance_line(record) == "Provenance: commit 0123abc, 2026-12-01. transcribed by hand."


@pytest.mark.parametrize("content, message", [
    ("{not json", "not a provenance record"),
    ('{"date": "2026-12-01"}', "needs at least commit and date"),
])
def test_malformed_provenance(tmp_path, content, message):
    (tmp_path / "provenance.json").write_text(content)
    with pytest.raises(DcslamError, match=message):
        read_provenance(tmp_path)


XEON = """processor\t: 0
vendor_id\t: GenuineIntel
cpu family\t: 6
model\t\t: 106
model name\t: Intel(R) Xeon(R) Platinum 8375C CPU @ 2.90GHz
flags\t\t: fpu sse sse2 avx avx2 avx512f avx512dq

processor\t: 1
model name\t: another name
flags\t\t: fpu sse
"""


def test_cpu_name_gives_the_model_its_numbers_and_widest_vector_extension():
    assert cpu_name(XEON) == "Intel(R) Xeon(R) Platinum 8375C CPU @ 2.90GHz (family 6, model 106; AVX-512)"
    amd = "processor\t: 0\ncpu family\t: 25\nmodel\t\t: 1\nmodel name\t: AMD EPYC\nflags\t\t: sse2 avx avx2 fma\n"
    assert cpu_name(amd) == "AMD EPYC (family 25, model 1; AVX2)"  # the two AMD hosts both call themselves AMD EPYC
    arm = "processor\t: 0\nBogoMIPS\t: 50.00\nFeatures\t: fp asimd\nCPU implementer\t: 0x41\n"
    assert cpu_name(arm) == cpu_name("") == (platform.processor() or platform.machine())  # no model name
    assert cpu_name() in default_machine() and "CPU cores" in default_machine()
