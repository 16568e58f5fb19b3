"""The import graph of the package: no circle, and the arrows docs/architecture.md promises."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = {"haulprofile.logger": ROOT / "logger", "haulprofile.contract": ROOT / "logger" / "contract",
           "haulprofile.analysis": ROOT / "analysis", "haulprofile.testing": ROOT / "analysis" / "testing"}
"""The design's folders and the installed names they map to (setup.py)."""


def modules() -> dict[str, Path]:
    found = {}
    for name, folder in FOLDERS.items():
        inner = [f for f in FOLDERS.values() if f != folder and f.is_relative_to(folder)]
        for path in folder.rglob("*.py"):
            if any(path.is_relative_to(f) for f in inner):
                continue
            parts = [name, *path.relative_to(folder).with_suffix("").parts]
            if parts[-1] == "__init__":
                parts = parts[:-1]
            found[".".join(parts)] = path
    return found


def imports_of(name: str, path: Path, known: dict[str, Path]) -> set[str]:
    """Modules of the package that ``name`` imports anywhere in its text (lazy imports too)."""
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            prefix = ".".join(base + ([node.module] if node.module else []))
            targets = [f"{prefix}.{alias.name}" if f"{prefix}.{alias.name}" in known else prefix
                       for alias in node.names]
        else:
            continue
        found |= {t for t in targets if t in known and t != name}
    return found


GRAPH = {name: imports_of(name, path, modules()) for name, path in modules().items()}


def test_no_module_imports_itself_round_a_circle():
    seen, on_path, circles = set(), [], []

    def visit(name):
        on_path.append(name)
        for target in sorted(GRAPH[name]):
            if target in on_path:
                circles.append(on_path[on_path.index(target):] + [target])
            elif target not in seen:
                visit(target)
        on_path.pop()
        seen.add(name)

    for name in sorted(GRAPH):
        if name not in seen:
            visit(name)
    assert circles == []


@pytest.mark.parametrize("side", ["haulprofile.analysis", "haulprofile.contract"])
def test_the_analysis_and_the_contract_never_import_the_daemon(side):
    allowed = {"haulprofile.analysis.commands.demo"}
    arrows = [(name, target) for name, targets in GRAPH.items() if name.startswith(side) and name not in allowed
              for target in targets if target.startswith("haulprofile.logger")]
    assert arrows == []


def test_shipped_code_never_imports_the_test_data_generators():
    arrows = [(name, target) for name, targets in GRAPH.items() if not name.startswith("haulprofile.testing")
              for target in targets if target.startswith("haulprofile.testing")]
    assert arrows == []
