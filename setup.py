"""The two programs keep the design's folders (`logger/`, `analysis/`) and install under the one
name `haulprofile`: each folder below them that is a package becomes `haulprofile.<folder>.<…>`,
the contract (`logger/contract/`) `haulprofile.contract` and the harness (`analysis/testing/`)
`haulprofile.testing`, so a new stage folder needs no line here."""

from pathlib import Path

from setuptools import setup

ROOTS = {"haulprofile.logger": "logger", "haulprofile.contract": "logger/contract",
         "haulprofile.analysis": "analysis", "haulprofile.testing": "analysis/testing"}


def packages() -> list[str]:
    """Every package below the folders, named after the most specific folder it lies in."""
    names = []
    found = sorted({init.parent for folder in ROOTS.values() for init in Path(folder).rglob("__init__.py")})
    for directory in found:
        name, folder = max(((n, f) for n, f in ROOTS.items() if directory.is_relative_to(f)), key=lambda nf: len(nf[1]))
        names.append(".".join((name, *directory.relative_to(folder).parts)))
    return names


setup(packages=packages(), package_dir=ROOTS)
