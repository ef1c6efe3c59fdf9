"""Colour grading: Unity's controls in Unity's order (:func:`color_grade`, its steps in :mod:`.steps`), OpenColorIO's
primary grading (:func:`primary_grade`), the curves both use (:mod:`.curves`), and their stages (:mod:`.layer`).

Examples:
    >>> import torch
    >>> from torchgrade.grading import ColorGrade
    >>> ColorGrade(contrast=20)(torch.rand(1, 3, 4, 4)).shape
    torch.Size([1, 3, 4, 4])
"""

from .grade import COLOR_GRADE_CONTROLS, color_grade
from .layer import ColorGrade, PrimaryGrade
from .primary import PRIMARY_GRADE_CONTROLS, STYLES, primary_grade

__all__ = ["ColorGrade", "PrimaryGrade", "color_grade", "primary_grade", "COLOR_GRADE_CONTROLS", "PRIMARY_GRADE_CONTROLS", "STYLES"]
