"""This user's secret key, which signs the files only this user's torchgrade may load back (compile caches: they hold
code). It lives in ``$XDG_CONFIG_HOME/torchgrade/`` (``~/.config/torchgrade/``): a folder of mode 0700 holding a
32-byte file of mode 0600, both owned by this user, created at the first save.

Whoever can read or replace the key can sign a file, so it is used only when the folder and the key are this user's
(the effective uid) and neither is open to the group or others, and neither is a symbolic link: the folder is opened
without following a link and the key through the folder's descriptor, and both are checked with ``fstat`` on what was
opened, so a path swapped between a check and a read changes nothing (another user can make a folder, never one
owned by this user). A key is written beside its final name and linked to it (``link`` never replaces a file), so two
processes creating it at once both read one whole key.

Examples:
    >>> import os, tempfile
    >>> folder = os.path.join(tempfile.mkdtemp(), "torchgrade")
    >>> key = user_key(folder, create=True)
    >>> len(key), key == user_key(folder), oct(os.stat(folder).st_mode & 0o777)
    (32, True, '0o700')
"""

from __future__ import annotations

import os
import secrets
import stat
from pathlib import Path

__all__ = ["KEY_BYTES", "KEY_NAME", "key_folder", "user_key"]

KEY_BYTES = 32
"""Bytes of the key: HMAC-SHA256's block-sized secret (RFC 2104 asks for at least the 32 bytes of its output)."""

KEY_NAME = "compile-cache.key"

_PRIVATE = 0o077
"""The mode bits of the group and others: none may be set on the folder or the key."""


def key_folder() -> Path:
    """Where this user's key lives: ``$XDG_CONFIG_HOME/torchgrade``, else (unset, or not an absolute path, which the XDG
    Base Directory specification says to ignore) ``~/.config/torchgrade``."""
    configured = os.environ.get("XDG_CONFIG_HOME", "")
    return (Path(configured) if os.path.isabs(configured) else Path.home() / ".config") / "torchgrade"


def user_key(folder=None, create: bool = False) -> bytes:
    """This user's key in ``folder`` (:func:`key_folder` by default), made first with ``create``.

    Raises ``ValueError`` naming the folder or the key when either is not this user's, is open to the group or others,
    is a symbolic link or is not the size of a key; ``FileNotFoundError`` where there is no key and ``create`` is false.
    """
    if not hasattr(os, "O_NOFOLLOW") or not hasattr(os, "geteuid"):
        raise ValueError("a signed file needs a key only this user can read, which this platform's files cannot say; "
                         "use torch's own cache folder (TORCHINDUCTOR_CACHE_DIR) instead")
    folder = Path(folder) if folder is not None else key_folder()
    if create:
        folder.parent.mkdir(parents=True, exist_ok=True)
        try:
            folder.mkdir(mode=0o700)
        except FileExistsError:
            pass
    try:
        directory = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW)
    except FileNotFoundError:
        raise FileNotFoundError(f"no key folder {folder}: nothing was signed by this user here") from None
    except OSError as error:  # ELOOP (a link), ENOTDIR
        raise ValueError(f"key folder {folder} is not a folder of its own ({error.strerror})") from None
    try:
        _check_private(os.fstat(directory), folder, "key folder", "700")
        if create:
            _create_once(directory)
        return _read_key(directory, folder / KEY_NAME)
    finally:
        os.close(directory)


def _check_private(status: os.stat_result, path: Path, what: str, mode: str) -> None:
    if status.st_uid != os.geteuid():
        raise ValueError(f"{what} {path} belongs to user {status.st_uid}, not to this user ({os.geteuid()})")
    if stat.S_IMODE(status.st_mode) & _PRIVATE:
        raise ValueError(f"{what} {path} is open to others (mode {stat.S_IMODE(status.st_mode):o}): "
                         f"chmod {mode} it, or remove it to start a new key")


def _read_key(directory: int, path: Path) -> bytes:
    try:
        descriptor = os.open(KEY_NAME, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK, dir_fd=directory)
    except FileNotFoundError:
        raise FileNotFoundError(f"no key {path}: nothing was signed by this user here") from None
    except OSError as error:  # ELOOP: a symbolic link
        raise ValueError(f"key {path} is not a file of its own ({error.strerror})") from None
    with os.fdopen(descriptor, "rb") as handle:
        status = os.fstat(descriptor)
        if not stat.S_ISREG(status.st_mode) or status.st_size != KEY_BYTES:
            raise ValueError(f"key {path} is not a {KEY_BYTES}-byte file")
        _check_private(status, path, "key", "600")
        key = handle.read(KEY_BYTES + 1)
    if len(key) != KEY_BYTES:
        raise ValueError(f"key {path} is not a {KEY_BYTES}-byte file")
    return key


def _create_once(directory: int) -> None:
    """Write a new key beside its name and link it there, unless a key is there already (or another process links
    one first)."""
    try:
        os.stat(KEY_NAME, dir_fd=directory, follow_symlinks=False)
        return
    except FileNotFoundError:
        pass
    temporary = f".{KEY_NAME}.{secrets.token_hex(4)}"
    descriptor = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600, dir_fd=directory)
    try:
        with os.fdopen(descriptor, "wb") as handle:
            handle.write(secrets.token_bytes(KEY_BYTES))
            handle.flush()
            os.fsync(handle.fileno())
        try:
            os.link(temporary, KEY_NAME, src_dir_fd=directory, dst_dir_fd=directory, follow_symlinks=False)
        except FileExistsError:
            pass  # another process made the key first: its key is the one
    finally:
        os.unlink(temporary, dir_fd=directory)
