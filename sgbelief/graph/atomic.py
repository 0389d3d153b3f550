"""Atomic file writes: a reader never sees a partial file, a failed write leaves the old file.

Each write goes to a temp file in the target's directory (``.<name>.<pid>.XXXX.tmp``), is
fsynced and renamed over the target. Temp files that a killed writer left behind are removed by
the next write of the same target.
"""

from __future__ import annotations

import os
import stat
import tempfile
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import BinaryIO


def atomic_write_text(path: str | Path, text: str | Iterable[str]) -> None:
    """Write text (a string or an iterable of chunks) atomically: temp file in the same directory,
    fsync, rename. Readers never see a partial file; on error the old file is left untouched."""

    def write(fh: BinaryIO) -> None:
        chunks = [text] if isinstance(text, str) else text
        for chunk in chunks:
            fh.write(chunk.encode("utf-8"))

    atomic_write_binary(path, write)


def _umask() -> int:
    """The process umask (read by setting and restoring it)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


#: temp files this process is writing right now (never removed as stale)
_IN_FLIGHT: set[str] = set()
#: a temp file without a writer's pid in its name (older sgbelief) is stale after this many seconds
_LEGACY_TMP_AGE = 600.0


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True  # exists (another user's process) or cannot tell: keep its file
    return True


def remove_stale_temp_files(path: str | Path) -> list[Path]:
    """Remove temp files a killed save of ``path`` left behind (``.<name>.<pid>.XXXX.tmp``).

    A temp file is stale when the process whose pid it names is gone (or is this process, which
    is not writing it); a temp file without a pid (written by an older sgbelief) when it is older
    than ten minutes. Temp files of other targets, and of live writers, are left alone.
    """
    path = Path(path)
    prefix, removed = f".{path.name}.", []
    try:
        names = os.listdir(path.parent)
    except OSError:
        return removed
    me = os.getpid()
    now = time.time()
    for name in names:
        if not (name.startswith(prefix) and name.endswith(".tmp")):
            continue
        cand = path.parent / name
        if str(cand) in _IN_FLIGHT:
            continue
        middle = name[len(prefix):-len(".tmp")].split(".")
        if len(middle) == 2 and middle[0].isdigit():
            pid = int(middle[0])
            stale = pid == me or not _pid_alive(pid)
        elif len(middle) == 1:
            try:
                stale = now - cand.stat().st_mtime > _LEGACY_TMP_AGE
            except OSError:
                continue
        else:
            continue  # another file name pattern (e.g. a target whose name has more dots)
        if stale:
            try:
                cand.unlink()
                removed.append(cand)
            except OSError:
                pass
    return removed


def atomic_write_binary(path: str | Path, write: Callable[[BinaryIO], None]) -> None:
    """Call ``write(fh)`` on a temp file in the same directory, fsync, rename over ``path``.
    Readers never see a partial file; on error the old file is left untouched. Temp files that
    an earlier, killed save of the same target left behind are removed first."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temp_files(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp", dir=path.parent)
    _IN_FLIGHT.add(tmp)
    try:
        # mkstemp creates the file 0600; give it the mode a plain open() would (or the old file's)
        try:
            mode = stat.S_IMODE(os.stat(path).st_mode)
        except FileNotFoundError:
            mode = 0o666 & ~_umask()
        os.chmod(fd, mode)
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    finally:
        _IN_FLIGHT.discard(tmp)


__all__ = ["atomic_write_binary", "atomic_write_text", "remove_stale_temp_files"]
