"""The files haulprofile wrote into an output folder, so that a later command replaces or removes
those and nothing else.

An output folder is shared with whatever the user keeps there (logs, their own tables, the input
itself). A command may write a new file, and may replace or remove a file only when this manifest
(a hidden JSON file in the folder) says haulprofile wrote it and the file is still the one it wrote:
the same inode, size and modification time. A file a user copied over it, or put there, is never
touched; the command stops with a one-line error instead. Symbolic links are refused, not followed.
"""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

from haulprofile.contract.private_files import FILE_MODE

from .errors import UserError

NAME = ".haulprofile-files.json"


def _identity(info: os.stat_result) -> list[int]:
    return [info.st_ino, info.st_size, info.st_mtime_ns]


def refuse_link(path: Path, what: str = "output") -> None:
    """A symbolic link where a command writes is refused: writing would go through it elsewhere."""
    if path.is_symlink():
        raise UserError(f"{what} {path} is a symbolic link; it is never followed, give the real path")


class Manifest:
    """The files under ``root`` that haulprofile wrote, by their path relative to ``root``."""

    def __init__(self, root: str | Path):
        self.root = Path(root)
        self.files: dict[str, list[list[int]]] = {}
        path = self.root / NAME
        refuse_link(path, "manifest")
        try:
            record = json.loads(path.read_text())
            self.files = {str(k): [list(map(int, i)) for i in v] for k, v in record.get("files", {}).items()}
        except (OSError, ValueError, TypeError, AttributeError):
            self.files = {}

    def _key(self, path: Path) -> str:
        return Path(path).relative_to(self.root).as_posix()

    def owns(self, path: str | Path) -> bool:
        """``path`` is a regular file haulprofile wrote and nobody has replaced since."""
        try:
            info = os.lstat(path)
        except OSError:
            return False
        return stat.S_ISREG(info.st_mode) and _identity(info) in self.files.get(self._key(Path(path)), [])

    def check_target(self, path: str | Path) -> None:
        """``path`` may be written: no symbolic link on the way from ``root``, and nothing there
        but a file haulprofile wrote."""
        path = Path(path)
        for part in [*reversed(path.relative_to(self.root).parents[:-1]), path.relative_to(self.root)]:
            probe = self.root / part
            refuse_link(probe)
            if probe != path and probe.exists() and not probe.is_dir():
                raise UserError(f"{probe} is a file in the way of {path}; it is never replaced, "
                                "move it away or give another output folder")
        if path.exists() and not self.owns(path):
            kind = "folder" if path.is_dir() else "file"
            raise UserError(f"{path} is a {kind} this command did not write; it is never replaced, "
                            "move it away or give another output folder")

    def expect(self, target: str | Path, written: str | Path) -> None:
        """``written`` (a finished file) is about to be renamed to ``target``: it counts as ours
        there, and so does what ``target`` holds now while the rename has not happened."""
        keep = [_identity(os.lstat(target))] if self.owns(target) else []
        self.files[self._key(Path(target))] = keep + [_identity(os.lstat(written))]

    def adopt(self, path: str | Path) -> None:
        """``path``, just written by this command, is ours."""
        self.files[self._key(Path(path))] = [_identity(os.lstat(path))]

    def remove(self, path: str | Path) -> bool:
        """Remove ``path`` if it is ours (and its folders left empty); returns whether it was."""
        path = Path(path)
        if not self.owns(path):
            return False
        path.unlink()
        self.files.pop(self._key(path), None)
        for parent in path.parents:
            if parent == self.root or self.root not in parent.parents:
                break
            try:
                parent.rmdir()
            except OSError:
                break
        return True

    def under(self, top: str) -> list[Path]:
        """The files recorded under the top-level name ``top`` (a file or a folder)."""
        return [self.root / key for key in self.files if key == top or key.startswith(top + "/")]

    def save(self, prune: bool = True) -> None:
        """Write the manifest, replacing the earlier one; ``prune`` forgets files no longer ours
        (not while files `expect`ed are still being renamed)."""
        if prune:
            self.files = {k: v for k, v in self.files.items() if self.owns(self.root / k)}
        path = self.root / NAME
        refuse_link(path, "manifest")
        partial = path.with_name(f"{NAME}.{os.getpid()}.partial")
        fd = os.open(partial, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, FILE_MODE)
        try:
            os.fchmod(fd, FILE_MODE)
            with os.fdopen(fd, "w") as stream:
                json.dump({"files": self.files}, stream)
            os.replace(partial, path)
        finally:
            if partial.exists():
                partial.unlink()

    def install(self, target: str | Path, written: str | Path) -> None:
        """Rename the finished file ``written`` (in the same folder tree) to ``target``, ours."""
        self.check_target(target)
        self.expect(target, written)
        self.save(prune=False)
        os.replace(written, target)
        self.save()

    def place(self, staging: str | Path, names: list[Path]) -> None:
        """Move the finished files ``names`` (relative paths, in this order) from ``staging`` to the
        same places under ``root``: all are checked first (`check_target`), each is recorded as
        ours before it is renamed, so an interrupted move leaves nothing that counts as foreign."""
        from haulprofile.contract.private_files import make_dirs

        staging = Path(staging)
        for rel in names:
            self.check_target(self.root / rel)
        for rel in names:
            self.expect(self.root / rel, staging / rel)
        self.save(prune=False)
        for rel in names:
            make_dirs((self.root / rel).parent)
            os.replace(staging / rel, self.root / rel)
        self.save()


def staged_files(staging: str | Path) -> list[Path]:
    """Every file under ``staging``, relative to it, sorted."""
    staging = Path(staging)
    return sorted(p.relative_to(staging) for p in staging.rglob("*") if not p.is_dir())
