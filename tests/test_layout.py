"""The folder tree is the architecture: each layer imports only the layers below it.

The rules are read off the import graph of `hamjax/` (every `import`/`from` line,
relative imports resolved, lazy imports inside functions included), so a break
fails here before it reaches `../shared/tools/check_layers.py`.
"""

import ast
from pathlib import Path

import pytest


PACKAGE = Path(__file__).resolve().parents[1] / "hamjax"

# Each top-level part of hamjax and the parts it may import (besides itself and
# the private modules `hamjax._*`). Lower layers first.
_CORE = {"models", "simulation", "signals"}
_PROCEDURES = _CORE | {"io", "identification", "fitting", "refinement", "diagnosis"}
ALLOWED = {
    "models": set(),
    "simulation": {"models"},
    "signals": {"models", "simulation"},
    "io": _CORE,
    "identification": _CORE,
    "fitting": _CORE,
    "refinement": _CORE | {"identification", "fitting"},
    "montecarlo": _CORE | {"io"},
    "diagnosis": _CORE | {"io", "fitting", "refinement"},
    "plotting": _CORE | {"io", "identification", "diagnosis"},
    "papers": _PROCEDURES | {"montecarlo", "plotting"},
    "demo": _PROCEDURES | {"plotting", "papers"},
}


def _module(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> set[str]:
    name = _module(path)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            found.add(target)
            found |= {f"{target}.{a.name}" for a in node.names}
    return {m for m in found if m.startswith("hamjax.")}


def _part(module: str) -> str:
    return module.split(".")[1]


def _breaks() -> list[str]:
    known = {p.name for p in PACKAGE.iterdir() if p.is_dir() and p.name in ALLOWED}
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        source = _module(path)
        if source.count(".") == 0:
            continue  # hamjax/__init__.py re-exports the public API
        part = _part(source)
        for target in _imports(path):
            other = _part(target)
            if other == part or other.startswith("_") or other not in known | {"cli"}:
                continue
            if other == "cli" and part not in {"cli", "__main__"}:
                out.append(f"{source} imports {target}: nothing outside cli/ does")
            elif part in ALLOWED and other not in ALLOWED[part]:
                out.append(f"{source} imports {target}: {part} sits below {other}")
    return out


def test_every_import_goes_down_the_layers():
    assert _breaks() == []


def test_every_part_of_the_package_has_a_layer():
    parts = {p.name for p in PACKAGE.iterdir() if p.is_dir() and p.name[0] != "_"}
    assert parts - {"__pycache__"} == set(ALLOWED) | {"cli"}


@pytest.mark.parametrize(
    "label, path",
    [
        ("Table 1", "identification/seed000/nbbi_table1.py"),
        ("Table 2", "identification/seed000/fgi_table2.py"),
        ("(4.1", "identification/seed001/normalised_gradient_4_1.py"),
        ("(5.1)", "signals/impulse_pe.py"),
        ("V.C", "papers/seed001/section_vc.py"),
    ],
)
def test_a_newcomer_finds_the_paper_by_file_name(label, path):
    # The file named after the paper's label exists and its docstring cites it.
    module = PACKAGE / path
    assert module.is_file(), f"{label} should be {path}"
    assert label in ast.get_docstring(ast.parse(module.read_text()))
