"""What a call costs at training sizes, where a call's time is its operations' overhead: the operations it dispatches,
counted by a ``TorchDispatchMode`` (:class:`~torchgrade.testing.dispatch.DispatchCount`: views, allocations and
arithmetic on 0-d CPU tensors aside), never timed (``benchmarks/per_call.py`` times the same cases)."""

import pytest
import torch

import torchgrade as tg
from torchgrade.color import safe_sqrt
from torchgrade.testing.dispatch import DispatchCount

GRADE_OPERATIONS = 14
"""A ``ColorGrade(contrast=20, saturation=20)`` call on a batch: the 8-bit check's sample (2), the non-finite policy (2),
LogC contrast as one power between two multiply-adds and a floor (4), the bounds (3), its matrix out with the saturation
folded in (3). 15 when eager without autograd took in-place forms and 21 under autograd, before each formula had one
form."""

LOOK_OPERATIONS = 105
"""A grade and ACES tone map of a one-pixel frame (``PostFX``): the grade's 12 (a frame of three values is no 8-bit
sample), the tone mapper's 93 (its input bounded, not scrubbed of NaN: the grade made it). 103 eager without autograd
and 136 under autograd before each formula had one form."""


def operations(call, *, grad: bool = False) -> DispatchCount:
    """The operations one call of ``call`` dispatches (``grad``: with autograd on), after a first call that builds
    constants."""
    with torch.set_grad_enabled(grad):
        call()
        with DispatchCount() as counted:
            call()
    return counted


@pytest.fixture(scope="module")
def batch():
    return torch.rand(8, 3, 32, 32, generator=torch.Generator().manual_seed(0))


def test_a_grade_of_a_batch_dispatches_fewer_operations_than_kornias_contrast_and_saturation(batch):
    import kornia.enhance

    grade = tg.ColorGrade(contrast=20, saturation=20)
    ours = operations(lambda: grade(batch))
    kornias = operations(lambda: kornia.enhance.adjust_saturation(kornia.enhance.adjust_contrast(batch, 1.2), 1.2))
    assert ours.launches <= GRADE_OPERATIONS, dict(ours.by_operation)
    assert ours.launches < kornias.launches, (dict(ours.by_operation), dict(kornias.by_operation))


def test_a_grade_and_aces_on_one_pixel_stay_within_their_operations():
    look, pixel = tg.PostFX(grade={"contrast": 20, "saturation": 20}, tonemap="aces"), torch.full((1, 3, 1, 1), 0.5)
    counted = operations(lambda: look(pixel))
    assert counted.launches <= LOOK_OPERATIONS, dict(counted.by_operation)
    assert counted.by_operation["nan_to_num"] == 1  # the look's input is scrubbed once


@pytest.mark.parametrize("case", ["grade", "look"])
def test_autograd_dispatches_the_operations_an_inference_call_does(case, batch):
    """One form a formula: the forward that autograd records is the inference forward, operation for operation."""
    module = tg.ColorGrade(contrast=20, saturation=20) if case == "grade" else tg.PostFX(
        grade={"contrast": 20, "saturation": 20}, tonemap="aces")
    image = batch if case == "grade" else batch[:1, :, :1, :1].contiguous()
    trainable = image.clone().requires_grad_()
    inferred = operations(lambda: module(image))
    recorded = operations(lambda: module(trainable), grad=True)
    assert recorded.by_operation == inferred.by_operation


def test_the_guarded_square_root_is_two_operations(batch):
    counted = operations(lambda: safe_sqrt(batch[:, 0]))
    assert dict(counted.by_operation) == {"relu": 1, "sqrt": 1}
