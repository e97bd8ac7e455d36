"""Known device descriptions (DDOPs) kept beside the session logs, so that a client whose
structure and localization labels match the pool the TC holds is told so and need not upload
it again (ISO 11783-10: the TC answers the label requests with the stored pool's labels).

One file per client NAME, named by the NAME and both labels in hex
(`A00A8000AFE01092_<structure>_<localization>.ddop`), holding a magic line, the SHA-256 of the
pool and the pool. A file that does not read back whole (cut, flipped bits, another format) is
never used: it is renamed `*.corrupt` (kept for a look, nothing lost), reported, and the client
is asked for its pool again. Writes go to a temporary file first and are renamed into place, so
a power cut leaves the old pool or the new one, never half of one.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from topdress.errors import ProtocolError

MAGIC = b"topdress DDOP 1\n"
SUFFIX = ".ddop"


class PoolStore:
    """The pools known to the terminal, in one folder (created on the first save)."""

    def __init__(self, folder: Path) -> None:
        self.folder = Path(folder)

    @classmethod
    def beside(cls, log_dir: Path | str) -> PoolStore:
        """The store of a terminal whose sessions go to `log_dir` (`[log] dir`)."""
        return cls(Path(log_dir) / "ddop")

    def _files(self, name: int) -> list[Path]:
        if not self.folder.is_dir():
            return []
        return sorted(self.folder.glob(f"{name:016X}_*{SUFFIX}"))

    def load(self, name: int) -> bytes | None:
        """The pool kept for `name`; None when there is none. ProtocolError (the file renamed
        `*.corrupt`) when it does not read back as it was written."""
        files = self._files(name)
        if not files:
            return None
        path = files[-1]
        try:
            raw = path.read_bytes()
        except OSError as exc:
            raise ProtocolError(f"stored DDOP {path.name} unreadable: {exc}") from None
        head = len(MAGIC) + 32
        if raw[: len(MAGIC)] != MAGIC or len(raw) <= head:
            self.discard(name, path)
            raise ProtocolError(f"stored DDOP {path.name} is not a pool file: set aside")
        pool = raw[head:]
        if hashlib.sha256(pool).digest() != raw[len(MAGIC) : head]:
            self.discard(name, path)
            raise ProtocolError(f"stored DDOP {path.name} fails its checksum: set aside")
        return pool

    def save(self, name: int, pool: bytes, structure: bytes, localization: bytes) -> Path:
        """Keeps `pool` for `name` (replacing any older one); OSError when the disk refuses."""
        self.folder.mkdir(parents=True, exist_ok=True)
        path = self.folder / f"{name:016X}_{structure.hex()}_{localization.hex()}{SUFFIX}"
        tmp = path.with_suffix(".tmp")
        with open(tmp, "wb") as f:
            f.write(MAGIC + hashlib.sha256(pool).digest() + pool)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
        for old in self._files(name):
            if old != path:
                old.unlink(missing_ok=True)
        return path

    def discard(self, name: int, path: Path | None = None) -> None:
        """Sets the pool of `name` aside as `*.corrupt` (it is not used again)."""
        for p in [path] if path is not None else self._files(name):
            try:
                p.replace(p.with_suffix(".corrupt"))
            except OSError:
                p.unlink(missing_ok=True)

    def delete(self, name: int) -> None:
        """Forgets the pool of `name` (the client deleted it)."""
        for p in self._files(name):
            p.unlink(missing_ok=True)
