"""Logs encrypted at rest (``.mcap.age``, age format): decrypted for reading with the fleet's identity.

``analyze --identity FILE …`` (or ``--identity FILE`` anywhere after the command) registers the
identity; every ``.mcap.age`` input is then decrypted with ``pyrage`` into a private temporary
directory (0700, files 0600, removed at exit) under its name without ``.age``, so the readers
and the file ordering see the logger's plain names. Decryption checks age's authentication
tags: a modified or truncated ciphertext is an error, not a silently shorter log.
"""

from __future__ import annotations

import atexit
import shutil
import tempfile
from pathlib import Path

from .errors import UserError

SUFFIX = ".mcap.age"
_identities: list = []
_decrypted: dict[Path, Path] = {}
_directory: Path | None = None


def is_encrypted(path: str | Path) -> bool:
    return Path(path).name.endswith(SUFFIX)


def use_identity_files(paths: list[str | Path]) -> None:
    """The identities for this run (replacing any earlier ones; decrypted copies are forgotten)."""
    _identities.clear()
    _decrypted.clear()
    for path in paths:
        use_identity_file(path)


def use_identity_file(path: str | Path) -> int:
    """Register the identities of an age identity file (``AGE-SECRET-KEY-1…`` lines) or an
    OpenSSH private key; returns how many."""
    path = Path(path)
    try:
        import pyrage
    except ImportError:
        raise UserError("reading .mcap.age logs needs pyrage (pip install 'haulprofile[analysis]')") from None
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise UserError(f"--identity {path}: cannot read: {exc.strerror}") from None
    found = []
    try:
        if data.lstrip().startswith(b"-----BEGIN OPENSSH PRIVATE KEY"):
            found.append(pyrage.ssh.Identity.from_buffer(data))
        else:
            for line in data.decode("ascii").splitlines():
                if line.strip().startswith("AGE-SECRET-KEY-"):
                    found.append(pyrage.x25519.Identity.from_str(line.strip()))
    except Exception as exc:  # pyrage.IdentityError, UnicodeDecodeError
        raise UserError(f"--identity {path}: not an age identity file or OpenSSH private key ({exc})") from None
    if not found:
        raise UserError(f"--identity {path}: no AGE-SECRET-KEY-1… line in it")
    _identities.extend(found)
    return len(found)


def _workdir() -> Path:
    global _directory
    if _directory is None:
        _directory = Path(tempfile.mkdtemp(prefix="haulprofile-decrypted-"))
        atexit.register(shutil.rmtree, _directory, True)
    return _directory


def read_bytes(path: str | Path) -> bytes:
    """The plaintext of a log (decrypted if it is ``.mcap.age``)."""
    path = Path(path)
    if not is_encrypted(path):
        return path.read_bytes()
    return decrypted(path).read_bytes()


def decrypted(path: str | Path) -> Path:
    """A readable plaintext path for ``path`` (itself unless it is ``.mcap.age``)."""
    path = Path(path)
    if not is_encrypted(path):
        return path
    key = path.resolve()
    if key in _decrypted:
        return _decrypted[key]
    if not _identities:
        raise UserError(f"{path} is encrypted (age): give the fleet's identity with --identity FILE")
    import pyrage
    target_dir = Path(tempfile.mkdtemp(dir=_workdir()))
    target = target_dir / path.name[:-len(".age")]
    from haulprofile.private_files import open_new
    try:
        with open(path, "rb") as source, open_new(target) as sink:
            pyrage.decrypt_io(source, sink, _identities)
        target.chmod(0o600)
    except Exception as exc:  # pyrage.DecryptError: wrong identity, modified or cut ciphertext
        target.unlink(missing_ok=True)
        raise UserError(f"{path}: cannot decrypt with the given identity ({exc})") from None
    _decrypted[key] = target
    return target
