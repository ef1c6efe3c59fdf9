"""Atomic file writing: a failed write leaves no file and never clobbers an existing one."""

from __future__ import annotations

import contextlib
import os
import secrets
import stat
from pathlib import Path
from typing import Callable

__all__ = ["atomic_write"]


def _temporary_beside(target: Path) -> str:
    """Create an empty file next to ``target``; mode 0666 less the umask, as ``open()`` would give."""
    while True:
        name = target.parent / f".{target.name}.{secrets.token_hex(4)}{target.suffix}"
        try:
            os.close(os.open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
            return str(name)
        except FileExistsError:
            continue


def atomic_write(path, write: Callable[[str], None]) -> None:
    """Call ``write(temporary_path)`` in ``path``'s folder, then rename the result onto ``path``.

    The rename is atomic on POSIX and Windows (``os.replace``): readers see either the old file or
    the complete new one. If ``write`` raises, the temporary file is removed and ``path`` untouched.
    A new file gets the permissions ``open()`` would give it (0666 less the umask), a rewritten
    file keeps its mode, and a symbolic link is followed: its target is replaced, the link stays.
    The data is flushed to disk before the rename, so a crash cannot leave an empty file behind.

    Examples:
        >>> import pathlib, tempfile
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "note.txt"
        >>> atomic_write(path, lambda temporary: pathlib.Path(temporary).write_text("done"))
        >>> path.read_text()
        'done'
    """
    target = Path(os.path.realpath(path))
    if not target.parent.is_dir():
        raise FileNotFoundError(f"cannot write {path}: folder {Path(path).parent} does not exist")
    temporary = _temporary_beside(target)
    try:
        with contextlib.suppress(FileNotFoundError):
            os.chmod(temporary, stat.S_IMODE(os.stat(target).st_mode))
        write(temporary)
        with open(temporary, "rb+") as written:
            os.fsync(written.fileno())
        os.replace(temporary, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temporary)
        raise
