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
    """Render rows under headers; floats use ``fmt``. Returns the text without a newline."""
    cells = [[_cell(v, fmt) for v in row] for row in rows]
    widths = [len(h) for h in headers]
    for row in cells:
        for i, c in enumerate(row):
            widths[i] = max(widths[i], len(c))
    lines = []
    if title:
        lines.append(title)
    lines.append("  ".join(h.rjust(w) for h, w in zip(headers, widths, strict=True)))
    lines.append("  ".join("-" * w for w in widths))
    for row in cells:
        lines.append("  ".join(c.rjust(w) for c, w in zip(row, widths, strict=True)))
    return "\n".join(lines)
