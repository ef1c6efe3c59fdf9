"""ITU-R BT.2100 ICtCp (PQ) from and to linear Rec.2020 in cd/m², the space in which HDR range
reduction compresses intensity while keeping hue (Dolby, "ICtCp" white paper; ITU-R BT.2100-2 table 7)."""

from __future__ import annotations

import torch

from ..base.planes import apply_matrix
from ..runtime import constant, values_of
from .transfer import linear_to_pq, pq_to_linear

__all__ = ["rec2020_to_ictcp", "ictcp_to_rec2020", "REC2020_TO_LMS", "PQ_LMS_TO_ICTCP"]

REC2020_TO_LMS = torch.tensor(((1688, 2146, 262), (683, 2951, 462), (99, 309, 3688)), dtype=torch.float64) / 4096.0
"""BT.2100's Rec.2020 → LMS cross-talk matrix, in its exact twelfths of 4096."""
PQ_LMS_TO_ICTCP = torch.tensor(((2048, 2048, 0), (6610, -13613, 7003), (17933, -17390, -543)), dtype=torch.float64) / 4096.0
"""BT.2100's L'M'S' (PQ-encoded) → ICtCp matrix."""
_ICTCP_TO_PQ_LMS = torch.linalg.inv(PQ_LMS_TO_ICTCP)
_LMS_TO_REC2020 = torch.linalg.inv(REC2020_TO_LMS)


_VALUES = {"rec2020_to_lms": values_of(REC2020_TO_LMS), "pq_lms_to_ictcp": values_of(PQ_LMS_TO_ICTCP),
           "ictcp_to_pq_lms": values_of(_ICTCP_TO_PQ_LMS), "lms_to_rec2020": values_of(_LMS_TO_REC2020)}
"""The matrices as tuples of floats: device constants (:func:`~torchgrade.runtime.constant`)."""


def _apply(name: str, image: torch.Tensor) -> torch.Tensor:
    return apply_matrix(constant(_VALUES[name], image), image)


def rec2020_to_ictcp(nits: torch.Tensor) -> torch.Tensor:
    """Linear Rec.2020 in cd/m² → ICtCp; LMS below 0 (outside the cone space) is clamped first.

    Examples:
        >>> [round(v, 4) for v in rec2020_to_ictcp(torch.full((3, 1, 1), 100.0)).flatten().tolist()]
        [0.5081, 0.0, 0.0]
    """
    return _apply("pq_lms_to_ictcp", linear_to_pq(_apply("rec2020_to_lms", nits), reference=1.0))


def ictcp_to_rec2020(ictcp: torch.Tensor) -> torch.Tensor:
    """ICtCp → linear Rec.2020 in cd/m², the inverse of :func:`rec2020_to_ictcp` for in-gamut colours.

    Examples:
        >>> [round(v, 3) for v in ictcp_to_rec2020(rec2020_to_ictcp(torch.tensor([50.0, 20.0, 5.0]).reshape(3, 1, 1))).flatten().tolist()]
        [50.0, 20.0, 5.0]
    """
    lms = pq_to_linear(_apply("ictcp_to_pq_lms", ictcp), reference=1.0)
    return _apply("lms_to_rec2020", lms)
