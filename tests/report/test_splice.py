"""Result tables spliced into pages: known inputs give a known page; a missing file, an unknown column or row and an
unclosed marker fail with one line naming the page and line."""
import json

import pytest

from dcslam.errors import DcslamError
from dcslam.report.splice import csv_table, find_regions, markdown_tables, select, splice, splice_page

RESULTS_MD = """### Table 5.2 — 2 test drive(s)

| method | layer | failed | localisation accuracy |
| --- | --- | --- | --- |
| sparse depth | sparse | 0 | 0.0482 ± 0.0437 |
| dense depth | dense | 0 | 0.0364 ± 0.0130 |
| IP-Basic | ip-basic-fast | 1 | 0.2459 ± 0.2275 |

- localisation accuracy: the thesis's metric

### Table 5.2, whole drives

| method | frames per drive |
| --- | --- |
| sparse depth | 32 |
"""
PROVENANCE = {"commit": "0123abc", "date": "2026-12-01", "profile": "quick", "command": "make reproduce-table-5-2",
              "machine": "2 CPU cores"}
LINE = "Provenance: commit 0123abc, 2026-12-01, profile quick, `make reproduce-table-5-2`, machine: 2 CPU cores."


@pytest.fixture
def results(tmp_path):
    folder = tmp_path / "results" / "table_5_2"
    folder.mkdir(parents=True)
    (folder / "table_5_2.md").write_text(RESULTS_MD)
    (folder / "table_5_2.csv").write_text("method,failures\nsparse depth,0\ndense depth,0\n")
    (folder / "provenance.json").write_text(json.dumps(PROVENANCE))
    return tmp_path


def test_known_page(results):
    page = results / "RESULTS.md"
    text = ("# Results\n\nbefore\n"
            '<!-- table: results/table_5_2/table_5_2.md columns="method,localisation accuracy,failed" '
            'rows="IP-Basic,sparse depth" -->\nstale\n<!-- /table -->\n'
            "between\n<!-- table: results/table_5_2/table_5_2.md index=2 -->\n<!-- /table -->\nafter\n")
    page.write_text(text)
    result = splice_page(page)
    assert result.text == (
        "# Results\n\nbefore\n"
        '<!-- table: results/table_5_2/table_5_2.md columns="method,localisation accuracy,failed" '
        'rows="IP-Basic,sparse depth" -->\n'
        "| method | localisation accuracy | failed |\n| --- | --- | --- |\n"
        "| IP-Basic | 0.2459 ± 0.2275 | 1 |\n| sparse depth | 0.0482 ± 0.0437 | 0 |\n\n"
        f"{LINE}\n<!-- /table -->\n"
        "between\n<!-- table: results/table_5_2/table_5_2.md index=2 -->\n"
        f"| method | frames per drive |\n| --- | --- |\n| sparse depth | 32 |\n\n{LINE}\n<!-- /table -->\nafter\n")
    assert [r.line for r in result.changed] == [4, 8]
    again = splice(result.text, page)  # a spliced page is a fixed point
    assert again.text == result.text and again.changed == ()


def test_names_with_commas_and_rows_keyed_by_several_columns(results):
    folder = results / "results" / "table_5_2"
    (folder / "beams.md").write_text("| beams | input | localisation |\n| --- | --- | --- |\n| 64 | sparse | 0.05 |\n"
                                     "| 8 | sparse | 0.30 |\n| 8 | pose, fine-tuned | 0.42 |\n")
    text = ('<!-- table: results/table_5_2/beams.md key="beams,input" rows="8 / pose\\, fine-tuned,8 / sparse" '
            'columns="input,localisation" -->\n<!-- /table -->\n')
    body = splice(text, results / "RESULTS.md").text
    assert "| input | localisation |\n| --- | --- |\n| pose, fine-tuned | 0.42 |\n| sparse | 0.30 |\n" in body
    with pytest.raises(DcslamError, match=r"no row '64'; the rows are: 64 / sparse, 8 / sparse"):
        splice(text.replace("8 / sparse", "64"), results / "RESULTS.md")


def test_csv_file(results):
    text = '<!-- table: results/table_5_2/table_5_2.csv rows="dense depth" -->\n<!-- /table -->\n'
    body = splice(text, results / "RESULTS.md").text
    assert "| method | failures |\n| --- | --- |\n| dense depth | 0 |\n" in body


def test_page_in_a_subfolder_resolves_paths_from_its_folder(results):
    (results / "docs").mkdir()
    text = "<!-- table: ../results/table_5_2/table_5_2.md columns=method -->\n<!-- /table -->\n"
    assert "| sparse depth |" in splice(text, results / "docs" / "page.md").text


@pytest.mark.parametrize("marker, message", [
    ("<!-- table: results/table_5_2/nope.md -->\n<!-- /table -->", r"RESULTS.md:2: results file .*nope.md not found"),
    ('<!-- table: results/table_5_2/table_5_2.md columns="method,speed" -->\n<!-- /table -->',
     r"RESULTS.md:2: table_5_2.md: no column 'speed'; the columns are: method, layer, failed"),
    ('<!-- table: results/table_5_2/table_5_2.md rows="exact" -->\n<!-- /table -->',
     r"RESULTS.md:2: table_5_2.md: no row 'exact'; the rows are: sparse depth, dense depth, IP-Basic"),
    ("<!-- table: results/table_5_2/table_5_2.md -->\nno end", r"RESULTS.md:2: table marker is not closed"),
    ("<!-- table: results/table_5_2/table_5_2.md -->\n<!-- table: x.md -->\n<!-- /table -->",
     r"RESULTS.md:2: table marker is not closed before the next one"),
    ("text\n<!-- /table -->", r"RESULTS.md:3: <!-- /table --> without an opening"),
    ("<!-- table: results/table_5_2/table_5_2.md index=3 -->\n<!-- /table -->", r"holds 2 table\(s\), not a table"),
    ("<!-- table: results/table_5_2/table_5_2.md index=0 -->\n<!-- /table -->", r"index= must be a whole number"),
    ("<!-- table: results/table_5_2/table_5_2.md colums=method -->\n<!-- /table -->",
     r"unknown marker attribute 'colums=method'; expected columns=, rows=, key= or index="),
    ("<!-- table: columns=method -->\n<!-- /table -->", r"the marker names no results file"),
])
def test_mistakes_fail_with_one_line(results, marker, message):
    with pytest.raises(DcslamError, match=message) as caught:
        splice(f"# page\n{marker}\n", results / "RESULTS.md")
    assert "\n" not in str(caught.value)


def test_missing_provenance_names_the_command_that_writes_it(results):
    (results / "results" / "table_5_2" / "provenance.json").unlink()
    with pytest.raises(DcslamError, match=r"provenance.json: missing; copy the results with `dcslam score collect`"):
        splice("<!-- table: results/table_5_2/table_5_2.md -->\n<!-- /table -->\n", results / "RESULTS.md")


def test_tables_and_selection():
    first, second = markdown_tables(RESULTS_MD)
    assert first.header == ("method", "layer", "failed", "localisation accuracy") and len(first.rows) == 3
    assert second.rows == (("sparse depth", "32"),)
    chosen = select(first, ("failed", "method"), ("dense depth",), "here")
    assert chosen.header == ("failed", "method") and chosen.rows == (("0", "dense depth"),)
    assert select(first, (), (), "here") == first
    assert csv_table("a,b\n1,2\n").rows == (("1", "2"),)
    assert find_regions("no markers here", "p.md") == []
