"""`dcslam score page` and `dcslam score collect`: exit codes, the files they write, and what --check leaves."""
import json



MARKER = '<!-- table: results/t/table.md columns="method,failed" -->\n'




def _results(root, failed="0"):
    folder = root / "results" / "t"
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "table.md").write_text("| method | layer | failed |\n| --- | --- | --- |\n"
                                     f"| sparse depth | s | {failed} |\n")
    (folder / "provenance.json").write_text(json.dumps({"commit": "0123abc", "date": "2026-12-01"}))


def test_page_rewrites_then_check_passes(cli, tmp_path):
    _results(tmp_path)
    page = tmp_path / "RESULTS.md"
    page.write_text(f"# R\n{MARKER}old\n<!-- /table -->\n")
    result = cli("score", "page", page, "--check")
    assert result.exit_code == 1
    assert "RESULTS.md:2: the table from results/t/table.md differs from its file" in result.output
    assert page.read_text() == f"# R\n{MARKER}old\n<!-- /table -->\n"  # --check writes nothing

    result = cli("score", "page", page)
    assert result.exit_code == 0 and "rewrote 1 of 1 table region(s)" in result.output
    assert "| sparse depth | 0 |\n\nProvenance: commit 0123abc, 2026-12-01.\n<!-- /table -->" in page.read_text()
    assert cli("score", "page", page, "--check").exit_code == 0

    _results(tmp_path, failed="2")  # the results changed: the page is stale again
    assert cli("score", "page", page, "--check").exit_code == 1


def test_page_errors_exit_1_with_one_line(cli, tmp_path):
    page = tmp_path / "RESULTS.md"
    result = cli("score", "page", page)
    assert result.exit_code == 1 and result.output.strip() == f"error: {page}: no such page"
    page.write_text(f"{MARKER}\n")
    result = cli("score", "page", page)
    assert result.exit_code == 1 and "table marker is not closed" in result.output
    assert len(result.output.strip().splitlines()) == 1


def test_collect_writes_results_and_provenance(cli, tmp_path):
    results = tmp_path / "ws" / "results"
    results.mkdir(parents=True)
    (results / "table_5_2.md").write_text("| a |\n| --- |\n| 1 |\n")
    dest = tmp_path / "repo-results"
    args = ("score", "collect", "--name", "table_5_2", "-w", tmp_path / "ws", "--dest", dest, "--commit", "0123abc",
            "--profile", "smoke")
    result = cli(*args)
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in (dest / "table_5_2").iterdir()) == ["provenance.json", "table_5_2.md"]
    assert json.loads((dest / "table_5_2" / "provenance.json").read_text())["profile"] == "smoke"
    assert cli(*args).exit_code == 1  # exists: --force
    assert cli(*args, "--force").exit_code == 0
    assert cli("score", "collect", "--name", "../x", "-w", tmp_path / "ws").exit_code == 1
