"""Writing .cube files: Adobe form for a linear shaper, Resolve form (a 1D shaper section) otherwise, or 3D-only."""

from __future__ import annotations

import torch

from ...lut import LUT3D, MIN_SIZE, SHAPERS, lattice, validation_colours
from ...lut.report import measure
from ..atomic import atomic_write
from .limits import MAX_SHAPER_SIZE, SHAPER_SIZE

__all__ = ["write_cube", "cube_text", "check_title", "shaper_samples", "lattice_only"]


def write_cube(path, lut: LUT3D, title: str = "torchgrade", shaper_size: int = SHAPER_SIZE, shaper_section: bool = True,
               top: float = 1.0):
    """Write ``lut`` to ``path`` as a .cube file (atomically: a failed write leaves nothing behind).

    ``shaper_section=False`` writes a 3D-only file (Adobe form, no 1D section: what ffmpeg's
    ``lut3d`` and other 3D-only readers accept): a LUT with a shaper is resampled onto a linear
    lattice over ``[0, top]`` (:func:`lattice_only`), and the :class:`~torchgrade.lut.ErrorReport` of
    that resampling against ``lut`` is returned. Otherwise returns ``None``.
    """
    cost = None
    if not shaper_section and not SHAPERS[lut.shaper].cube_domain_form:
        lut, cost = lattice_only(lut, top)
    text = cube_text(lut, title, shaper_size)
    atomic_write(path, lambda temporary: _write_text(temporary, text))
    return cost


def lattice_only(lut: LUT3D, top: float = 1.0) -> tuple:
    """``(linear-shaper LUT over [0, top], ErrorReport)``: ``lut`` sampled on an evenly spaced linear lattice of its size.

    The report measures the resampled LUT against ``lut`` on the validation colours (HDR ones when
    ``top`` exceeds 1): shadows lose the shaper's resolution and inputs above ``top`` clamp.

    Examples:
        >>> from torchgrade.lut import identity_table
        >>> resampled, cost = lattice_only(LUT3D(identity_table(3), "logc"))
        >>> resampled.shaper, cost.colours > 0
        ('linear', True)
    """
    if not top > 0:
        raise ValueError(f"3D-only lattice top must be above 0, got {top}")
    points = (lattice(lut.size) * top).reshape(1, -1, 3).permute(0, 2, 1).unsqueeze(-1)  # (1, 3, S³, 1)
    with torch.no_grad():
        table = lut(points.float()).double().squeeze(-1)[0].t().reshape(lut.size, lut.size, lut.size, 3)
    resampled = LUT3D(table.float(), "linear", domain=(0.0, top), output_range=lut.output_range)
    colours = validation_colours(hdr=top > 1.0).reshape(1, 3, 1, -1)
    with torch.no_grad():
        cost = measure(resampled, (colours, lut(colours.float()).double()), 1.0)
    return resampled, cost


def cube_text(lut: LUT3D, title: str = "torchgrade", shaper_size: int = SHAPER_SIZE) -> str:
    """The .cube file contents of ``lut``: Adobe form for a shaper without a 1D section, Resolve form otherwise.

    Examples:
        >>> from torchgrade.lut import identity_table
        >>> cube_text(LUT3D(identity_table(2))).splitlines()[:4]
        ['TITLE "torchgrade"', 'DOMAIN_MIN 0.0 0.0 0.0', 'DOMAIN_MAX 1.0 1.0 1.0', 'LUT_3D_SIZE 2']
    """
    check_title(title, "cube", '"')
    section = shaper_samples(lut, shaper_size)
    if section is None:
        lines = [f'TITLE "{title}"']
        lines += [f"DOMAIN_MIN {_numbers(lut.domain_min)}", f"DOMAIN_MAX {_numbers(lut.domain_max)}"]
        lines += [f"LUT_3D_SIZE {lut.size}"]
    else:
        low, high, shaper = section
        lines = [f"# {title}"]  # OpenColorIO's Resolve reader rejects the TITLE keyword
        lines += [f"LUT_1D_SIZE {shaper_size}", f"LUT_1D_INPUT_RANGE {low!r} {high!r}"]
        lines += [f"LUT_3D_SIZE {lut.size}", "LUT_3D_INPUT_RANGE 0.0 1.0"]
        lines += _data_lines(shaper)
    lines += _data_lines(lut.linear_table().detach().reshape(-1, 3))
    return "\n".join(lines) + "\n"


def shaper_samples(lut: LUT3D, count: int):
    """The Resolve 1D section of ``lut``'s shaper, ``(low, high, (count, 3) lattice coordinates)``, or ``None``.

    The shaper object gives it (:meth:`~torchgrade.lut.Shaper.cube_section`); a shaper whose
    ``cube_domain_form`` is true (linear) has none: the Adobe ``DOMAIN_MIN/MAX`` keywords state it.

    Examples:
        >>> from torchgrade.lut import identity_table
        >>> low, high, samples = shaper_samples(LUT3D(identity_table(2), "logc"), 16)
        >>> samples.shape
        torch.Size([16, 3])
    """
    shaper = SHAPERS[lut.shaper]
    if shaper.cube_domain_form:
        return None
    if not MIN_SIZE <= count <= MAX_SHAPER_SIZE:
        raise ValueError(f"shaper size must be from {MIN_SIZE} to {MAX_SHAPER_SIZE}, got {count}")
    with torch.no_grad():
        return shaper.cube_section(lut, count)


def _numbers(values: torch.Tensor) -> str:
    return " ".join(repr(float(v)) for v in values)


def _data_lines(rows: torch.Tensor) -> list:
    """Rows rounded to float32 and printed with ``%.9g``: enough digits to read back bit-exact."""
    array = rows.detach().cpu().float().double().numpy()
    return [f"{r:.9g} {g:.9g} {b:.9g}" for r, g, b in array]


def check_title(title: str, kind: str, forbidden: str = "") -> None:
    """Raise ``ValueError`` unless ``title`` is printable text (no control characters: a carriage return or NUL ends
    or corrupts the line a reader sees) without the ``forbidden`` characters of ``kind``'s syntax.

    Examples:
        >>> check_title("Résumé 2", "cube", '"')
        >>> check_title("shot" + chr(13) + "42", "cube", '"')
        Traceback (most recent call last):
        ...
        ValueError: cube title must be printable text without control characters or '"', got 'shot\\r42'
    """
    if not isinstance(title, str) or not title.isprintable() or any(c in title for c in forbidden):
        besides = f" or {forbidden!r}" if forbidden else ""
        raise ValueError(f"{kind} title must be printable text without control characters{besides}, got {title!r}")


def _write_text(path: str, text: str) -> None:
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(text)
