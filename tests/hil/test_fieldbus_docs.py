"""docs/fieldbus.md shows the process-data records as declared in hil/fieldbus/pdo.py."""

from pathlib import Path

import pytest

from hil.fieldbus import pdo

DOC = Path(__file__).resolve().parents[2] / "docs" / "fieldbus.md"


@pytest.mark.parametrize("fields", [pdo.ACTUATOR_OUT, pdo.ACTUATOR_IN, pdo.FOOT_IN, pdo.IMU_IN])
def test_doc_tables_match_declaration(fields):
    assert pdo.markdown_table(fields) in DOC.read_text()


def test_record_sizes():
    assert pdo.slot_sizes("actuator") == (10, 22)
    assert pdo.ACTUATOR_IN_DTYPE.itemsize == sum(
        int(f.dtype[1]) for f in pdo.ACTUATOR_IN)
