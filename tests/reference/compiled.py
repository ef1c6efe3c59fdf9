"""What a module computes while ``torch.compile`` traces it, run eagerly, and what to compare it by."""

import torch


def as_compiled(monkeypatch):
    """From here on (the test's ``monkeypatch``), what a compiler is given: ``torch.compiler.is_compiling()`` is true, so
    a per-pixel stage computes on the image's planes (:func:`~torchgrade.runtime.strips.pixelwise`), on whole frames,
    and no check reads a value."""
    monkeypatch.setattr(torch.compiler, "is_compiling", lambda: True)


def outputs_and_gradients(function, image: torch.Tensor) -> tuple:
    """``function(image)`` and the gradient of a fixed random weighting of it with respect to ``image``."""
    image = image.detach().requires_grad_()
    weights = torch.rand(image.shape, dtype=image.dtype, generator=torch.Generator().manual_seed(0))
    out = function(image)
    (gradient,) = torch.autograd.grad((out * weights).sum(), image)
    return out.detach(), gradient
