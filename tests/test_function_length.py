"""No function in dcslam/ is longer than 60 lines (its ``def`` line to its last line, docstring included): a longer
one does several things, and the next change to one of them has to read all of them."""
import ast
from pathlib import Path

PACKAGE = Path(__file__).parents[1] / "dcslam"
MAX_LINES = 60


def long_functions(package: Path = PACKAGE, limit: int = MAX_LINES) -> list[str]:
    found = []
    for path in sorted(package.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = node.end_lineno - node.lineno + 1
                if lines > limit:
                    found.append(f"{path.relative_to(package.parent)}:{node.lineno} {node.name} ({lines} lines)")
    return found


def test_the_check_counts_def_to_last_line(tmp_path):
    (tmp_path / "m.py").write_text("def short():\n" + "    x = 1\n" * 59 + "\n\ndef long():\n" + "    x = 1\n" * 60)
    assert long_functions(tmp_path) == [f"{tmp_path.name}/m.py:63 long (61 lines)"]


def test_no_function_over_60_lines():
    assert long_functions() == []
