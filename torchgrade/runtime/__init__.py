"""The execution policy: per device, whole frames or strips, constants kept on the device, and
the compiled form of a look. Every stage asks here; the maths modules decide nothing about devices.

Examples:
    >>> import torch
    >>> import torchgrade as tg
    >>> tg.runtime.policy_for(torch.device("meta")).strip_pixels is None  # a GPU's: whole frames
    True
"""

from .checks import DeferredCheck
from .compile import compile, compile_mode
from .constants import affine, constant, device_cached, folded, scalar, values_of, where
from .recording import is_exporting, is_tracing, untracked
from .policy import ExecutionPolicy, policy_for
from .strips import in_strips, pixelwise

__all__ = ["ExecutionPolicy", "policy_for", "in_strips", "pixelwise", "constant", "scalar", "where", "affine", "values_of", "device_cached", "folded",
           "compile", "compile_mode", "DeferredCheck", "is_tracing", "is_exporting", "untracked"]
