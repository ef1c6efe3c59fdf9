"""What a module computes while ``torch.compile`` traces it, run eagerly."""

import torch

from torchgrade.runtime import policy_for


def as_compiled(monkeypatch):
    """From here on (the test's ``monkeypatch``), the graph's forms: ``torch.compiler.is_compiling()`` is true, so the
    policy is a compiler's (:attr:`~torchgrade.runtime.ExecutionPolicy.pixel_planes`) and nothing takes eager shortcuts."""
    monkeypatch.setattr(torch.compiler, "is_compiling", lambda: True)
    assert policy_for(torch.device("cpu")).pixel_planes
