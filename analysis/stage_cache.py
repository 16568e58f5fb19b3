"""Stage results kept between runs of ``analyze run``, so a rerun reruns only what changed.

A stage's key hashes the key of the stage before it, the stage's name, its options, and (where the
stage says it reads them) the vehicle and the DEM tiles' bytes; the first key hashes the bytes of
every input file and the package version. The key is of content, never of size and modification
time: a log replaced by another of the same size and time stamp is read again. A stage whose key
matches what is stored is not run: the signals table, summary and results after it are loaded
instead (a pickle the run itself wrote into ``out_dir/.cache``), and the output step copies the
files it kept for that stage (``.cache/<stage>/files``) rather than drawing them again.
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import shutil
from dataclasses import asdict, is_dataclass
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import pandas as pd

from haulprofile.contract.input_files import refuse_special
from haulprofile.contract.private_files import make_dirs, restrict_tree

from .errors import UserError
from .jsonable import jsonable

HASH_BLOCK_BYTES = 1 << 20


def _package_version() -> str:
    try:
        return version("haulprofile")
    except PackageNotFoundError:
        return "unknown"


def content_hash(paths: list[Path]) -> list[tuple[str, str]]:
    """(path, SHA-256 of its bytes) of every file in ``paths`` (directories walked, sorted)."""
    entries = []
    for path in paths:
        files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [
            refuse_special(path, "input", UserError)]
        for file in files:
            digest = hashlib.sha256()
            with open(file, "rb") as stream:
                while block := stream.read(HASH_BLOCK_BYTES):
                    digest.update(block)
            entries.append((str(file), digest.hexdigest()))
    return entries


def _token(value):
    """JSON form of an option value; tables and arrays by a hash of their content."""
    if isinstance(value, pd.DataFrame):
        return hashlib.sha256(pd.util.hash_pandas_object(value, index=True).to_numpy().tobytes()).hexdigest()
    if hasattr(value, "tobytes"):
        return hashlib.sha256(value.tobytes()).hexdigest()
    if is_dataclass(value) and not isinstance(value, type):
        return asdict(value)
    return jsonable(value) if hasattr(value, "item") else str(value)


class StageCache:
    """Keys, saves and restores the state after each of ``stages`` under ``out_dir/.cache``."""

    def __init__(self, ctx, stages):
        self.ctx = ctx
        self.stages = list(stages)
        self.directory = ctx.out_dir / ".cache"
        self.keys: dict[str, str] = {}
        self.restored: set[str] = set()
        """Stages whose state this run took from the cache."""
        output = ctx.options.output
        previous = self._hash(["inputs", content_hash(ctx.inputs), _package_version()])
        for stage in self.stages:
            parts = [previous, stage.name, getattr(ctx.options, stage.name, None), output.figures,
                     stage.name in output.flat]
            # figures and folders: the files kept for the stage depend on them
            if stage.reads_vehicle and ctx.vehicle is not None:
                parts.append(asdict(ctx.vehicle))
            if stage.reads_dem and ctx.dem_dir is not None and ctx.dem_dir.exists():
                parts.append(content_hash([ctx.dem_dir]))
            previous = self.keys[stage.name] = self._hash(parts)

    @staticmethod
    def _hash(parts) -> str:
        text = json.dumps(parts, sort_keys=True, default=_token)
        return hashlib.sha256(text.encode()).hexdigest()[:20]

    def restore(self) -> int:
        """Load the state after the longest run of unchanged stages; return how many to skip."""
        matched = 0
        for stage in self.stages:
            stored = self.directory / stage.name / "key"
            if not (stored.is_file() and stored.read_text() == self.keys[stage.name]):
                break
            matched += 1
        if matched:
            last = self.directory / self.stages[matched - 1].name
            try:
                if (last / "state.pickle").stat().st_uid != os.getuid():
                    return 0  # a pickle runs code when loaded: only this user's own cache is read
                with open(last / "state.pickle", "rb") as stream:
                    state = pickle.load(stream)
                signals = pd.read_parquet(last / "signals.parquet") if (last / "signals.parquet").is_file() else None
            except (OSError, EOFError, pickle.UnpicklingError, AttributeError, ImportError, ValueError):
                return 0
            self.ctx.signals = signals
            self.ctx.summary.update(state["summary"])
            self.ctx.results = state["results"]
            self.ctx.skipped.update(state["skipped"])
            self.restored = {stage.name for stage in self.stages[:matched]}
        return matched

    def save(self, name: str) -> None:
        target = self.directory / name
        if target.exists():
            shutil.rmtree(target)
        make_dirs(target)  # 0750: the cache holds positions (the output step sets its files 0640)
        if self.ctx.signals is not None:
            self.ctx.signals.to_parquet(target / "signals.parquet", index=False)
        with open(target / "state.pickle", "wb") as stream:
            pickle.dump({"summary": self.ctx.summary, "results": self.ctx.results, "skipped": self.ctx.skipped},
                        stream, protocol=pickle.HIGHEST_PROTOCOL)
        (target / "key").write_text(self.keys[name])
        restrict_tree(target)  # 0640 now, not only if the run gets to its output step
