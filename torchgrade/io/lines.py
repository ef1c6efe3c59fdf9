"""Untrusted text files read as blocks of whole lines, in bounded memory.

A reader that splits a whole file into Python strings needs tens of bytes per short line (a 256³
``.cube`` file held 5.4 GB that way). :func:`line_blocks` instead yields blocks of about
:data:`BLOCK_BYTES` that end on a line end, with CR, LF and CRLF line ends all turned into LF, so a
parser can hand each block to a vectorised reader and still report the line a problem is on.

Lines may be arbitrarily long when they are comments (they are shortened to their ``#``, which keeps
the line count); any other line is refused once more than :data:`MAX_LINE_BYTES` of it are held
waiting for its end, so memory stays within a block and a line.
"""

from __future__ import annotations

import re
from typing import BinaryIO, Iterator

__all__ = ["line_blocks", "BLOCK_BYTES", "MAX_LINE_BYTES"]

BLOCK_BYTES = 1 << 22
"""Bytes read at a time: large enough that per-block overhead vanishes, small next to any table."""

MAX_LINE_BYTES = 1 << 20
"""Longest line kept whole (a long TITLE fits); a longer comment is shortened, anything else refused."""

_TEXT_BYTES = bytes(range(0x20, 0x7F)) + bytes(range(0x80, 0x100)) + b"\t\n\v\f\r"
_NOT_TEXT = re.compile(rb"[^\x20-\x7e\x80-\xff\t\n\v\f\r]")

BYTE_ORDER_MARK = b"\xef\xbb\xbf"
"""UTF-8's byte order mark, which some editors put at the start of a text file: skipped."""


def line_blocks(handle: BinaryIO, path, comment: bytes = b"#") -> Iterator[tuple]:
    """Yield ``(number of the block's first line, bytes)``; each block is whole lines, each ending in ``\\n``.

    A last line without a line end comes as a block of its own. The text is UTF-8 (a title or a comment may hold
    any language; a leading byte order mark is skipped). Raises ``ValueError`` naming the line for control bytes,
    for bytes that are not UTF-8, or for an over-long line that is not a comment.

    Examples:
        >>> import io
        >>> list(line_blocks(io.BytesIO(b"a\\r\\nb\\rc"), "x"))
        [(1, b'a\\nb\\n'), (3, b'c\\n')]
    """
    carry, line, first = b"", 1, True
    while True:
        data = handle.read(BLOCK_BYTES)
        if not data:
            break
        if first and data.startswith(BYTE_ORDER_MARK):
            data = data[len(BYTE_ORDER_MARK):]
        first = False
        text = carry + data
        # A final CR may be the first half of a CRLF split across two reads: keep it for the next block.
        end = len(text) - 1 if text.endswith(b"\r") else len(text)
        cut = max(text.rfind(b"\n", 0, end), text.rfind(b"\r", 0, end)) + 1
        block = _normalised(text[:cut], line, path)
        if block:
            # Yielded before the unfinished line is judged, so a caller can refuse the file from its header first.
            yield line, block
            line += block.count(b"\n")
        carry = _bounded_carry(text[cut:], line, path, comment)
    if carry:
        yield line, _normalised(carry + b"\n", line, path)


def _bounded_carry(partial: bytes, line: int, path, comment: bytes) -> bytes:
    """The unfinished last line, shortened to its comment mark when it is a long comment."""
    if len(partial) <= MAX_LINE_BYTES:
        return partial
    if partial.lstrip(b" \t").startswith(comment):
        return comment
    raise ValueError(f"{path}: line {line}: longer than {MAX_LINE_BYTES} bytes")


def _normalised(text: bytes, line: int, path) -> bytes:
    text = text.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    if text.translate(None, _TEXT_BYTES):
        position = next(_NOT_TEXT.finditer(text)).start()
        raise ValueError(f"{path}: line {line + text.count(NEWLINE, 0, position)}: not a text file (control bytes)")
    if not text.isascii():
        try:
            text.decode("utf-8")  # whole lines: a block never cuts a character in two
        except UnicodeDecodeError as error:
            raise ValueError(f"{path}: line {line + text.count(NEWLINE, 0, error.start)}: not a text file (not UTF-8)") from None
    return text


NEWLINE = b"\n"
