"""A small 3D LUT fitted on top of a matched look, for what its controls cannot express.

The residual LUT takes the look's display-referred output, encoded as sRGB (so its lattice spends
its points evenly over the codes a viewer sees), and returns the corrected display colour. It
starts as the identity and is fitted to the target with two regularisers: smoothness (squared
second differences of the correction along each lattice axis), which also fills lattice points no
pixel reaches, and monotonicity (each output channel must not fall as its own input channel rises),
which keeps gradients and banding out of the correction.

Examples:
    >>> import torch
    >>> residual = ResidualLUT(size=5)
    >>> display = torch.rand(1, 3, 4, 4, dtype=torch.float64)
    >>> bool(torch.allclose(residual(display), display, atol=1e-6))   # starts as the identity
    True
    >>> smoothness(residual.lut.table).item(), monotonicity(residual.lut.table).item()
    (0.0, 0.0)
"""

from __future__ import annotations

import torch
from torch import nn

from tqdm import tqdm

from ..color import linear_to_srgb
from ..lut import LUT3D, identity_table
from ..lut.kernels import KERNELS
from ..lut.lattice import planar_table
from .metrics import display_codes

__all__ = ["ResidualLUT", "smoothness", "monotonicity", "lattice_coordinates", "optimise", "fit_residual"]


class ResidualLUT(nn.Module):
    """``size``³ LUT on sRGB-encoded display values, sRGB entries decoded after the lookup, clamped to [0, 1].

    ``forward(display_linear)`` takes and returns display-referred linear ``(N, 3, H, W)``. The table
    is learnable (:attr:`lut`, a :class:`~torchgrade.LUT3D`).
    """

    display_referred = True

    def __init__(self, size: int = 17, dtype=torch.float64):
        super().__init__()
        self.lut = LUT3D(identity_table(size, dtype), shaper="linear", output_range=(0.0, 1.0),
                         output_encoding="srgb", learnable=True)

    def forward(self, display_linear: torch.Tensor) -> torch.Tensor:
        return self.lut(linear_to_srgb(display_linear.clamp(0.0, 1.0)), "tetrahedral")


def _correction(table: torch.Tensor) -> torch.Tensor:
    return table - identity_table(table.shape[0], table.dtype).to(table.device)


def smoothness(table: torch.Tensor) -> torch.Tensor:
    """Mean squared second difference of the correction (table minus identity) along the three lattice axes.

    Examples:
        >>> smoothness(identity_table(3) * 2.0).item()   # a straight ramp has no curvature
        0.0
    """
    correction = _correction(table)
    total = table.new_zeros(())
    for axis in range(3):
        total = total + torch.diff(correction, n=2, dim=axis).square().mean()
    return total


def monotonicity(table: torch.Tensor) -> torch.Tensor:
    """Mean squared fall of each output channel along its own input axis (zero for a non-decreasing table).

    The table is indexed ``[b, g, r, channel]``: red changes along axis 2, blue along axis 0.

    Examples:
        >>> monotonicity(identity_table(3).flip(2)).item() > 0   # red falling as red rises
        True
    """
    total = table.new_zeros(())
    for channel, axis in ((0, 2), (1, 1), (2, 0)):
        total = total + torch.diff(table[..., channel], dim=axis).neg().clamp_min(0.0).square().mean()
    return total


def lattice_coordinates(display_linear: torch.Tensor, size: int) -> torch.Tensor:
    """The lattice coordinates ``(3, P)`` at which :class:`ResidualLUT` looks up display-linear pixels: their sRGB
    codes times ``size - 1``.

    While the residual is fitted its input (the look's output) does not change, so they are computed once; each step
    looks the table up at them with the tetrahedral kernel (:data:`~torchgrade.lut.kernels.KERNELS`), as
    :class:`ResidualLUT` does, and the gathers' lookup and backward cost less than a sparse matrix's
    (``benchmarks/results/cpu_forms.md``, "residual fit: the lookup and its backward").

    Examples:
        >>> from torchgrade.lut.kernels import KERNELS
        >>> from torchgrade.lut.lattice import planar_table
        >>> display = torch.rand(1, 3, 6, 1, dtype=torch.float64)
        >>> residual = ResidualLUT(5)
        >>> looked_up = KERNELS["tetrahedral"](lattice_coordinates(display, 5), planar_table(residual.lut.table), 5)
        >>> bool(torch.allclose(looked_up.reshape(1, 3, 6, 1), linear_to_srgb(residual(display)), atol=1e-9))
        True
    """
    return linear_to_srgb(display_linear.clamp(0.0, 1.0)).movedim(-3, 0).reshape(3, -1) * (size - 1)


def optimise(module: nn.Module, loss_fn, steps: int, lbfgs_steps: int, lr: float, progress: bool, desc: str) -> dict:
    """Adam for ``steps``, then up to ``lbfgs_steps`` L-BFGS iterations (strong Wolfe line search).

    Returns the loss at every evaluation, in order, by optimiser: ``{"Adam": [one per step], "L-BFGS": [...]}``
    (L-BFGS evaluates a few times per iteration; no ``"L-BFGS"`` without iterations); a module with nothing to fit
    gives ``{"fixed": [its loss]}``.
    ``progress`` shows a tqdm bar (on stderr, when it is a terminal) with the latest loss.
    """
    parameters = [p for p in module.parameters() if p.requires_grad]
    if not parameters:
        with torch.no_grad():
            return {"fixed": [float(loss_fn())]}
    history = []
    with tqdm(total=steps + lbfgs_steps, desc=desc, disable=None if progress else True, leave=False) as bar:

        def closure():
            optimiser.zero_grad()
            loss = loss_fn()
            loss.backward()
            history.append(loss.item())
            bar.set_postfix(loss=f"{history[-1]:.4g}", refresh=False)
            return loss

        optimiser: torch.optim.Optimizer = torch.optim.Adam(parameters, lr=lr)
        for _ in range(steps):
            optimiser.step(closure)
            bar.update()
        if lbfgs_steps:
            # One call runs every iteration: L-BFGS's curvature pairs are only kept within a call.
            optimiser = torch.optim.LBFGS(parameters, lr=1.0, max_iter=lbfgs_steps, history_size=20,
                                          tolerance_grad=1e-12, tolerance_change=1e-14, line_search_fn="strong_wolfe")
            optimiser.step(closure)
            bar.update(lbfgs_steps)
    return {"Adam": history[:steps], **({"L-BFGS": history[steps:]} if lbfgs_steps else {})}


def fit_residual(display: torch.Tensor, target: torch.Tensor, size: int, steps: int, smooth: float, monotone: float,
                 progress: bool) -> tuple:
    """Fit a :class:`ResidualLUT` from the look's display output to the target; ``(residual, losses by optimiser)``.

    The data term is Huber in 8-bit codes (squared within one code, linear beyond), so pixels no smooth correction
    can reach (several sources shown as one clipped display colour, each with its own target) do not bend it
    elsewhere; the table is looked up at the pixels' :func:`lattice_coordinates`, computed once.
    """
    residual = ResidualLUT(size).to(display.device)
    coords = lattice_coordinates(display, size)
    target_codes = display_codes(target).movedim(-3, 0).reshape(3, -1).T
    scale = 255.0**2  # regularisers on the table's [0, 1] units, brought to the data term's squared codes

    def loss_fn():
        table = residual.lut.table
        # Entries are sRGB codes: decoding, clamping to the display and encoding again is a clamp.
        codes = 255.0 * KERNELS["tetrahedral"](coords, planar_table(table), size).T.clamp(0.0, 1.0)
        data = 2.0 * nn.functional.smooth_l1_loss(codes, target_codes, beta=1.0)
        return data + scale * (smooth * smoothness(table) + monotone * monotonicity(table))

    history = optimise(residual, loss_fn, steps // 2, steps - steps // 2, 2e-3, progress, f"residual {size}³")
    return residual, history
