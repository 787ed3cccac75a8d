"""Rules of the layout, checked on the source: only hil/transports/ knows a transport by
name; the firmware models do not import the plant or the harness; the plant does not import
the harness."""

from __future__ import annotations

import ast
from pathlib import Path

from hil.transports import BACKENDS

ROOT = Path(__file__).resolve().parents[2]


def _sources(package: str, skip: tuple[str, ...] = ()) -> list[Path]:
    return [p for p in sorted((ROOT / package).rglob("*.py"))
            if not any(str(p.relative_to(ROOT)).startswith(s) for s in skip)]


def _branches_on_backend_name(tree: ast.AST) -> list[int]:
    """Lines comparing something with a backend's name (==, !=, in, match case)."""
    names = set(BACKENDS)
    lines = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            parts = [node.left, *node.comparators]
            consts = [p for p in parts if isinstance(p, ast.Constant) and p.value in names]
            consts += [e for p in parts if isinstance(p, ast.Tuple | ast.List | ast.Set)
                       for e in p.elts if isinstance(e, ast.Constant) and e.value in names]
            if consts:
                lines.append(node.lineno)
        elif isinstance(node, ast.MatchValue) and isinstance(node.value, ast.Constant) \
                and node.value.value in names:
            lines.append(node.lineno)
    return lines


def test_only_the_transports_package_branches_on_a_transport_name():
    bad = {}
    for path in _sources("hil", skip=("hil/transports/",)):
        lines = _branches_on_backend_name(ast.parse(path.read_text()))
        if lines:
            bad[str(path.relative_to(ROOT))] = lines
    assert not bad


def test_the_check_finds_a_branch():
    tree = ast.parse("if args.transport == 'udp':\n    pass\nok = t in ('serial', 'x')\n")
    assert _branches_on_backend_name(tree) == [1, 3]


def _imports(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


def test_layers_import_only_downwards():
    allowed = {"protocols": {"protocols"},
               "firmware_model": {"firmware_model", "protocols"},
               "plant": {"plant", "firmware_model", "protocols"}}
    ours = {"protocols", "firmware_model", "plant", "hil"}
    bad = {}
    for package, ok in allowed.items():
        for path in _sources(package):
            wrong = (_imports(path) & ours) - ok
            if wrong:
                bad[str(path.relative_to(ROOT))] = sorted(wrong)
    assert not bad
