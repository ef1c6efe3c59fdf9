"""Atomic file writing: a failed write leaves no file and never clobbers an existing one.

A write goes to a hidden temporary beside its file, ``.{name}.{8 hex digits}{suffix}``, renamed onto the file once
whole; an exception or SIGTERM removes it, but a process killed with SIGKILL (or a machine that stops) cannot:
:func:`remove_interrupted` removes what such a write of the same files left.
"""

from __future__ import annotations

import contextlib
import os
import re
import secrets
import stat
from pathlib import Path
from typing import Callable, Iterable

__all__ = ["atomic_write", "remove_interrupted"]

_TEMPORARY = re.compile(r"\.(?P<name>.+)\.[0-9a-f]{8}(?P<suffix>.*)", re.S)
"""A temporary's name: ``.`` the file's name, ``.``, 8 hex digits, the file's suffix (the longest name that fits)."""


def _temporary_beside(target: Path) -> str:
    """Create an empty file next to ``target``; mode 0666 less the umask, as ``open()`` would give."""
    while True:
        name = target.parent / f".{target.name}.{secrets.token_hex(4)}{target.suffix}"
        try:
            os.close(os.open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
            return str(name)
        except FileExistsError:
            continue


def atomic_write(path, write: Callable[[str], object]) -> None:
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


def _written_by_a_temporary(name: str) -> str | None:
    """The name of the file a temporary called ``name`` was written for, or ``None`` for any other name.

    Examples:
        >>> _written_by_a_temporary(".g.0015.exr.8ff158ee.exr"), _written_by_a_temporary(".g.0015.exr")
        ('g.0015.exr', None)
    """
    match = _TEMPORARY.fullmatch(name)
    if match is None or Path(match["name"]).suffix != match["suffix"]:
        return None
    return match["name"]


def remove_interrupted(paths: Iterable) -> int:
    """Remove the temporaries that writes of ``paths`` left when their process was killed (SIGKILL), and return how
    many: this user's regular files named as :func:`atomic_write` names a temporary of one of ``paths``, and no other
    file (a write of another file, in flight in another process, keeps its temporary).

    Examples:
        >>> import pathlib, tempfile
        >>> folder = pathlib.Path(tempfile.mkdtemp())
        >>> _ = (folder / ".g.0015.exr.8ff158ee.exr").write_bytes(b"half a frame")
        >>> _ = (folder / ".g.0016.exr.0bc52090.exr").write_bytes(b"another run's frame")
        >>> remove_interrupted([folder / "g.0015.exr"]), sorted(p.name for p in folder.iterdir())
        (1, ['.g.0016.exr.0bc52090.exr'])
    """
    wanted: dict[str, set] = {}
    for path in paths:
        target = Path(os.path.realpath(path))
        wanted.setdefault(str(target.parent), set()).add(target.name)
    removed = 0
    for folder, names in wanted.items():
        with contextlib.suppress(FileNotFoundError), os.scandir(folder) as entries:
            for entry in entries:
                if entry.name.startswith(".") and _written_by_a_temporary(entry.name) in names and _own_file(entry):
                    with contextlib.suppress(FileNotFoundError):
                        os.unlink(entry.path)
                        removed += 1
    return removed


def _own_file(entry: os.DirEntry) -> bool:
    status = entry.stat(follow_symlinks=False)
    return stat.S_ISREG(status.st_mode) and (not hasattr(os, "geteuid") or status.st_uid == os.geteuid())
