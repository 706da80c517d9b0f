"""The benchmark tables: every bench module prints its figures as Markdown with ``table``."""

from __future__ import annotations

from collections.abc import Callable, Sequence

#: one row of a table: each cell printed with str()
Row = tuple[object, ...]
#: how the table functions of the bench modules receive ``table``
Table = Callable[[str, tuple[str, ...], Sequence[Row]], None]


def table(title: str, header: tuple[str, ...], rows: Sequence[Row]) -> None:
    print(f"\n{title}\n")
    widths = [max(len(str(x)) for x in column) for column in zip(header, *rows, strict=True)]
    print("| " + " | ".join(str(h).ljust(w) for h, w in zip(header, widths, strict=True)) + " |")
    print("|" + "|".join("-" * (w + 2) for w in widths) + "|")
    for row in rows:
        print("| " + " | ".join(str(x).ljust(w) for x, w in zip(row, widths, strict=True)) + " |")
