"""``tg.onnx.verify`` on onnxruntime: every look, eye adaptation included, fed as its file expects (``adapted`` and
``dt`` optional or plain inputs), and a ``ValueError`` naming what is wrong with a call that cannot be verified."""

import pytest
import torch

import torchgrade as tg
from torchgrade.onnx import export, verify

from reference.onnx import SHAPES, TOLERANCE, hdr

ADAPTING = dict(exposure={"speed": 2.0, "metering": "histogram"}, grade={"contrast": 15}, tonemap="neutral")
"""A look with eye adaptation, as a newcomer writes one."""


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The adapting look exported with optional state inputs (the default) and with plain ones, and a still look."""
    folder = tmp_path_factory.mktemp("verify")
    look, still = tg.PostFX(**ADAPTING), tg.PostFX(grade={"contrast": 15}, tonemap="neutral")
    return {
        "look": look,
        "still": still,
        "optional": export(look, folder / "optional.onnx"),
        "plain": export(look, folder / "plain.onnx", optional_inputs=False),
        "still-file": export(still, folder / "still.onnx"),
    }


@pytest.mark.parametrize("form", ["optional", "plain"])
@pytest.mark.parametrize("shape", SHAPES, ids=["batch-1", "batch-3"])
def test_a_look_with_eye_adaptation_verifies_from_the_image_alone(files, form, shape):
    assert verify(files["look"], files[form], hdr(shape)) <= TOLERANCE


@pytest.mark.parametrize("form", ["optional", "plain"])
def test_a_look_with_eye_adaptation_verifies_with_its_state(files, form):
    shape = SHAPES[1]
    adapted = torch.linspace(0.0, 1.0, shape[0])  # the first sample starts a sequence, the others adapt from a state
    assert verify(files["look"], files[form], (hdr(shape), adapted, 0.1)) <= TOLERANCE


def test_verify_tells_another_look_from_the_one_exported(files):
    other = tg.PostFX(**{**ADAPTING, "grade": {"contrast": 40}})
    assert verify(other, files["optional"], hdr(SHAPES[0])) > 100 * TOLERANCE


def test_a_file_that_is_missing_or_no_model_is_named(files, tmp_path):
    missing = tmp_path / "missing.onnx"
    with pytest.raises(ValueError, match=f"no ONNX file at '{missing}'"):
        verify(files["look"], missing, hdr(SHAPES[0]))
    garbage = tmp_path / "garbage.onnx"
    garbage.write_bytes(b"not a model")
    with pytest.raises(ValueError, match="is not an ONNX model onnxruntime can load"):
        verify(files["look"], garbage, hdr(SHAPES[0]))


@pytest.mark.parametrize("module, file, message", [
    ("still", "optional", "the file takes adapted and dt .* but the module has no exposure stage"),
    ("look", "still-file", "the module has an exposure stage but the file takes no adapted and dt"),
], ids=["still-module", "still-file"])
def test_a_module_and_a_file_of_different_looks_are_refused(files, module, file, message):
    with pytest.raises(ValueError, match=message):
        verify(files[module], files[file], hdr(SHAPES[0]))


@pytest.mark.parametrize("inputs, error, message", [
    (torch.rand(1, 2, 8, 8), ValueError, r"3 colour channels, got \(1, 2, 8, 8\)"),
    (torch.rand(1, 4, 8, 8), ValueError, r"3 colour channels, got \(1, 4, 8, 8\)"),
    (torch.rand(3, 8, 8), ValueError, r"image must be a batch, \(batch, 3, height, width\), got \(3, 8, 8\)"),
    (torch.rand(1, 3, 0, 8), ValueError, "image is empty"),
    (torch.zeros(1, 3, 8, 8, dtype=torch.uint8), TypeError, r"srgb_to_linear\(image.float\(\) / 255\)"),
    ((torch.rand(2, 3, 8, 8), torch.zeros(3), 0.1), ValueError, r"adapted must have shape \(2,\)"),
    ((torch.rand(2, 3, 8, 8), torch.zeros(2), torch.zeros(2)), ValueError, "dt be a scalar"),
    ((torch.rand(2, 3, 8, 8), "dark", 0.1), ValueError, "adapted and dt must be numbers or tensors, got str"),
    ((torch.rand(2, 3, 8, 8), torch.zeros(2)), ValueError, r"the look takes \(image,\) or \(image, adapted, dt\); got 2 inputs"),
], ids=["2-channels", "4-channels", "no-batch", "empty", "uint8", "adapted-shape", "dt-shape", "adapted-type", "two-inputs"])
def test_a_wrong_input_is_named(files, inputs, error, message):
    with pytest.raises(error, match=message):
        verify(files["look"], files["optional"], inputs)
