"""Every ``analyze`` command in README.md and docs/*.md names a subcommand and options that exist
(and parses as written where it has no placeholders); every Python example compiles and its
imports resolve. Running them all would install and download everything, so they are checked
rather than run (``analyze demo`` and the API example are run by test_demo.py and test_api.py)."""

import argparse
import ast
import importlib
import re
from pathlib import Path

import pytest

from haulprofile.analysis import cli

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def commands(text: str) -> list[str]:
    """``analyze …`` command lines (continuations joined, comments dropped) and inline ```analyze …```
    spans of a page; quoted messages (``analyze run: error: …``) are not commands."""
    lines, found = text.splitlines(), re.findall(r"`(analyze [^`]*)`", text)
    i = 0
    while i < len(lines):
        line = lines[i].strip().strip("`")
        match = re.search(r"(?:^|&& |\.venv/bin/)(analyze(?: [^`]*)?)$", line)
        if match:
            command = match.group(1)
            while command.endswith("\\") and i + 1 < len(lines):
                i += 1
                command = command[:-1] + " " + lines[i].strip()
            found.append(command.split(" #")[0].strip())
        i += 1
    return [c for c in dict.fromkeys(found) if not re.match(r"analyze [a-z|]+:", c)]


def python_blocks(text: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


CASES = [(page.name, command) for page in PAGES for command in commands(page.read_text())]
BLOCKS = [(page.name, n, block) for page in PAGES for n, block in enumerate(python_blocks(page.read_text()))]


def subparser(name: str) -> argparse.ArgumentParser:
    module = importlib.import_module(cli.COMMANDS[name][0])
    parser = argparse.ArgumentParser(prog=f"analyze {name}")
    module.add_arguments(parser)
    return parser


def test_the_pages_hold_commands_and_examples():
    assert len(CASES) > 10 and {c.split()[1] for _, c in CASES if len(c.split()) > 1} >= {"run", "demo", "fleet"}
    assert BLOCKS


GLOBAL_OPTIONS = {"--debug": False, "--help": False, "-h": False, "--identity": True}
"""``analyze``'s own options, before the command → whether it takes a value."""


def test_global_options_are_analyzes():
    help_text = cli.build_parser({}).format_help()
    assert set(GLOBAL_OPTIONS) <= set(re.findall(r"(?<![\w-])(--?[a-z][a-z0-9-]*)", help_text))


def without_global_options(words: list[str]) -> list[str]:
    while words and words[0].split("=")[0] in GLOBAL_OPTIONS:
        words = words[1 + (GLOBAL_OPTIONS[words[0]] if words[0] in GLOBAL_OPTIONS else 0):]
    return words


@pytest.mark.parametrize("page,command", CASES)
def test_documented_command_exists_with_its_options(page, command):
    words = without_global_options(command.replace("…", "").split()[1:])
    if not words or words[0].startswith("-"):
        known = set(re.findall(r"(?<![\w-])(--?[a-z][a-z0-9-]*)", cli.build_parser({}).format_help()))
        assert set(w for w in words if w.startswith("-")) <= known, f"{page}: {command}"
        return
    name = words[0].split("|")[0]
    assert name in cli.COMMANDS, f"{page}: {command}"
    parser = subparser(name)
    options = set(re.findall(r"(?<![\w-])(--?[a-z][a-z0-9-]*)", parser.format_help()))
    used = {w.strip("[]").split("=")[0] for w in words[1:] if w.strip("[").startswith("-")}
    assert used <= options, f"{page}: {command}: unknown {sorted(used - options)}"
    if len(words) > 1 and not re.search(r"[\[\]…|]|\b[A-Z]{3,}\b", command):
        parser.parse_args(words[1:])


@pytest.mark.parametrize("page,number,block", BLOCKS, ids=[f"{p}-{n}" for p, n, _ in BLOCKS])
def test_python_example_compiles_and_its_imports_resolve(page, number, block):
    tree = ast.parse(block)
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            module = importlib.import_module(node.module)
            for alias in node.names:
                assert hasattr(module, alias.name) or importlib.util.find_spec(f"{node.module}.{alias.name}"), \
                    f"{page}: from {node.module} import {alias.name}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                importlib.import_module(alias.name)


def test_every_analysis_name_the_api_page_uses_exists():
    from haulprofile import analysis

    text = (ROOT / "docs" / "python-api.md").read_text()
    names = set(re.findall(r"\banalysis\.([a-z_A-Z]+)\(", text))
    assert names and all(hasattr(analysis, name) for name in names), sorted(n for n in names if not hasattr(analysis, n))
