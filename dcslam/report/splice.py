"""Result tables spliced into Markdown pages, so that a page shows the figures of committed results files.

A page marks each region with an opening and a closing comment; everything between them is rewritten::

    <!-- table: results/table_5_2/table_5_2.md columns="method,failed,localisation accuracy" rows="sparse depth" -->
    ...
    <!-- /table -->

The path is relative to the page's folder. ``columns`` and ``rows`` (optional, comma-separated; ``\\,`` is a comma
inside a name) keep only the named columns (by header) and rows (by their first cell, or by the cells of the
``key`` columns joined by `` / ``), in the order given; ``index`` (optional, from 1) picks the file's n-th table
(default the first). The region then holds that table followed by the provenance line of the
``provenance.json`` beside the file (written by :func:`dcslam.report.provenance.collect_results`). The results
files are CSV or Markdown as ``dcslam score`` writes them; a CSV file's first row is its header.
"""
from __future__ import annotations

import csv
import io
import re
import shlex
from dataclasses import dataclass
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.report.provenance import provenance_line, read_provenance

OPEN = re.compile(r"<!--\s*table:\s*(?P<body>.*?)\s*-->")
CLOSE = re.compile(r"<!--\s*/table\s*-->")


@dataclass(frozen=True)
class MarkdownTable:
    """A table as header cells and rows of cells (strings, as written)."""

    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]

    def render(self) -> str:
        lines = [_row(self.header), _row(("---",) * len(self.header))]
        lines += [_row(r) for r in self.rows]
        return "\n".join(lines)


@dataclass(frozen=True)
class Region:
    """One marked region of a page: what its opening marker asks for, and where its body lies in the text."""

    source: str                  # the path as written in the marker
    columns: tuple[str, ...]     # empty: every column
    rows: tuple[str, ...]        # empty: every row
    key: tuple[str, ...]         # columns whose cells, joined by " / ", name a row; empty: the first column
    index: int                   # which table of the file, from 1
    line: int                    # line number of the opening marker
    body_start: int              # offsets of the text between the markers
    body_end: int


@dataclass(frozen=True)
class SpliceResult:
    """A page with its regions refreshed: the new text, its regions, and those whose body changed."""

    page: Path
    text: str
    regions: tuple[Region, ...]
    changed: tuple[Region, ...]


def _row(cells) -> str:
    return "| " + " | ".join(cells) + " |"


def _cells(line: str) -> tuple[str, ...]:
    inner = line.strip()
    inner = inner[1:] if inner.startswith("|") else inner
    inner = inner[:-1] if inner.endswith("|") else inner
    return tuple(c.strip() for c in re.split(r"(?<!\\)\|", inner))


def _is_rule(line: str) -> bool:
    cells = _cells(line)
    return bool(cells) and all(re.fullmatch(r":?-{3,}:?", c) for c in cells)


def markdown_tables(text: str) -> list[MarkdownTable]:
    """Every pipe table in ``text`` (a header line, a ``| --- |`` rule, then rows), in order."""
    lines = text.splitlines()
    tables, i = [], 0
    while i + 1 < len(lines):
        if lines[i].lstrip().startswith("|") and _is_rule(lines[i + 1]):
            header = _cells(lines[i])
            rows, i = [], i + 2
            while i < len(lines) and lines[i].lstrip().startswith("|"):
                cells = _cells(lines[i])
                rows.append(cells + ("",) * (len(header) - len(cells)))
                i += 1
            tables.append(MarkdownTable(header, tuple(rows)))
        else:
            i += 1
    return tables


def csv_table(text: str) -> MarkdownTable:
    """A CSV file's rows as a table; its first row is the header."""
    rows = [tuple(r) for r in csv.reader(io.StringIO(text)) if r]
    if not rows:
        return MarkdownTable((), ())
    return MarkdownTable(rows[0], tuple(rows[1:]))


def _attributes(body: str, where: str) -> tuple[str, dict[str, str]]:
    try:
        words = shlex.split(body)
    except ValueError as exc:
        raise DcslamError(f"{where}: cannot read the marker ({exc}); write <!-- table: PATH "
                          f'columns="a,b" rows="x,y" -->') from None
    if not words or "=" in words[0]:
        raise DcslamError(f"{where}: the marker names no results file; write <!-- table: PATH ... -->")
    attrs = {}
    for word in words[1:]:
        key, sep, value = word.partition("=")
        if not sep or key not in ("columns", "rows", "key", "index"):
            raise DcslamError(f"{where}: unknown marker attribute {word!r}; expected columns=, rows=, key= or index=")
        attrs[key] = value
    return words[0], attrs


def _names(value: str | None) -> tuple[str, ...]:
    """Comma-separated names; ``\\,`` is a comma inside a name (``rows="pose\\, fine-tuned from chamfer-8"``)."""
    if not value:
        return ()
    return tuple(v.replace("\\,", ",").strip() for v in re.split(r"(?<!\\),", value) if v.strip())


def find_regions(text: str, page: str) -> list[Region]:
    """The marked regions of ``text``; a marker left open, a closing marker without an opening one, or a region
    inside another fails naming the page and line."""
    regions, pos = [], 0
    while True:
        opening, closing = OPEN.search(text, pos), CLOSE.search(text, pos)
        if opening is None:
            if closing is not None:
                line = text.count("\n", 0, closing.start()) + 1
                raise DcslamError(f"{page}:{line}: <!-- /table --> without an opening <!-- table: ... --> marker")
            return regions
        line = text.count("\n", 0, opening.start()) + 1
        where = f"{page}:{line}"
        if closing is not None and closing.start() < opening.start():
            line = text.count("\n", 0, closing.start()) + 1
            raise DcslamError(f"{page}:{line}: <!-- /table --> without an opening <!-- table: ... --> marker")
        if closing is None:
            raise DcslamError(f"{where}: table marker is not closed; add <!-- /table --> after it")
        following = OPEN.search(text, opening.end())
        if following is not None and following.start() < closing.start():
            raise DcslamError(f"{where}: table marker is not closed before the next one; add <!-- /table -->")
        source, attrs = _attributes(opening.group("body"), where)
        try:
            index = int(attrs.get("index", "1"))
        except ValueError:
            index = 0
        if index < 1:
            raise DcslamError(f"{where}: index= must be a whole number from 1, got {attrs['index']!r}")
        regions.append(Region(source, _names(attrs.get("columns")), _names(attrs.get("rows")),
                              _names(attrs.get("key")), index, line, opening.end(), closing.start()))
        pos = closing.end()


def select(table: MarkdownTable, columns: tuple[str, ...], rows: tuple[str, ...], where: str,
           key: tuple[str, ...] = ()) -> MarkdownTable:
    """Only ``columns`` (by header) and ``rows`` (by name), in the order given; an empty selection keeps everything.
    A row's name is its first cell, or with ``key`` the cells of those columns joined by `` / `` (``64 / sparse``).
    An unknown name fails listing the ones there are."""
    def index_of(names: tuple[str, ...]) -> list[int]:
        missing = [c for c in names if c not in table.header]
        if missing:
            raise DcslamError(f"{where}: no column {missing[0]!r}; the columns are: {', '.join(table.header)}")
        return [table.header.index(c) for c in names]

    keep = index_of(columns) if columns else list(range(len(table.header)))
    chosen = list(table.rows)
    if rows:
        by = index_of(key) if key else [0]
        names = [" / ".join(r[i] for i in by) for r in table.rows]
        missing = [r for r in rows if r not in names]
        if missing:
            raise DcslamError(f"{where}: no row {missing[0]!r}; the rows are: {', '.join(names)}")
        chosen = [table.rows[names.index(r)] for r in rows]
    return MarkdownTable(tuple(table.header[i] for i in keep), tuple(tuple(r[i] for i in keep) for r in chosen))


def region_text(region: Region, page_dir: Path, where: str) -> str:
    """The body a region should hold: its file's table (selected) and the provenance line, between blank lines."""
    path = page_dir / region.source
    if not path.is_file():
        raise DcslamError(f"{where}: results file {path} not found; copy it with `dcslam score collect` or fix "
                          f"the marker's path (relative to the page)")
    text = path.read_text()
    tables = [csv_table(text)] if path.suffix == ".csv" else markdown_tables(text)
    if len(tables) < region.index or not tables[region.index - 1].header:
        raise DcslamError(f"{where}: {path} holds {len(tables)} table(s), not a table number {region.index}")
    table = select(tables[region.index - 1], region.columns, region.rows, f"{where}: {path.name}", region.key)
    return f"\n{table.render()}\n\n{provenance_line(read_provenance(path.parent))}\n"


def splice(text: str, page: Path) -> SpliceResult:
    """``text`` (the page ``page``) with every marked region rewritten from its results file."""
    regions = find_regions(text, str(page))
    pieces, changed, pos = [], [], 0
    for region in regions:
        body = region_text(region, page.parent, f"{page}:{region.line}")
        if text[region.body_start:region.body_end] != body:
            changed.append(region)
        pieces += [text[pos:region.body_start], body]
        pos = region.body_end
    pieces.append(text[pos:])
    return SpliceResult(page, "".join(pieces), tuple(regions), tuple(changed))


def splice_page(page: Path) -> SpliceResult:
    """:func:`splice` of the file ``page``."""
    if not page.is_file():
        raise DcslamError(f"{page}: no such page")
    return splice(page.read_text(), page)
