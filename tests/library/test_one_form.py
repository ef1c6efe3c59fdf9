"""One form per formula: a stage computes the same values eager and while autograd records, bit for bit (the same code
runs; each formula's guards, which keep its gradients finite, are part of its one form)."""

import pytest
import torch

from torchgrade.testing.catalog import STAGE_KINDS


@pytest.fixture(scope="module")
def frame():
    """A frame of every kind of value a stage meets: negatives, 0, denormals, greys, saturated colours, HDR peaks."""
    generator = torch.Generator().manual_seed(0)
    image = torch.rand(2, 3, 40, 56, generator=generator) ** 4 * 30.0
    image[:, :, 0, :8] = torch.tensor([-1.0, 0.0, 1e-40, 0.18, 1.0, 60.0, 1e4, 65504.0])
    image[:, 1:, 1, :] = image[:, :1, 1, :]  # a row of greys
    return image


@pytest.mark.parametrize("name", sorted(STAGE_KINDS))
def test_eager_and_autograd_compute_the_same_values(name, frame):
    stage = STAGE_KINDS[name].example()
    with torch.no_grad():
        eager = stage(frame)
    recorded = stage(frame.clone().requires_grad_())
    assert recorded.requires_grad
    assert torch.equal(recorded.detach(), eager)


def test_every_stage_takes_the_word_of_a_caller_that_knows_its_image_holds_no_nan():
    """``Stage.takes_nan_free`` is declared, not read from a signature: every stage's ``forward`` takes ``nan_free``."""
    import inspect
    import sys

    from torchgrade.base.stage import Stage

    def kinds(base):  # the package's own (a docstring's example stage is not an attribute of its module)
        for kind in base.__subclasses__():
            if getattr(sys.modules[kind.__module__], kind.__qualname__, None) is kind:
                yield kind
            yield from kinds(kind)

    assert len(list(kinds(Stage))) >= 10
    refusing = [kind.__name__ for kind in kinds(Stage) if "nan_free" not in inspect.signature(kind.forward).parameters]
    assert refusing == []
