"""Stage results kept between runs of ``analyze run``, so a rerun reruns only what changed.

A stage's key hashes the key of the stage before it, the stage's name, its option tables, and (where
`pipeline.DEPENDS_ON` says it reads them) the vehicle file and the DEM tiles' names and sizes; the
first key hashes the inputs (path, size, modification time) and the package version. A stage whose
key matches what is stored is not run: the signals table and summary after it are loaded instead.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from dataclasses import asdict
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import pandas as pd


def _package_version() -> str:
    try:
        return version("haulprofile")
    except PackageNotFoundError:
        return "unknown"


def _files_fingerprint(paths: list[Path]) -> list:
    entries = []
    for path in paths:
        files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
        entries.extend((str(f), f.stat().st_size, f.stat().st_mtime_ns) for f in files)
    return entries


class StageCache:
    """Keys, saves and restores the state after each stage under ``out_dir/.cache``."""

    def __init__(self, ctx):
        from .pipeline import DEPENDS_ON, jsonable

        self.ctx = ctx
        self.directory = ctx.out_dir / ".cache"
        self._depends_on = DEPENDS_ON
        self._jsonable = jsonable
        self._keys: dict[str, str] = {}
        self._base = self._hash(["inputs", _files_fingerprint(ctx.inputs), _package_version()])

    def _hash(self, parts) -> str:
        text = json.dumps(parts, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:20]

    def key(self, names: list[str], index: int) -> str:
        previous = self._base if index == 0 else self._keys[names[index - 1]]
        name = names[index]
        needs = self._depends_on.get(name, {})
        parts = [previous, name, {k: self.ctx.options.get(k) for k in needs.get("options", ())},
                 self.ctx.figures]
        if needs.get("vehicle") and self.ctx.vehicle is not None:
            parts.append(asdict(self.ctx.vehicle))
        if needs.get("dem") and self.ctx.dem_dir is not None:
            parts.append(_files_fingerprint([Path(self.ctx.dem_dir)]))
        self._keys[name] = self._hash(parts)
        return self._keys[name]

    def restore(self, names: list[str]) -> int:
        """Load the state after the longest run of unchanged stages; return how many to skip."""
        matched = 0
        for index, name in enumerate(names):
            key = self.key(names, index)
            stored = self.directory / name / "key"
            if matched == index and stored.is_file() and stored.read_text() == key:
                matched = index + 1
        if matched:
            last = self.directory / names[matched - 1]
            self.ctx.signals = pd.read_parquet(last / "signals.parquet")
            self.ctx.summary.update(json.loads((last / "summary.json").read_text()))
        return matched

    def save(self, name: str) -> None:
        target = self.directory / name
        if target.exists():
            shutil.rmtree(target)
        target.mkdir(parents=True)
        self.ctx.signals.to_parquet(target / "signals.parquet", index=False)
        (target / "summary.json").write_text(json.dumps(self.ctx.summary, default=self._jsonable))
        (target / "key").write_text(self._keys[name])
