"""Logs encrypted at rest (``.mcap.age``, age format): decrypted for reading with the fleet's identity.

``analyze --identity FILE …`` (or ``--identity FILE`` anywhere after the command) registers the
identity; every ``.mcap.age`` input is then decrypted with ``pyrage`` into memory (a ``memfd``,
which no file system holds and which ends with the process, however it ends: SIGTERM, SIGHUP or
SIGKILL included). The readers open it by a symbolic link under its name without ``.age`` in a
private temporary directory (0700), so they and the file ordering see the logger's plain names;
that directory holds no plaintext, is removed at exit and on SIGTERM/SIGHUP, and one left by a
killed process is removed by the next run. Decryption checks age's authentication tags: a
modified or truncated ciphertext is an error, not a silently shorter log.
"""

from __future__ import annotations

import atexit
import os
import shutil
import signal
import tempfile
import threading
from pathlib import Path

from haulprofile.contract.input_files import read_small

from .errors import UserError

SUFFIX = ".mcap.age"
_identities: list = []
_decrypted: dict[Path, Path] = {}
_directory: Path | None = None
_open_plaintexts: list[int] = []
"""Descriptors of the decrypted logs (memfds), open while the process runs."""


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
    data = read_small(path, "identity", UserError)
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


PREFIX = "haulprofile-decrypted-"


def _remove_left_behind() -> None:
    """Directories of links left by killed runs (their process is gone)."""
    for directory in Path(tempfile.gettempdir()).glob(f"{PREFIX}*-*"):
        try:
            pid = int(directory.name[len(PREFIX):].split("-")[0])
            if directory.is_symlink() or directory.stat().st_uid != os.getuid() or _alive(pid):
                continue
        except (ValueError, OSError):
            continue
        shutil.rmtree(directory, ignore_errors=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _exit_on(signum, _frame) -> None:
    raise SystemExit(128 + signum)


def _workdir() -> Path:
    global _directory
    if _directory is None:
        _remove_left_behind()
        _directory = Path(tempfile.mkdtemp(prefix=f"{PREFIX}{os.getpid()}-"))
        atexit.register(shutil.rmtree, _directory, True)
        if threading.current_thread() is threading.main_thread():
            for signum in (signal.SIGTERM, signal.SIGHUP):
                if signal.getsignal(signum) == signal.SIG_DFL:
                    signal.signal(signum, _exit_on)  # atexit runs: the directory goes too
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
    name = path.name[:-len(".age")]
    fd = os.memfd_create(name, os.MFD_CLOEXEC)
    try:
        with open(path, "rb") as source, open(os.dup(fd), "wb") as sink:
            pyrage.decrypt_io(source, sink, _identities)
    except Exception as exc:  # pyrage.DecryptError: wrong identity, modified or cut ciphertext
        os.close(fd)
        raise UserError(f"{path}: cannot decrypt with the given identity ({exc})") from None
    target = Path(tempfile.mkdtemp(dir=_workdir())) / name
    target.symlink_to(f"/proc/{os.getpid()}/fd/{fd}")
    _open_plaintexts.append(fd)
    _decrypted[key] = target
    return target
