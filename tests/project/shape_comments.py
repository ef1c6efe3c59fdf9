"""The shapes the examples' comments state, checked against what the code returns.

An example line ``codes = session.run(...)[0]  # uint8 sRGB, (4, 45, 80, 3)`` states the shape of ``codes``; after
the example runs, :func:`check_shape_comments` compares it with ``codes.shape``. A dimension written as a capital
letter (``(1, 3, H, W)``) stands for any size; a number must match.
"""

import re

CLAIM = re.compile(r"^(?P<name>\w+)\s*=[^#]*#.*?\((?P<dims>\s*(?:\d+|[A-Z])\s*(?:,\s*(?:\d+|[A-Z])\s*)+)\)")


def shape_claims(block: str) -> list:
    """``(name, dims, line)`` for each top-level assignment whose comment states a shape."""
    claims = []
    for line in block.splitlines():
        match = CLAIM.match(line)
        if match:
            dims = [int(d) if d.strip().isdigit() else None for d in match["dims"].split(",")]
            claims.append((match["name"], dims, line.strip()))
    return claims


def check_shape_comments(block: str, namespace: dict) -> int:
    """Assert that every stated shape of ``block`` is the shape its name holds in ``namespace``; the count checked."""
    checked = 0
    for name, dims, line in shape_claims(block):
        value = namespace.get(name)
        if not hasattr(value, "shape"):
            continue
        shape = tuple(value.shape)
        assert len(shape) == len(dims) and all(d is None or d == s for d, s in zip(dims, shape)), (line, shape)
        checked += 1
    return checked
