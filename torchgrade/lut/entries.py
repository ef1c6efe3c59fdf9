"""Fitting a baked LUT's entries to its transform: on a fixed lattice, the table whose largest display error is smallest.

A baked table samples the transform at the lattice points, and interpolation misses it between them,
worst where the picture bends inside a cell. With the lattice fixed, every lookup is a fixed linear
combination of table entries (4 for tetrahedral interpolation, 8 for trilinear), so the entries that
minimise the largest error on a set of colours solve a convex problem; ``benchmarks/lut_floor.py``
solves it exactly as a linear program to prove what no table can reach. :func:`fit_entries` approaches
the same optimum quickly: L-BFGS from the sampled table on the ``p``-norm of the errors, ``p`` growing
through :data:`FIT_POWERS` (the ``p``-norm tends to the max as ``p`` grows), in float64.

Errors are counted as the error report counts them (:func:`~torchgrade.lut.report.code_errors`): 8-bit
sRGB codes of the output clamped to [0, 1]. The fit uses their convex stand-in: where the direct output
is displayed inside (0, 255) codes, the table-unit error times the code slope there (exact for
sRGB-encoded tables, to first order for linear ones); where the display clips it (at 0 or 255 codes),
only a lookup short of the clip costs, so the error is one-sided. Without the stand-in, a lookup past the
clip has no gradient and an entry can stay stuck there.

A fitted table is only as good as the colours it was fitted on: entries no colour reads keep their
sampled values, and colours between the fitted ones may move either way. :func:`fitting_colours` holds
the validation set drawn with another seed than the one the error report's worst case measures, plus the
scene's pixels, so the report of a fitted bake (realistic colours and worst case) is measured on colours the
fit did not see (the scene's pixels excepted: those are the point of fitting to a scene).

Examples:
    >>> import torch
    >>> from torchgrade.lut import bake_lut
    >>> from torchgrade import ColorGrade, ToneMap
    >>> look = torch.nn.Sequential(ColorGrade(contrast=30.0, saturation=20.0), ToneMap("aces"))
    >>> sampled, fitted = (bake_lut(look, size=9, shaper="logc", report_tolerance=float("inf"), entries=entries)
    ...                    for entries in ("sampled", "fitted"))
    >>> fitted.error_report.p99_9 < 0.7 * sampled.error_report.p99_9  # on colours the fit did not see
    True
"""

from __future__ import annotations

import copy
import math
from typing import Optional

import torch

from ..base.images import sanitize
from ..color import linear_to_srgb
from .kernels import KERNELS
from .lattice import planar_table
from .layer import LUT3D
from .apply import decode_output, encode_output
from .shapers import lattice_unit, shaper_encode
from .validation import validation_colours

__all__ = ["fit_entries", "fitting_colours", "scene_pixels", "display_miss", "power_mean", "ANCHOR_WEIGHT", "SCENE_WEIGHT", "FIT_SCENE_PIXELS", "FIT_POWERS", "FIT_ITERATIONS", "FIT_SEED", "ENTRY_CHOICES"]

FIT_POWERS = (2, 8, 32, 128)
"""The ``p`` of each round of :func:`fit_entries`: least squares first, then ever closer to the max."""

FIT_ITERATIONS = 60
"""L-BFGS iterations per round."""

ANCHOR_WEIGHT = 1.0
"""Weight of a lattice point's own error (its entry against the sampled value) beside a validation colour's: the fit
may move an entry up to 1 / ANCHOR_WEIGHT times the largest error it leaves. On the strong look at 17³, no scene, the
largest error on unseen validation colours within the lattice goes 44.3 codes (sampled) -> 32.7 at 1, but 50.2 at 0.25."""

FIT_SCENE_PIXELS = 1 << 18
"""At most this many scene pixels (evenly strided) join a fit: a pixel the fit does not see is the likeliest to stay the worst."""

SCENE_WEIGHT = 4.0
"""Weight of a scene pixel beside a validation colour or a lattice point: the fit serves the scene first and keeps
the table sane elsewhere (benchmarks/results/lut_fit.md measures the trade on the scene's unseen neighbours)."""

FIT_SEED = 1
"""Seed of the validation colours a fit uses; the error report's are drawn with seed 0."""

ENTRY_CHOICES = ("sampled", "fitted")
"""How ``bake_lut(entries=...)`` fills the table: the transform at the lattice points, or :func:`fit_entries`."""


def fitting_colours(lut: LUT3D, transform, scene: Optional[torch.Tensor], hdr: bool,
                    scene_weight: float = SCENE_WEIGHT) -> tuple:
    """``(points (3, N) float64, transform(points) (3, N), weights (N,))`` :func:`fit_entries` fits ``lut`` on:
    validation colours of seed :data:`FIT_SEED` that lie within the lattice, then the scene's pixels (every one up to
    :data:`FIT_SCENE_PIXELS`, evenly strided beyond), wherever they lie, weighing ``scene_weight`` each
    (a validation colour weighs 1).

    A validation colour outside the lattice is looked up at its face, where its error is the domain's doing:
    fitting the face's entries to colours nobody asked for would move them away from the colours inside. A
    scene's pixels are the colours asked for, so the face serves them as well as it can.

    Examples:
        >>> from torchgrade import LUT3D
        >>> from torchgrade.lut import identity_table
        >>> points, reference, weights = fitting_colours(LUT3D(identity_table(2)), lambda x: 2 * x, None, hdr=False)
        >>> points.shape[0], torch.equal(reference, 2 * points), bool((weights == 1).all())
        (3, True, True)
    """
    colours = validation_colours(hdr, seed=FIT_SEED)
    colours = colours[:, _inside_lattice(lut, colours)]
    weights = torch.ones(colours.shape[1], dtype=torch.float64)
    if scene is not None:
        pixels = scene_pixels(scene)
        colours = torch.cat((colours, pixels), dim=1)
        weights = torch.cat((weights, torch.full((pixels.shape[1],), scene_weight, dtype=torch.float64)))
    with torch.no_grad():
        return colours, transform(colours.reshape(1, 3, 1, -1)).double().reshape(3, -1), weights


def scene_pixels(scene: torch.Tensor) -> torch.Tensor:
    """The scene's pixels a fit sees, ``(3, N)`` float64: every one up to :data:`FIT_SCENE_PIXELS`, evenly strided
    beyond, after the non-finite policy.

    Examples:
        >>> import torch
        >>> scene_pixels(torch.ones(1, 3, 2, 2)).shape
        torch.Size([3, 4])
    """
    pixels = sanitize(scene.detach().double()).movedim(-3, 0).reshape(3, -1)
    return pixels[:, :: max(1, -(-pixels.shape[1] // FIT_SCENE_PIXELS))]


@torch.enable_grad()  # the fit runs on gradients, also when called inside torch.no_grad()
def fit_entries(lut: LUT3D, transform, scene: Optional[torch.Tensor] = None, hdr: bool = True,
                interpolation: str = "tetrahedral", scene_weight: float = SCENE_WEIGHT,
                anchor_weight: float = ANCHOR_WEIGHT, powers=FIT_POWERS, iterations: int = FIT_ITERATIONS) -> LUT3D:
    """A copy of ``lut`` (baked from ``transform``) whose entries minimise the largest display error.

    The colours are :func:`fitting_colours` (``hdr=False``: validation colours up to 1) and the lattice
    points, each held to its sampled value with ``anchor_weight`` (a validation colour weighs 1, a scene
    pixel ``scene_weight``), so that the table cannot drift where no colour looks. Heavier scene pixels let the
    fit serve the scene's own pixels better and their neighbours worse (benchmarks/results/lut_fit.md measures the trade). The lattice (shaper, domain, curve) and the table's dtype
    are ``lut``'s. See the module docstring for the objective; ``interpolation`` is the lookup the table
    is fitted for.

    Examples:
        >>> from torchgrade.lut import bake_lut
        >>> reinhard = lambda x: x.clamp_min(0) / (1 + x.clamp_min(0))
        >>> lut = bake_lut(reinhard, size=9, shaper="logc", report_tolerance=float("inf"))
        >>> fit_entries(lut, reinhard).table.shape
        torch.Size([9, 9, 9, 3])
    """
    points, reference, weights = fitting_colours(lut, transform, scene, hdr, scene_weight)
    sampled = planar_table(lut.table.detach().double())
    nodes = _node_coords(lut.size, sampled.device)
    coords = torch.cat((_lattice_coords(lut, points), nodes), dim=1)
    references = torch.cat((reference, decode_output(sampled, lut.output_encoding)), dim=1)
    target, slope, below, above = _targets(references, lut.output_encoding)
    slope *= torch.cat((weights, torch.full((nodes.shape[1],), anchor_weight, dtype=torch.float64)))
    rows = sampled.clone().requires_grad_(True)
    kernel = KERNELS[interpolation]
    for power in powers:
        optimizer = torch.optim.LBFGS([rows], max_iter=iterations, history_size=20, line_search_fn="strong_wolfe")

        def closure(optimizer=optimizer, power=power) -> torch.Tensor:
            optimizer.zero_grad()
            loss = power_mean(display_miss(kernel(coords, rows, lut.size), target, slope, below, above), power)
            loss.backward()
            return loss

        optimizer.step(closure)
    fitted = copy.deepcopy(lut)
    fitted.table = rows.detach().t().reshape(lut.table.shape).to(lut.table.dtype)
    return fitted


def power_mean(errors: torch.Tensor, power: float) -> torch.Tensor:
    """``(mean(e^p))^(1/p)`` of non-negative ``errors``, by log-sum-exp so that neither a large ``p`` nor errors of 0
    overflow, underflow or give a NaN gradient (errors are floored at 1e-12 of their largest).

    Examples:
        >>> import torch
        >>> e = torch.tensor([0.0, 1.0, 2.0], dtype=torch.float64)
        >>> round(float(power_mean(e, 2)), 6), round(float(power_mean(e, 10000)), 3)
        (1.290994, 2.0)
    """
    scale = errors.detach().max().clamp_min(torch.finfo(errors.dtype).tiny)
    logs = power * torch.log(errors / scale + 1e-12)
    return scale * torch.exp((torch.logsumexp(logs.flatten(), 0) - math.log(errors.numel())) / power)


def display_miss(values: torch.Tensor, target: torch.Tensor, slope: torch.Tensor, below: torch.Tensor,
                 above: torch.Tensor) -> torch.Tensor:
    """The fit's convex stand-in for the displayed error of table ``values`` against ``target`` (table units):
    ``slope |v - t|``, only ``slope max(v - t, 0)`` where the display clips the target at black (``below``) and
    only ``slope max(t - v, 0)`` where it clips it at white (``above``).

    Examples:
        >>> import torch
        >>> t, k = torch.tensor([0.5, 0.0, 1.0], dtype=torch.float64), torch.full((3,), 255.0, dtype=torch.float64)
        >>> display_miss(torch.tensor([0.75, -0.2, 1.3], dtype=torch.float64), t, k, torch.tensor([False, True, False]),
        ...              torch.tensor([False, False, True])).tolist()
        [63.75, 0.0, 0.0]
    """
    miss = values - target
    return slope * torch.where(below, miss.clamp_min(0.0), torch.where(above, (-miss).clamp_min(0.0), miss.abs()))


def _inside_lattice(lut: LUT3D, points: torch.Tensor) -> torch.Tensor:
    """``(N,)`` bool: which linear ``(3, N)`` points lie within ``lut``'s lattice domain on every channel."""
    codes = shaper_encode(points, lut.shaper, None if lut.curve is None else lut.curve.double(), lut.curve_range)
    low, high = (bound.double().reshape(-1, 1) for bound in (lut.domain_min, lut.domain_max))
    return ((codes >= low) & (codes <= high)).all(dim=0)


def _lattice_coords(lut: LUT3D, points: torch.Tensor) -> torch.Tensor:
    """Lattice coordinates ``(3, N)`` in [0, S - 1], float64, of linear ``(3, N)`` points, as ``lut``'s lookup finds them."""
    unit = lattice_unit(sanitize(points), lut.shaper, lut.domain_min.double(), lut.domain_max.double(),
                        None if lut.curve is None else lut.curve.double(), lut.curve_range)
    return unit * (lut.size - 1)


def _node_coords(size: int, device) -> torch.Tensor:
    """Coordinates ``(3, S³)`` of the lattice points, in flat index order ``r + S g + S² b``."""
    axis = torch.arange(size, dtype=torch.float64, device=device)
    b, g, r = torch.meshgrid(axis, axis, axis, indexing="ij")
    return torch.stack((r.flatten(), g.flatten(), b.flatten()))


def _targets(reference: torch.Tensor, encoding: str) -> tuple:
    """Per value: the table entry that displays ``reference`` (clamped to [0, 1]), 8-bit codes per table unit
    there, and whether the display clips it at black or at white."""
    shown = reference.clamp(0.0, 1.0)
    target = encode_output(shown, encoding).detach().requires_grad_(True)
    codes = 255.0 * linear_to_srgb(decode_output(target, encoding))
    (slope,) = torch.autograd.grad(codes.sum(), target)
    return target.detach(), slope, reference <= 0.0, reference >= 1.0
