"""Markdown tables of the LVDS register maps and status bits, generated from
:mod:`firmware_model.fpga.layout` (``python -m firmware_model.fpga.regdoc``); the docs
carry this output and a test checks they still match."""

from __future__ import annotations

from firmware_model.fpga import layout as B


def _rows(regs: tuple) -> list[str]:
    out = ["| addr | name | type | unit | meaning |", "|---|---|---|---|---|"]
    out += [f"| 0x{a:02X} | `{n}` | {t} | {u} | {m} |" for a, n, t, u, m in regs]
    return out


def markdown() -> str:
    """The three tables: downstream memory, upstream memory, status bits."""
    lines = [f"Downstream memory (MCU -> driver), {B.DOWN_WORDS} words swept:", ""]
    lines += _rows(B.DOWN_REGISTERS)
    lines += ["", f"Upstream memory (driver -> MCU), {B.UP_WORDS} words swept:", ""]
    lines += _rows(B.UP_REGISTERS)
    lines += ["", "Status word bits (upstream 0x00):", "", "| bit | name | meaning |",
              "|---|---|---|"]
    lines += [f"| {b} | `{n}` | {m} |" for b, n, m in B.STATUS_BITS]
    return "\n".join(lines)


if __name__ == "__main__":
    print(markdown())
