"""Encryption at rest: every closed log becomes ``<name>.mcap.age``, encrypted to the fleet's public
key(s) in the age format (age-encryption.org/v1, X25519) by ``pyrage``, a binding of the audited
``rage`` implementation. The Pi holds only recipients (public keys): it cannot read its own old logs.

Order of a file's way to ciphertext, so that a power cut at any moment loses nothing:

1. a file not closed cleanly (no MCAP footer: a power cut, a failed write) is first repaired
   (`haulprofile.contract.repair.repair`: every message the contract reader recovers into a new,
   indexed file, replacing the cut one);
2. the ciphertext is written to ``<name>.mcap.age.partial`` (mode 0640), flushed and fsynced,
   renamed to ``<name>.mcap.age`` and the directory fsynced;
3. only then is the plaintext removed (and the directory fsynced again).

At start the daemon hands every plaintext log left in its directory to the same path (a
``.partial`` is a ciphertext cut short: removed; a plaintext beside its finished ``.age`` is the
moment between steps 2 and 3: removed). The work runs in one background thread, never on the
event loop.
"""

from __future__ import annotations

import os
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

from haulprofile.contract.naming import log_files
from haulprofile.contract.repair import is_complete, repair
from haulprofile.contract.private_files import open_new

SUFFIX = ".age"


class EncryptionUnavailable(Exception):
    """Recipients are configured but pyrage is not installed or a recipient is not a key."""


def parse_recipients(strings: list[str]) -> list:
    """age recipients (``age1…``) or SSH public keys (``ssh-ed25519 …``, ``ssh-rsa …``)."""
    try:
        import pyrage
    except ImportError:
        raise EncryptionUnavailable("encryption.recipients needs pyrage (pip install 'haulprofile[logger]')") from None
    recipients = []
    for index, text in enumerate(strings):
        try:
            if text.startswith("ssh-"):
                recipients.append(pyrage.ssh.Recipient.from_str(text))
            else:
                recipients.append(pyrage.x25519.Recipient.from_str(text))
        except Exception as exc:  # pyrage.RecipientError, ValueError
            raise EncryptionUnavailable(f"encryption.recipients[{index}] is not an age or SSH public key: {exc}") from None
    return recipients


def _fsync_dir(directory: Path) -> None:
    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def encrypt_log(path: Path, recipients: list) -> Path:
    """Steps 1–3 above for one log; returns the ``.age`` path."""
    import pyrage
    path = Path(path)
    target = path.with_name(path.name + SUFFIX)
    partial = target.with_name(target.name + ".partial")
    if target.exists():  # encrypted and renamed before a power cut: only the removal was missing
        path.unlink()
        _fsync_dir(path.parent)
        return target
    if not is_complete(path):
        repair(path)
    try:
        with open(path, "rb") as source, open_new(partial, exclusive=False) as sink:
            pyrage.encrypt_io(source, sink, recipients)
            sink.flush()
            os.fsync(sink.fileno())
        os.replace(partial, target)
        _fsync_dir(path.parent)
    finally:
        partial.unlink(missing_ok=True)
    path.unlink()
    _fsync_dir(path.parent)
    return target


class Encryptor:
    """One worker thread that encrypts closed logs in the order they were handed in."""

    def __init__(self, recipients: list, say=None):
        self.recipients = recipients
        self._say = say or (lambda message: None)
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="encrypt")
        self._lock = threading.Lock()
        self._pending: list[Future] = []
        self.encrypted: list[Path] = []
        self.errors = 0
        self.cpu_s = 0.0
        """CPU time of the worker thread spent on logs so far [s] (benchmark)."""

    def _run(self, path: Path) -> None:
        start = time.thread_time()
        try:
            self.encrypted.append(encrypt_log(path, self.recipients))
        except Exception as exc:  # a full disk, a vanished file: the plaintext stays for the next start
            self.errors += 1
            self._say(f"encryption of {path.name} failed ({exc!r}); it stays plaintext until the next start")
        finally:
            self.cpu_s += time.thread_time() - start

    def submit(self, path: Path) -> None:
        with self._lock:
            self._pending = [f for f in self._pending if not f.done()]
            self._pending.append(self._executor.submit(self._run, Path(path)))

    def submit_leftovers(self, directory: Path, prefix: str, current: Path | None = None) -> int:
        """Hand in every plaintext log of ``directory`` but the one being written; remove cut ``.partial``s."""
        directory = Path(directory)
        for partial in directory.glob(f"{prefix}_*.mcap{SUFFIX}.partial"):
            partial.unlink(missing_ok=True)
        leftovers = [p for p in log_files(directory, prefix) if p.suffix == ".mcap" and p != current]
        for path in leftovers:
            self.submit(path)
        return len(leftovers)

    def wait(self) -> None:
        with self._lock:
            pending = list(self._pending)
        for future in pending:
            future.result()

    def close(self) -> None:
        self.wait()
        self._executor.shutdown(wait=True)
