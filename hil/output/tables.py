"""Plain-text tables for the terminal (no dependency, right-aligned numbers)."""

from __future__ import annotations

from collections.abc import Sequence


def _cell(value: object, fmt: str) -> str:
    if isinstance(value, float):
        return format(value, fmt)
    return str(value)


def table(
    headers: Sequence[str], rows: Sequence[Sequence[object]], fmt: str = ".4g", title: str = ""
) -> str:
    """Render rows under headers; floats use ``fmt``. Returns the text without a final newline."""
    cells = [[_cell(v, fmt) for v in row] for row in rows]
    widths = [len(h) for h in headers]
    for row in cells:
        for i, c in enumerate(row):
            widths[i] = max(widths[i], len(c))
    lines = []
    if title:
        lines.append(title)
    def line(items: Sequence[str]) -> str:
        # The first column names the row: left-aligned; the rest are values: right-aligned.
        parts = [items[0].ljust(widths[0])]
        parts += [c.rjust(w) for c, w in zip(items[1:], widths[1:], strict=True)]
        return "  ".join(parts).rstrip()

    lines.append(line(list(headers)))
    lines.append("  ".join("-" * w for w in widths))
    lines.extend(line(row) for row in cells)
    return "\n".join(lines)
