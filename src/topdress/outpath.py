"""Output files of the command-line tools: never the input, never half written.

Every command that writes a file (`log export`, `log map`, `replay`) goes through here:

- `check_output(out, inputs)` refuses an output that is one of the inputs, a SQLite companion of
  one (`-wal`, `-shm`, `-journal`: truncating the WAL of a session left by a power cut loses
  every row in it), or the same file under another name (a link: same device and inode);
- the file is written under a temporary name in the same directory and renamed over the target
  only once complete, so an error or a kill leaves the old file (or none), not a torn one;
- `-` means standard output: the result is written to a temporary file and copied out.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import sys
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import TextIO, TypeVar

from topdress.errors import OutputError

STDOUT = "-"
_COMPANIONS = ("-wal", "-shm", "-journal")
_T = TypeVar("_T")


def is_stdout(out: str | Path) -> bool:
    return str(out) == STDOUT


def check_output(out: str | Path, inputs: Iterable[str | Path]) -> None:
    """OutputError when writing `out` would destroy one of `inputs` (or its companions)."""
    if is_stdout(out):
        return
    target = Path(out)
    for given in inputs:
        if is_stdout(given):
            continue
        source = Path(given)
        for victim in (source, *(source.with_name(source.name + c) for c in _COMPANIONS)):
            if _same(target, victim):
                what = "" if victim == source else f" ({victim.name}, part of {source.name})"
                raise OutputError(f"{out}: is the input {given}{what}: give another output")


def _same(a: Path, b: Path) -> bool:
    if a.resolve() == b.resolve():
        return True
    try:
        return a.samefile(b)  # hard link or another path to the same inode
    except OSError:  # one of them does not exist
        return False


@contextlib.contextmanager
def _staged(out: str | Path, suffix: str) -> Iterator[Path]:
    """A temporary path beside `out`, renamed over it when the block ends without an
    exception; removed in every case that did not rename it."""
    target = Path(out)
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp{suffix}")
    try:
        yield tmp
        os.replace(tmp, target)
    except OSError as exc:
        raise OutputError(f"cannot write {out}: {exc}") from exc
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()


def write_output(
    out: str | Path,
    inputs: Iterable[str | Path],
    write: Callable[[Path], _T],
    suffix: str = "",
) -> _T:
    """Call `write(tmp_path)` and put the file it made at `out` (renamed) or on standard
    output (copied); the temporary file never outlives the call. `suffix` is the temporary
    file's extension, for writers that choose their format by it."""
    check_output(out, inputs)
    if is_stdout(out):
        with tempfile.TemporaryDirectory(prefix="topdress-out-") as tmp_dir:
            tmp = Path(tmp_dir) / f"out{suffix}"
            result = write(tmp)
            with tmp.open("rb") as f:
                shutil.copyfileobj(f, sys.stdout.buffer)
            sys.stdout.buffer.flush()
            return result
    with _staged(out, suffix) as tmp:
        return write(tmp)


@contextlib.contextmanager
def open_text_output(out: str | Path, inputs: Iterable[str | Path]) -> Iterator[TextIO]:
    """A text stream for `out`: standard output for `-`, else a temporary file renamed over
    `out` when the block ends without an exception (and removed when it raises)."""
    check_output(out, inputs)
    if is_stdout(out):
        yield sys.stdout
        sys.stdout.flush()
        return
    with _staged(out, "") as tmp, tmp.open("w", encoding="utf-8", newline="") as f:
        yield f


def atomic_write(path: Path, text: str) -> None:
    """Write `text` to `path` so that a crash leaves the old or the new file, never a mix."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError:
        # A full disk: no 0-byte temporary file left beside the sessions.
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
