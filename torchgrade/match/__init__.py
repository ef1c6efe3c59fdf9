"""Learn a look from examples: fit interpretable controls and the tone mapper by Levenberg-Marquardt, and optionally a
residual LUT by gradient descent.

* :mod:`~torchgrade.match.look`: :func:`match_look` and :class:`MatchResult`;
* :mod:`~torchgrade.match.fit`: the fitted model, the staged fit of its controls, tone mapper screening;
* :mod:`~torchgrade.match.solver`: Levenberg-Marquardt with a batched forward-difference Jacobian;
* :mod:`~torchgrade.match.bounded`: controls reparameterised onto their documented ranges;
* :mod:`~torchgrade.match.residual`: :class:`ResidualLUT`, its regularisers and its fit;
* :mod:`~torchgrade.match.pixels`: before/after pairs, masks and the held-out split;
* :mod:`~torchgrade.match.metrics`: 8-bit code errors and CIEDE2000 (in torch).

Examples:
    >>> from torchgrade.match import delta_e_2000, match_look
    >>> callable(match_look)
    True
"""

from .fit import GLOBAL_CONTROLS, GRADE_CONTROLS, TONEMAP_CANDIDATES, MatchedControls
from .look import LUT_FILES, STAGES, MatchResult, match_look
from .metrics import delta_e_2000, linear_to_lab, match_errors
from .residual import ResidualLUT

__all__ = [
    "match_look", "MatchResult", "MatchedControls", "ResidualLUT", "GLOBAL_CONTROLS", "GRADE_CONTROLS",
    "TONEMAP_CANDIDATES", "STAGES", "LUT_FILES", "delta_e_2000", "linear_to_lab", "match_errors",
]
"""What a user calls and what a match returns; the fit's building blocks (bounded controls, pixel pairs, the residual
LUT's penalties) are imported from their modules."""
