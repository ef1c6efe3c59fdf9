"""Colour science on ``(..., 3, H, W)`` tensors: luminance, sRGB, LogC, ACES, LMS, HSV, primaries
and display encodings (PQ, HLG), ICtCp.

All functions are differentiable and safe: no NaN or Inf in outputs or gradients at 0, at grey
pixels (undefined hue), or at very large values. Branches are computed with ``torch.where`` on
guarded arguments, so the branch not taken never produces an infinite gradient.

Constants are Unity's (``com.unity.render-pipelines.core/ShaderLibrary/Color.hlsl`` and
``ACES.hlsl``), so grades typed in from Unity's inspector reproduce Unity's numbers; the primaries
and display encodings are the standards' (ITU-R BT.2020 and BT.2100, SMPTE ST 2084 and EG 432-1, Academy
S-2016-001).
"""

from .hsv import *  # noqa: F401,F403
from .hsv import __all__ as _hsv_names
from .ictcp import *  # noqa: F401,F403
from .ictcp import __all__ as _ictcp_names
from .spaces import *  # noqa: F401,F403
from .spaces import __all__ as _space_names
from .transfer import *  # noqa: F401,F403
from .transfer import __all__ as _transfer_names

__all__ = [*_space_names, *_transfer_names, *_hsv_names, *_ictcp_names]
