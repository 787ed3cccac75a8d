"""Rules of the layout, checked on the source: only hil/transports/ knows a transport by
name; the firmware models do not import the plant or the harness; the plant does not import
the harness; inside the harness, each room (folder of hil/) has one rule naming the rooms it
may import, nothing outside the command line imports it and the engines import nothing of
the verification; the harness holds no model arithmetic of a hardware part."""

from __future__ import annotations

import ast
import functools
import importlib
import re
import shutil
from pathlib import Path

from hil.transports import BACKENDS

ROOT = Path(__file__).resolve().parents[2]


@functools.cache
def _parse(source: str) -> ast.Module:
    """The tree of a source text, parsed once for all the checks here (each walks every
    module of hil/, and the planted copy repeats most of them: parsing was most of their
    time). The trees are only read."""
    return ast.parse(source)


@functools.cache
def _nodes(tree: ast.AST) -> tuple[ast.AST, ...]:
    """Every node of ``tree`` in ``ast.walk``'s order, listed once: several checks walk
    each module's whole tree, and walking (not parsing) was most of this file's time."""
    return tuple(ast.walk(tree))


def _sources(package: str, skip: tuple[str, ...] = ()) -> list[Path]:
    return [p for p in sorted((ROOT / package).rglob("*.py"))
            if not any(str(p.relative_to(ROOT)).startswith(s) for s in skip)]


def _branches_on_backend_name(tree: ast.AST) -> list[int]:
    """Lines comparing something with a backend's name (==, !=, in, match case)."""
    names = set(BACKENDS)
    lines = []
    for node in _nodes(tree):
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
        lines = _branches_on_backend_name(_parse(path.read_text()))
        if lines:
            bad[str(path.relative_to(ROOT))] = lines
    assert not bad


def test_the_check_finds_a_branch():
    tree = ast.parse("if args.transport == 'udp':\n    pass\nok = t in ('serial', 'x')\n")
    assert _branches_on_backend_name(tree) == [1, 3]


def _imports(path: Path) -> set[str]:
    names = set()
    for node in _nodes(_parse(path.read_text())):
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


# --- the rooms of hil/ -------------------------------------------------------------------------
#: One rule per room (folder) of hil/: the other rooms its modules may import. Read from the
#: bottom: transports and analysis stand alone; the engines (sim) and the fieldbus they run on
#: are one layer; logs, replay, identification, scenarios, sweeps, verification and benchmarks
#: sit on them; the command line (cli) sits on everything and nothing imports it.
ROOMS: dict[str, set[str]] = {
    "transports": set(),
    "workers": set(),
    "analysis": set(),
    "output": {"analysis"},
    "framelog": {"output"},
    "sim": {"fieldbus"},
    "fieldbus": {"sim", "transports"},
    "replay": {"fieldbus", "framelog", "sim"},
    "identify": {"analysis", "output", "workers"},
    "scenarios": {"analysis", "fieldbus", "identify", "output", "sim"},
    "sweep": {"output", "scenarios", "workers"},
    "verify": {"sim"},
    "bench": {"fieldbus", "framelog", "identify", "replay", "sim", "sweep", "transports"},
    "cli": {"analysis", "bench", "fieldbus", "framelog", "identify", "output", "replay",
            "scenarios", "sim", "sweep", "transports", "verify"},
}
#: Modules that may import more than their room's rule, each with its reason.
ROOM_EXCEPTIONS = {
    ("hil/sim/warmup.py", "replay"): "compiles every kernel once: the FPGA replay's",
    ("hil/sim/warmup.py", "identify"): "compiles every kernel once: the fitted model's",
    ("hil/sim/warmup.py", "framelog"): "compiles every kernel once: the log's byte planes",
}


def _room(module: str) -> str | None:
    """The room of a dotted module of hil (``hil.sim.robot`` -> ``sim``), None outside."""
    parts = module.split(".")
    return parts[1] if parts[0] == "hil" and len(parts) > 1 else None


def hil_imports(root: Path) -> dict[str, set[str]]:
    """Every module of ``root/hil`` (path relative to ``root``) -> the hil modules it
    imports, at any depth of the file (deferred imports inside functions count too)."""
    graph = {}
    for path in sorted((root / "hil").rglob("*.py")):
        names = set()
        for node in _nodes(_parse(path.read_text())):
            if isinstance(node, ast.Import):
                names.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module == "hil":
                names.update(f"hil.{a.name}" for a in node.names)  # from hil import sim
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names.add(node.module)
        graph[path.relative_to(root).as_posix()] = {n for n in names if n.startswith("hil.")}
    return graph


def room_violations(graph: dict[str, set[str]], rooms: dict[str, set[str]] = ROOMS,
                    exceptions: dict = ROOM_EXCEPTIONS) -> list[str]:
    """What breaks the rooms' rules in an import graph (path -> dotted hil modules)."""
    bad = []
    for path, names in sorted(graph.items()):
        parts = path.split("/")
        if len(parts) == 2:
            if parts[1] != "__init__.py":
                bad.append(f"{path}: a loose module at the top of hil/ (put it in a room)")
            continue
        mine = parts[1]
        if mine not in rooms:
            bad.append(f"{path}: room hil/{mine}/ has no rule in ROOMS")
            continue
        for name in sorted(names):
            other = _room(name)
            if other is None or other == mine:
                continue
            if other == "cli":
                bad.append(f"{path} imports {name}: nothing outside hil/cli/ imports it")
            elif other not in rooms[mine] and (path, other) not in exceptions:
                bad.append(f"{path} imports {name}: hil/{mine}/ may import only "
                           f"{sorted(rooms[mine])}")
    return bad


def test_every_room_keeps_its_rule():
    assert room_violations(hil_imports(ROOT)) == []


def test_every_rule_and_exception_is_needed():
    graph = hil_imports(ROOT)
    used = {(p, _room(n)) for p, names in graph.items() for n in names}
    rooms_used = {(p.split("/")[1], r) for p, r in used}
    unused = {(room, other) for room, others in ROOMS.items() for other in others
              if (room, other) not in rooms_used}
    assert not unused, f"rules allowing what nobody imports: {sorted(unused)}"
    assert set(ROOM_EXCEPTIONS) <= used, set(ROOM_EXCEPTIONS) - used


def test_the_engines_import_nothing_of_the_verification():
    assert "verify" not in ROOMS["sim"] and "verify" not in ROOMS["fieldbus"]
    graph = {"hil/sim/robot.py": {"hil.verify.mcu.model"}}
    assert room_violations(graph) == [
        "hil/sim/robot.py imports hil.verify.mcu.model: hil/sim/ may import only "
        "['fieldbus']"]


def test_the_rules_catch_violations_planted_in_a_copy(tmp_path):
    """A copy of hil/ with three planted mistakes: an engine importing the verification,
    a room importing the command line, a loose module at the top; each is reported."""
    shutil.copytree(ROOT / "hil", tmp_path / "hil",
                    ignore=shutil.ignore_patterns("__pycache__", "*.v", "*.toml"))
    assert room_violations(hil_imports(tmp_path)) == []
    sched = tmp_path / "hil" / "sim" / "scheduler.py"
    sched.write_text(sched.read_text() + "\nfrom hil.verify.compare import compare\n")
    sweep = tmp_path / "hil" / "sweep" / "engine.py"
    sweep.write_text(sweep.read_text() + "\ndef f():\n    from hil.cli import args\n")
    (tmp_path / "hil" / "helpers.py").write_text("X = 1\n")
    (tmp_path / "hil" / "newroom").mkdir()
    (tmp_path / "hil" / "newroom" / "a.py").write_text("import hil.sim.robot\n")
    bad = room_violations(hil_imports(tmp_path))
    assert bad == [
        "hil/helpers.py: a loose module at the top of hil/ (put it in a room)",
        "hil/newroom/a.py: room hil/newroom/ has no rule in ROOMS",
        "hil/sim/scheduler.py imports hil.verify.compare: hil/sim/ may import only "
        "['fieldbus']",
        "hil/sweep/engine.py imports hil.cli: nothing outside hil/cli/ imports it",
    ]


# --- the harness holds no model of a hardware part --------------------------------------------
#: The packages that hold the hardware parts' models and codecs.
PARTS = ("protocols", "firmware_model", "plant")
#: Names of indices and sizes (wiring: where a word or a value sits, how many there are),
#: as opposed to a part's scales, offsets, masks and Q-format shifts.
_INDEX = re.compile(r"^((FIRST_)?N|U|R|D|F|C|K|P|S|Y|IN|LK|TRACE|ST|STATE|CTRL|RING)_"
                    r"|_(WORDS|W|WIDTH|BITS|BYTES|BASE)$")
_ARITHMETIC = (ast.Add, ast.Sub, ast.Mult, ast.Div, ast.FloorDiv, ast.Mod, ast.Pow,
               ast.LShift, ast.RShift, ast.BitAnd, ast.BitOr, ast.BitXor)
_KERNEL_DECORATORS = {"njit", "jit", "vectorize", "guvectorize", "cfunc", "stencil"}

#: hil/ modules that may do what the rule forbids, each with its reason.
ALLOWED = {
    ("hil/sim/actuator.py", "kernel"):
        "the stack's compiled wiring loop: calls the parts' kernels tick by tick",
    ("hil/sim/robot.py", "kernel"):
        "the whole robot's compiled wiring loop: calls the stack's and the MCU law's compiled "
        "steps per actuator, and copies process-data bytes",
    ("hil/sim/robot.py", "plant.lanes.LW"):
        "the lane width: how many actuators one batch of the vector lanes holds (a size)",
    ("hil/sim/robot.py", "plant.lanes.YO"):
        "where the plant outputs' rows start in a lane buffer (an offset, for the tap's copy)",
    ("hil/replay/signal_kernel.py", "kernel"):
        "a log's decoded signals (hil.replay.signals' numpy reference, same operations) "
        "compiled per block and encoded into their records: the log decoder's conversions, "
        "no part's model",
    ("hil/replay/signal_records.py", "kernel"):
        "the boxes' records decoded and encoded into their log messages (hil.replay."
        "signals' numpy reference, same operations) compiled per block: the log's "
        "conversions, no part's model",
    ("hil/sim/actuator.py", "plant.lanes.LW"):
        "the lane width: a row's stride in the plant lanes the inverter writes (a size)",
    ("hil/sim/compute_threads.py", "kernel"):
        "the engine's helper threads waiting for a cycle and calling the robot kernel "
        "without the interpreter lock (a futex and counters, no part's arithmetic)",
    ("hil/bench/robot_stages.py", "kernel"):
        "times each stage of the robot engine alone: calls the parts' compiled steps in a "
        "loop, computes nothing of its own",
    ("hil/fieldbus/pdo_compiled.py", "kernel"):
        "the process data's conversions (hil.fieldbus.pdo's, same steps) compiled for the "
        "per-cycle path: counts and little-endian bytes, no part's arithmetic",
    ("hil/sim/pc.py", "kernel"):
        "the demo PC loop's stimulus (a force sine per actuator) compiled for the per-cycle "
        "path: a test signal, not the PC's joint loop (firmware_model/pc)",
    ("hil/fieldbus/hip_box.py", "kernel"):
        "the hip box's compiled wiring loop: both stacks and the thigh's coupling tick by tick",
    ("hil/fieldbus/esc/frames.py", "kernel"):
        "the EtherCAT frame loop: receives and sends through the C library, without the "
        "interpreter lock, and passes each frame to the ESC model's compiled frame path",
    ("hil/replay/fpga_replay.py", "kernel"):
        "feeds logged words through the board's compiled tick and compares its outputs",
    ("hil/framelog/heads.py", "kernel"):
        "a log batch's MCAP record heads and index entries written in one compiled pass: "
        "bytes moved, no part's arithmetic",
    ("hil/framelog/planes.py", "kernel"):
        "a log's raw blocks split into byte planes (and frame-to-frame differences) in one "
        "compiled pass: bytes moved, no part's arithmetic",
    ("hil/identify/model.py", "kernel"):
        "identification: the reduced model fitted to measured data, not the plant's parts",
    ("hil/identify/tangent.py", "kernel"):
        "identification: the reduced model's tangent-linear simulation (its derivatives in "
        "the fitted parameters), not the plant's parts",
    ("hil/identify/linear_columns.py", "kernel"):
        "identification: the reduced linear model's Jacobian columns by the recursion of "
        "their states' differences, not the plant's parts",
    ("hil/identify/rig.py", "kernel"):
        "identification: the independent generator of rig data, which must differ from "
        "the plant's model (DESIGN.md, data formats)",
    ("hil/bench/identify_batch.py", "kernel"):
        "a probe: the identification model's kernel (hil.identify.model) with a lane index, "
        "timed and compared bit for bit against single calls; no part's model",
}


def _numeric(module: str, name: str) -> bool:
    try:
        value = getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError):
        return False
    return type(value) in (int, float)


def _part_names(tree: ast.AST) -> tuple[dict[str, str], dict[str, str]]:
    """(numeric constants, modules) imported from the parts' packages: local name -> full."""
    consts, modules = {}, {}
    for node in _nodes(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0 \
                and node.module.split(".")[0] in PARTS:
            for a in node.names:
                full = f"{node.module}.{a.name}"
                try:
                    importlib.import_module(full)
                    modules[a.asname or a.name] = full
                except ImportError:
                    if _numeric(node.module, a.name) and not _INDEX.search(a.name):
                        consts[a.asname or a.name] = full
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] in PARTS:
                    modules[a.asname or a.name] = a.name
    return consts, modules


def part_arithmetic(source: str) -> list[tuple[int, str]]:
    """(line, what) of every numba kernel defined in ``source``, and of every arithmetic or
    bit operation with a numeric constant of a part's module (a scale, an offset, a mask,
    a code's mid-scale: not an index or a size) as an operand."""
    tree = _parse(source)
    consts, modules = _part_names(tree)
    found = []
    for node in _nodes(tree):
        if isinstance(node, ast.FunctionDef):
            for d in node.decorator_list:
                f = d.func if isinstance(d, ast.Call) else d
                if (f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")) \
                        in _KERNEL_DECORATORS:
                    found.append((node.lineno, "kernel"))
        elif isinstance(node, ast.BinOp) and isinstance(node.op, _ARITHMETIC):
            for side in (node.left, node.right):
                if isinstance(side, ast.Name) and side.id in consts:
                    found.append((node.lineno, consts[side.id]))
                elif isinstance(side, ast.Attribute) and isinstance(side.value, ast.Name) \
                        and side.value.id in modules and not _INDEX.search(side.attr) \
                        and _numeric(modules[side.value.id], side.attr):
                    found.append((node.lineno, f"{modules[side.value.id]}.{side.attr}"))
    return found


def test_the_harness_holds_no_model_arithmetic_of_a_part():
    bad, used = {}, set()
    for path in _sources("hil"):
        rel = str(path.relative_to(ROOT))
        for line, what in part_arithmetic(path.read_text()):
            if (rel, what) in ALLOWED:
                used.add((rel, what))
            else:
                bad.setdefault(rel, []).append((line, what))
    assert not bad, bad
    assert used == set(ALLOWED), f"exceptions no longer needed: {set(ALLOWED) - used}"


def test_the_arithmetic_check_finds_a_parts_scale_and_a_kernel():
    snippet = (
        "from numba import njit\n"
        "from protocols.ad7195 import MIDSCALE\n"
        "from protocols import biss\n"
        "from firmware_model.fpga import layout as B\n"
        "@njit(cache=True)\n"
        "def decode(code):\n"
        "    return code - MIDSCALE\n"
        "x = count * biss.LINEAR_COUNT_M\n"
        "y = up[B.U_IQ] + B.N_RAW\n"   # an index and a size: wiring, not a model
    )
    assert sorted(part_arithmetic(snippet)) == [(6, "kernel"), (7, "protocols.ad7195.MIDSCALE"),
                                                 (8, "protocols.biss.LINEAR_COUNT_M")]
