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

from .bounded import BoundedControls, fittable_names
from .fit import GLOBAL_CONTROLS, GRADE_CONTROLS, TONEMAP_CANDIDATES, MatchedControls
from .look import LUT_FILES, STAGES, MatchResult, match_look
from .metrics import delta_e_2000, linear_to_lab, match_errors
from .pixels import PixelPairs, sample_pairs
from .residual import ResidualLUT, monotonicity, smoothness

__all__ = [
    "BoundedControls", "fittable_names", "GLOBAL_CONTROLS", "GRADE_CONTROLS", "TONEMAP_CANDIDATES", "MatchedControls", "STAGES", "LUT_FILES",
    "MatchResult", "match_look", "delta_e_2000", "linear_to_lab", "match_errors", "PixelPairs", "sample_pairs",
    "ResidualLUT", "monotonicity", "smoothness",
]
