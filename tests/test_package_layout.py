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


NUMBA_COMPILERS = {"njit", "jit", "vectorize", "guvectorize", "cfunc", "generated_jit"}


def _uncached_kernels(path: Path) -> list[str]:
    """``file:line`` of every numba compiler use in ``path`` without ``cache=True``: a bare
    ``@njit`` / ``@numba.njit``, or a call (decorator, ``numba.njit(...)(f)``, ``jit = numba.njit(...)``)
    that does not pass ``cache=True``."""
    found = []
    tree = ast.parse(path.read_text())
    calls = {id(node.func) for node in ast.walk(tree) if isinstance(node, ast.Call)}
    imported = {alias.asname or alias.name for node in ast.walk(tree)
                if isinstance(node, ast.ImportFrom) and node.module == "numba" for alias in node.names}

    def compiler_name(node) -> str | None:
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "numba":
            return node.attr if node.attr in NUMBA_COMPILERS else None
        if isinstance(node, ast.Name) and node.id in NUMBA_COMPILERS and node.id in imported:
            return node.id
        return None

    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and compiler_name(node.func):
            cached = any(k.arg == "cache" and isinstance(k.value, ast.Constant) and k.value.value is True
                         for k in node.keywords)
            if not cached:
                found.append(f"{path.name}:{node.lineno}")
        elif compiler_name(node) and id(node) not in calls:
            decorated = any(node in getattr(d, "decorator_list", ()) for d in ast.walk(tree))
            if decorated:
                found.append(f"{path.name}:{node.lineno}")
    return found


def test_every_numba_kernel_is_cached():
    """A second ``analyze demo`` compiles nothing: every kernel of the package is compiled with
    ``cache=True`` (numba keeps the machine code beside the source; without it each process
    compiles again, about a minute for the whole pipeline)."""
    uncached = [where for path in modules().values() for where in _uncached_kernels(path)]
    assert not uncached, f"numba kernels without cache=True: {uncached}"


def test_the_kernel_scan_finds_an_uncached_kernel(tmp_path):
    source = tmp_path / "kernels.py"
    source.write_text("import numba\nfrom numba import njit\n\n@numba.njit\ndef a(x):\n    return x\n\n"
                      "b = numba.njit(nogil=True)(a)\n\n@numba.njit(cache=True)\ndef c(x):\n    return x\n\n"
                      "@njit\ndef d(x):\n    return x\n\njit = numba.njit(cache=True)\ne = jit(d)\n")
    assert sorted(_uncached_kernels(source)) == ["kernels.py:14", "kernels.py:4", "kernels.py:8"]
