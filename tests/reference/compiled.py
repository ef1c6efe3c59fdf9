"""What a module computes while ``torch.compile`` traces it, run eagerly, and what to compare it by."""

import torch

from torchgrade.runtime import policy_for


def as_compiled(monkeypatch):
    """From here on (the test's ``monkeypatch``), the graph's forms: ``torch.compiler.is_compiling()`` is true, so the
    policy is a compiler's (:attr:`~torchgrade.runtime.ExecutionPolicy.pixel_planes`) and nothing takes eager shortcuts."""
    monkeypatch.setattr(torch.compiler, "is_compiling", lambda: True)
    assert policy_for(torch.device("cpu")).pixel_planes


def outputs_and_gradients(function, image: torch.Tensor) -> tuple:
    """``function(image)`` and the gradient of a fixed random weighting of it with respect to ``image``."""
    image = image.detach().requires_grad_()
    weights = torch.rand(image.shape, dtype=image.dtype, generator=torch.Generator().manual_seed(0))
    out = function(image)
    (gradient,) = torch.autograd.grad((out * weights).sum(), image)
    return out.detach(), gradient
