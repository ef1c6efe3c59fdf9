"""The compiled LUT loop (``lookup.c``), as a type checker reads it: tensors' addresses, strides in elements and
sizes, no Python objects; :mod:`torchgrade.lut.operator` checks what it passes."""

def interpolate(kind: int, codes: int, codes_frame: int, codes_channel: int, out: int, out_frame: int, out_channel: int,
                frames: int, pixels: int, low: int, scale: int, table: int, size: int, chunk: int, threads: int,
                /) -> None: ...
