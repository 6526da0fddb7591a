"""The end of ``dcslam reproduce``: the table's headline columns as a compact terminal table within the terminal's
width, cells unwrapped, and the path of the full Markdown table (not the 21-column Markdown itself)."""
from dcslam.cli.reproduce import read_markdown_table, report
from dcslam.report.table_5_2 import TABLE_5_2_COLUMNS
from dcslam.report.tables import Table

ROWS = [{"method": "pose, fine-tuned from chamfer-8", "layer": "pose-from-chamfer-8", "drives": 4, "failures": 3,
         "localisation_text": "0.3928 ± 0.1477", "vs_sparse": "within spread", "mae_mm_text": "1783.9 ± 459.0",
         "ate_rmse_m_text": "0.262 ± 0.095", "notes": "drives too short (longest 31 m < 100 m)"},
        {"method": "sparse depth", "layer": "sparse", "drives": 4, "failures": 0,
         "localisation_text": "0.0485 ± 0.0444", "vs_sparse": "reference", "ate_rmse_m_text": "0.028 ± 0.029"}]


def write_table(tmp_path):
    table = Table("Table 5.2 — 4 test drive(s)", TABLE_5_2_COLUMNS, ROWS, ["a note | with a bar"])
    path = tmp_path / "table_5_2.md"
    path.write_text(table.to_markdown())
    return table, path


def test_the_markdown_table_reads_back(tmp_path):
    table, path = write_table(tmp_path)
    title, headers, rows = read_markdown_table(path)
    assert title == table.title and headers == [c.header for c in TABLE_5_2_COLUMNS]
    assert rows == [[table.cell(r, c) for c in TABLE_5_2_COLUMNS] for r in ROWS]


def test_the_end_prints_a_compact_table_and_the_full_tables_path(tmp_path, capsys, monkeypatch):
    _, path = write_table(tmp_path)
    # 80 columns: method, failed, localisation, vs sparse; 120 (at most WIDTH = 100 used): and ATE
    for columns, shown, hidden in ((80, ("failed", "localisation", "vs sparse"), ("ATE RMSE (m)", "MAE (mm)")),
                                   (120, ("failed", "localisation", "vs sparse", "ATE RMSE (m)"), ("MAE (mm)",))):
        monkeypatch.setenv("COLUMNS", str(columns))
        report((path, 60.0))
        out = capsys.readouterr().out
        lines = out.splitlines()
        assert max(len(line) for line in lines[:-1]) <= columns, out
        assert all(h in out for h in shown) and not any(h in out for h in hidden), out
        assert "why —" not in out and "|" not in out and "0.3928 ± 0.1477" in out  # a cell on one line
        assert lines[-1] == f"full table ({len(TABLE_5_2_COLUMNS) - len(shown) - 1} more columns): {path}"
