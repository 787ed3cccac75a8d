"""The register maps in docs/fpga.md are the ones the code uses."""

from __future__ import annotations

from pathlib import Path

from firmware_model.fpga import regdoc

DOC = Path(__file__).resolve().parents[2] / "docs" / "fpga.md"


def test_register_tables_in_the_docs_match_the_layout():
    text = DOC.read_text(encoding="utf-8")
    assert regdoc.markdown() in text, (
        "docs/fpga.md register tables are stale: paste `python -m firmware_model.fpga.regdoc`")
