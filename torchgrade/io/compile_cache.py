"""Compiled graphs saved to a file and loaded in another process: PyTorch's cache artifacts
(``torch.compiler.save_cache_artifacts``), which hold Inductor's generated code and AOTAutograd's graphs for what this
process compiled, so that a later compile of the same look skips code generation.

Those artifacts are code: PyTorch unpickles them, writes each where its key says, and runs what they hold at the next
compile (a file whose entries were replaced by a pickle ran its shell command; an entry keyed by an absolute path was
written outside Inductor's cache folder). So a file is loaded only if this user's torchgrade wrote it: it is signed
with HMAC-SHA256 (RFC 2104) under this user's key (:mod:`torchgrade.io.user_key`, made at the first save, readable
by this user only), and :func:`load_compile_cache` checks the signature over every byte before PyTorch sees any. A
file from anywhere else (another user, another machine without the key, a hand-made or edited one) is refused with a
``ValueError`` and nothing is loaded. To carry compiles to a machine that lacks the key, keep Inductor's own cache
folder there (``TORCHINDUCTOR_CACHE_DIR`` on a volume that machine's user owns) instead of a file.

A file is ``MAGIC``, the 32-byte signature, the torch version that wrote it and a newline, then PyTorch's bytes; the
signature covers everything after it.

Examples:
    >>> import pathlib, tempfile, torch, torchgrade as tg
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "look.compiled"
    >>> compiled = tg.compile(tg.ToneMap("reinhard"))
    >>> _ = compiled.warm_up(torch.rand(1, 3, 8, 8))  # doctest: +SKIP
    >>> save_compile_cache(path)  # doctest: +SKIP
    >>> load_compile_cache(path)  # in the next process, before its first compile  # doctest: +SKIP
    True
"""

from __future__ import annotations

import hashlib
import hmac
import warnings
from pathlib import Path

import torch

from ..base.files import read_regular
from .atomic import atomic_write
from .user_key import key_folder, user_key

__all__ = ["save_compile_cache", "load_compile_cache", "signed", "verified", "MAX_CACHE_BYTES", "MAGIC"]

MAX_CACHE_BYTES = 1 << 30
"""Largest cache file :func:`load_compile_cache` reads (the cinematic look's is about 3 MB)."""

MAGIC = b"torchgrade compile cache, signed\n"
"""The first bytes of a file :func:`save_compile_cache` writes."""

_SIGNATURE_BYTES = hashlib.sha256().digest_size
_MAX_VERSION_BYTES = 64
"""Longest torch version a file may name (``2.13.0+cu128`` is 12 bytes)."""


def signed(payload: bytes, key: bytes) -> bytes:
    """PyTorch's ``payload`` as a file: :data:`MAGIC`, the signature under ``key``, this torch's version, the payload.

    Examples:
        >>> data = signed(b"artifacts", bytes(32))
        >>> verified(data, bytes(32), "cache") == (torch.__version__, b"artifacts")
        True
    """
    body = f"{torch.__version__}\n".encode() + payload
    return MAGIC + hmac.digest(key, MAGIC + body, "sha256") + body


def verified(data: bytes, key: bytes, name) -> tuple[str, bytes]:
    """``(torch version, payload)`` of a file :func:`signed` under ``key``; ``ValueError`` naming ``name`` for any
    other bytes, decided before anything is parsed past the signature.

    Examples:
        >>> data = bytearray(signed(b"artifacts", bytes(32)))
        >>> data[-1] ^= 1
        >>> verified(bytes(data), bytes(32), "look.compiled")
        Traceback (most recent call last):
        ...
        ValueError: look.compiled: its signature does not match this user's key, so this user's torchgrade did not write it as it is: refused, nothing loaded
    """
    if not data.startswith(MAGIC):
        raise ValueError(f"{name}: not a signed torchgrade compile cache (another program's file, or one saved before "
                         "caches were signed: save it again): refused, nothing loaded")
    signature, body = data[len(MAGIC):len(MAGIC) + _SIGNATURE_BYTES], data[len(MAGIC) + _SIGNATURE_BYTES:]
    if not hmac.compare_digest(signature, hmac.digest(key, MAGIC + body, "sha256")):
        raise ValueError(f"{name}: its signature does not match this user's key, so this user's torchgrade did not write "
                         "it as it is: refused, nothing loaded")
    end = body.find(b"\n", 0, _MAX_VERSION_BYTES)
    if end < 0:  # signed, so written by this code: only a file of another format version gets here
        raise ValueError(f"{name}: a signed file of another format: refused, nothing loaded")
    return body[:end].decode("ascii", "replace"), body[end + 1:]


def save_compile_cache(path) -> bool:
    """Write what this process compiled to ``path``, signed with this user's key (made at the first save), atomically:
    ``False`` (and no file) where it compiled nothing."""
    saved = torch.compiler.save_cache_artifacts()
    if saved is None:
        return False
    data = signed(saved[0], user_key(create=True))
    atomic_write(path, lambda temporary: Path(temporary).write_bytes(data))
    return True


def load_compile_cache(path) -> bool:
    """Load a file :func:`save_compile_cache` wrote for this user, before the first compile: ``True`` if PyTorch took it.

    A missing file (``FileNotFoundError``), a pipe, a file over :data:`MAX_CACHE_BYTES`, and any file this user's
    torchgrade did not sign (its signature checked under this user's key, :mod:`torchgrade.io.user_key`, before PyTorch
    sees a byte) are refused with ``ValueError``, nothing loaded. A file signed here by another torch, or that PyTorch
    cannot use, warns and loads nothing: the compile then runs cold.
    """
    data = read_regular(path, MAX_CACHE_BYTES, "compile cache")
    try:
        key = user_key()
    except FileNotFoundError:
        raise ValueError(f"{path}: this user has no key ({key_folder()}), so no compile cache was signed here: "
                         "refused, nothing loaded") from None
    version, payload = verified(data, key, path)
    if version != torch.__version__:
        return _not_loaded(path, f"written by torch {version}, this is {torch.__version__}")
    try:
        loaded = torch.compiler.load_cache_artifacts(payload)
    except Exception as error:  # torch's own checks of the artifacts (format, versions), where it raises them
        return _not_loaded(path, str(error))
    return loaded is not None or _not_loaded(path, "damaged")


def _not_loaded(path, reason: str) -> bool:
    warnings.warn(f"{path}: PyTorch could not load the compile cache ({reason}); compiles run without it",
                  RuntimeWarning, stacklevel=3)
    return False
