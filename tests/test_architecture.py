"""The package's import graph against docs/architecture.md: no cycles, no upward imports, every unit placed.

Every ``import`` / ``from ... import`` of every module under workflow/redsup is read with `ast` (module level,
inside functions and under ``if TYPE_CHECKING``); dynamic imports (``importlib``) are not seen. The layer table
and the forbidden pairs are parsed from docs/architecture.md, the one place they are written.

``python tests/test_architecture.py`` prints the imports between units, each with its layers.
"""
from __future__ import annotations

import ast
import re
import sys
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "workflow" / "redsup"
DOC = ROOT / "docs" / "architecture.md"

# Module-level edges (importer, imported) the rules let through for now, each with why. An entry the code no
# longer has fails test_known_exceptions_are_still_needed: delete it then.
KNOWN_EXCEPTIONS: dict[tuple[str, str], str] = {}  # (importer, imported): why it is allowed for now


# ------------------------------------------------------------------------------------------ the graph
def modules_of(package: Path) -> dict[str, Path]:
    """Dotted name -> file of every module of the package (a package's ``__init__`` is the package's name)."""
    out = {}
    for path in sorted(package.rglob("*.py")):
        parts = list(path.relative_to(package.parent).with_suffix("").parts)
        if "__pycache__" in parts:
            continue
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _resolve(name: str, modules: dict[str, Path]) -> str | None:
    """The module a dotted name lives in: the longest prefix that is a module, None outside the package."""
    parts = name.split(".")
    while parts:
        if ".".join(parts) in modules:
            return ".".join(parts)
        parts.pop()
    return None


def import_edges(package: Path) -> dict[tuple[str, str], list[int]]:
    """(importer, imported module) -> the importer's line numbers, over every import statement anywhere in
    each module; ``from a import b`` imports module ``a.b`` when b is a module, else ``a``."""
    modules = modules_of(package)
    root = package.name
    edges: dict[tuple[str, str], list[int]] = defaultdict(list)
    for name, path in modules.items():
        here = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = here.split(".")[:len(here.split(".")) - (node.level - 1)]
                    source = ".".join(base + ([node.module] if node.module else []))
                else:
                    source = node.module or ""
                targets = [f"{source}.{a.name}" if f"{source}.{a.name}" in modules else source for a in node.names]
            for target in targets:
                if target != root and not target.startswith(root + "."):
                    continue
                module = _resolve(target, modules)
                if module is not None and module != name and node.lineno not in edges[(name, module)]:
                    edges[(name, module)].append(node.lineno)
    return dict(edges)


def unit(module: str) -> str:
    """A top-level module or a subpackage (its ``__init__`` and every module below it): ``redsup.calib.plan`` ->
    ``calib``, ``redsup.config`` -> ``config``; the root package itself is ``""``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def cycles(edges) -> list[list[str]]:
    """Strongly connected components with more than one node (Tarjan, iterative)."""
    graph: dict[str, set[str]] = defaultdict(set)
    for a, b in edges:
        graph[a].add(b)
        graph.setdefault(b, set())
    index, low, on_stack, stack, out = {}, {}, set(), [], []
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    out.append(sorted(component))
    return out


# ------------------------------------------------------------------------------------------ the doc
def _section(text: str, heading: str) -> list[str]:
    lines = text.splitlines()
    start = lines.index(heading) + 1
    end = next((i for i in range(start, len(lines)) if lines[i].startswith("## ")), len(lines))
    return lines[start:end]


def layer_table(text: str) -> dict[str, list[str]]:
    """Layer number -> units, from the rows ``| <n> ... | `unit`, `unit` ... | what lives there |`` of the section
    ``## Layers`` (a unit: a backquoted name in the second column)."""
    out: dict[str, list[str]] = {}
    for line in _section(text, "## Layers"):
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("|") and len(cells) >= 3 and re.match(r"\d+\b", cells[0]):
            out[cells[0].split()[0]] = re.findall(r"`([A-Za-z_][A-Za-z0-9_]*)`", cells[1])
    return out


def forbidden_pairs(text: str) -> dict[tuple[str, str], str]:
    """(importer unit, imported unit) -> why, from the rows ``| `a` | `b` | why |`` of ``## Forbidden imports``."""
    out = {}
    for line in _section(text, "## Forbidden imports"):
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        names = [re.fullmatch(r"`([A-Za-z_][A-Za-z0-9_]*)`", c) for c in cells[:2]]
        if line.startswith("|") and len(cells) >= 3 and all(names):
            out[(names[0].group(1), names[1].group(1))] = cells[2]
    return out


def layers_of(table: dict[str, list[str]]) -> dict[str, int]:
    return {u: int(n) for n, units in table.items() for u in units}


def violations(edges, layer: dict[str, int], forbidden=(), exceptions=()) -> list[str]:
    """'importer:line imports module (unit layer a < b)' for every import of a unit from a higher layer or of a
    forbidden pair, except the module edges in ``exceptions``."""
    out = []
    for (a, b), lines in sorted(edges.items()):
        ua, ub = unit(a), unit(b)
        if ua == ub or "" in (ua, ub) or (a, b) in exceptions:
            continue
        where = f"{a}:{','.join(map(str, lines))} imports {b}"
        if ua in layer and ub in layer and layer[ub] > layer[ua]:
            out.append(f"{where} (upward: {ua} is in layer {layer[ua]}, {ub} in layer {layer[ub]})")
        if (ua, ub) in forbidden:
            out.append(f"{where} (forbidden {ua} -> {ub}: {forbidden[(ua, ub)]})")
    return out


# ------------------------------------------------------------------------------------------ the package
@pytest.fixture(scope="module")
def edges():
    return import_edges(PACKAGE)


@pytest.fixture(scope="module")
def doc():
    return DOC.read_text()


def test_every_unit_has_exactly_one_layer(doc):
    table = layer_table(doc)
    assert table, "docs/architecture.md has no layer rows under '## Layers'"
    placed = [u for units in table.values() for u in units]
    twice = sorted({u for u in placed if placed.count(u) > 1})
    units = {unit(m) for m in modules_of(PACKAGE)} - {""}
    assert not twice, f"units in more than one layer of docs/architecture.md: {twice}"
    assert not units - set(placed), (f"units without a layer: {sorted(units - set(placed))}; add each to the layer "
                                      f"table of docs/architecture.md (the layer of what it imports or above)")
    assert not set(placed) - units, f"the layer table names units the package does not have: {sorted(set(placed) - units)}"


def test_the_root_package_imports_nothing_of_its_own(edges):
    assert [b for a, b in edges if a == "redsup"] == []


def test_no_import_cycle_between_modules(edges):
    found = cycles(edges)
    assert not found, "import cycles between modules:\n" + "\n".join(
        " <-> ".join(c) + "\n  " + "; ".join(f"{a} -> {b} (line {edges[(a, b)][0]})"
                                            for a in c for b in c if (a, b) in edges) for c in found)


def test_no_import_cycle_between_units(edges):
    unit_edges = defaultdict(list)
    for (a, b), lines in edges.items():
        if unit(a) != unit(b) and "" not in (unit(a), unit(b)):
            unit_edges[(unit(a), unit(b))].append(f"{a}:{lines[0]} -> {b}")
    found = cycles(unit_edges)
    assert not found, "import cycles between units:\n" + "\n".join(
        " <-> ".join(c) + "\n  " + "; ".join(unit_edges[(a, b)][0] for a in c for b in c if (a, b) in unit_edges)
        for c in found)


def test_no_import_from_a_higher_layer_or_of_a_forbidden_pair(edges, doc):
    bad = violations(edges, layers_of(layer_table(doc)), forbidden_pairs(doc), KNOWN_EXCEPTIONS)
    assert not bad, "imports against docs/architecture.md:\n" + "\n".join(bad)


def test_known_exceptions_are_still_needed(edges, doc):
    layer, forbidden = layers_of(layer_table(doc)), forbidden_pairs(doc)
    for edge in KNOWN_EXCEPTIONS:
        assert edge in edges and violations({edge: edges[edge]}, layer, forbidden), (
            f"{edge[0]} no longer imports {edge[1]} against the rules: delete it from KNOWN_EXCEPTIONS")


def test_rules_files_do_not_change_names_at_include_time():
    """A rules file defines its own names; it never appends to or reassigns one another file defined (the
    figure ids of rule all are data: common.smk's from tables.yaml, depth.smk's Galteland figures)."""
    mutation = re.compile(r"^([A-Z][A-Z0-9_]*)(\.(append|extend|insert|update|setdefault|pop|remove|clear)\(|"
                          r"\s*(\+=|\|=|-=)|\[.*\]\s*=[^=])")
    files = sorted((ROOT / "workflow" / "rules").glob("*.smk")) + [ROOT / "Snakefile"]
    bad = [f"{path.relative_to(ROOT)}:{i}: {line.strip()}" for path in files
           for i, line in enumerate(path.read_text().splitlines(), 1) if mutation.match(line)]
    assert not bad, "rules files changing a name at include time:\n" + "\n".join(bad)


# ------------------------------------------------------------------------------------------ the checker itself
def _package(tmp_path: Path, files: dict[str, str]) -> Path:
    package = tmp_path / "redsup"
    for name, text in {"__init__.py": "", **files}.items():
        (package / name).parent.mkdir(parents=True, exist_ok=True)
        (package / name).write_text(text)
    return package


def test_the_checks_find_an_upward_import_inside_a_function_and_cycles(tmp_path):
    package = _package(tmp_path, {
        "base.py": "def f():\n    from redsup.top import g\n",
        "top.py": "from redsup import base\nfrom redsup.stage import a\ndef g():\n    pass\n",
        "stage/__init__.py": "",
        "stage/a.py": "from redsup.stage.b import x\n",
        "stage/b.py": "from . import a\nx = 1\n",
        "other/__init__.py": "import redsup.stage.a\n",
    })
    edges = import_edges(package)
    assert set(edges) == {("redsup.base", "redsup.top"), ("redsup.top", "redsup.base"), ("redsup.top", "redsup.stage.a"),
                          ("redsup.stage.a", "redsup.stage.b"), ("redsup.stage.b", "redsup.stage.a"),
                          ("redsup.other", "redsup.stage.a")}
    assert sorted(cycles(edges)) == [["redsup.base", "redsup.top"], ["redsup.stage.a", "redsup.stage.b"]]
    doc = ("## Layers\n\n| Layer | Units | What |\n|---|---|---|\n| 1 base | `base` | x |\n| 2 | `stage`, `other` | y |\n"
           "| 3 top | `top` | z |\n\n## Forbidden imports\n\n| From | To | Why |\n|---|---|---|\n"
           "| `other` | `stage` | no |\n")
    layer, forbidden = layers_of(layer_table(doc)), forbidden_pairs(doc)
    assert layer == {"base": 1, "stage": 2, "other": 2, "top": 3} and forbidden == {("other", "stage"): "no"}
    bad = violations(edges, layer, forbidden)
    assert len(bad) == 2 and bad[0].startswith("redsup.base:2 imports redsup.top (upward")
    assert bad[1].startswith("redsup.other:1 imports redsup.stage.a (forbidden")
    assert violations(edges, layer, forbidden, {("redsup.base", "redsup.top"), ("redsup.other", "redsup.stage.a")}) == []


if __name__ == "__main__":
    found = import_edges(PACKAGE)
    where = layers_of(layer_table(DOC.read_text()))
    pairs = sorted({(unit(a), unit(b)) for a, b in found if unit(a) != unit(b) and "" not in (unit(a), unit(b))},
                   key=lambda p: (-where.get(p[0], 99), p))
    for ua, ub in pairs:
        print(f"{ua} ({where.get(ua, '?')}) -> {ub} ({where.get(ub, '?')})", file=sys.stdout)
