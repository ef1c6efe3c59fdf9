"""ColorGrade as a compiler is given it, run eagerly: its steps on the image's planes (what
:func:`~torchgrade.runtime.strips.pixelwise` gives a stage while compiling), its curves and tensor split-toning colours
on the joined image. Against the float64 re-implementation of Unity's
ColorGrade and against the eager forms, in outputs and gradients. (That Inductor fuses it: ``tests/runtime/test_gpu_path.py``.)"""

import numpy as np
import pytest
import torch

import torchgrade as tg

from reference.compiled import as_compiled, outputs_and_gradients
from reference.grade import sample_pixels, unity_grade, unity_grade_pixel
from reference.pixels import pixels, rows
from test_grade import LOOKS, extremes_image
from test_grade_parity import EARLY, TAIL_LOOKS, unity_tail_pixel


@pytest.mark.parametrize("aces", [False, True], ids=["linear", "aces"])
@pytest.mark.parametrize("look", sorted(LOOKS))
def test_as_compiled_matches_unity_color_grade_reference(monkeypatch, look, aces):
    as_compiled(monkeypatch)
    rgb = sample_pixels()
    ours = rows(tg.ColorGrade(aces=aces, **LOOKS[look])(pixels(rgb)))
    np.testing.assert_allclose(ours, unity_grade(rgb, aces, **LOOKS[look]), rtol=1e-9, atol=1e-9)


EXTREME_GRADES = {**{look: LOOKS[look] for look in ("everything", "split", "saturation")},
                  **{f"early+{look}": dict(EARLY, **TAIL_LOOKS[look]) for look in ("lift_gamma_gain", "everything")}}
"""Grades with every step on planes (and, in ``early+everything``, curves on the joined image) for the extremes."""


@pytest.mark.parametrize("look", sorted(EXTREME_GRADES))
@pytest.mark.parametrize("aces", [False, True], ids=["linear", "aces"])
def test_as_compiled_equals_eager_on_extremes_in_outputs_and_gradients(monkeypatch, look, aces):
    grade = tg.ColorGrade(aces=aces, **EXTREME_GRADES[look])
    image = extremes_image(torch.float64)
    eager = outputs_and_gradients(grade, image)
    as_compiled(monkeypatch)
    compiled = outputs_and_gradients(grade, image)
    for ours, theirs in zip(compiled, eager):
        assert torch.isfinite(ours).all()
        torch.testing.assert_close(ours, theirs, rtol=1e-9, atol=1e-9)


def test_as_compiled_takes_per_sample_and_tensor_controls(monkeypatch):
    """Per-sample gains, a tensor split-toning colour (blended on the joined image) and learnable controls, whose
    gradients match eager's too."""
    image = torch.rand(3, 3, 5, 4, dtype=torch.float64, generator=torch.Generator().manual_seed(1)) * 4

    def graded():
        contrast = torch.nn.Parameter(torch.tensor([-20.0, 0.0, 40.0], dtype=torch.float64))
        tint = torch.tensor([[1.0, 0.9, 0.8], [1.0, 1.0, 1.0], [0.7, 0.8, 1.0]], dtype=torch.float64)
        shadows = torch.nn.Parameter(torch.tensor([0.3, 0.5, 0.7], dtype=torch.float64))
        grade = tg.ColorGrade(aces=True, contrast=contrast, color_filter=tint, split_shadows=shadows, saturation=25.0)
        out = grade(image)
        return (out, *torch.autograd.grad(out.square().sum(), (grade.contrast, grade.split_shadows)))

    eager = graded()
    as_compiled(monkeypatch)
    for ours, theirs in zip(graded(), eager):
        torch.testing.assert_close(ours.detach(), theirs.detach(), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("look", sorted(TAIL_LOOKS))
def test_as_compiled_matches_unity_lift_gamma_gain_and_curves_reference(monkeypatch, look):
    """Lift/gamma/gain, zones and hue shift on planes, curves on the joined image, after the early steps."""
    as_compiled(monkeypatch)
    rgb = sample_pixels()
    ours = rows(tg.ColorGrade(**EARLY, **TAIL_LOOKS[look])(pixels(rgb)))
    expected = [unity_tail_pixel(unity_grade_pixel(c, **EARLY), **TAIL_LOOKS[look]) for c in rgb]
    np.testing.assert_allclose(ours, expected, rtol=1e-9, atol=1e-9)
