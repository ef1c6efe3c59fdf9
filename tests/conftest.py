from pathlib import Path

import pytest
import torch

EXR_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "exr"


@pytest.fixture(scope="session")
def exr_dir() -> Path:
    """The sample OpenEXR images beside the checkout (``../shared/data/exr``); missing data is an error."""
    assert EXR_DIR.is_dir(), f"sample images not found at {EXR_DIR}"
    return EXR_DIR


@pytest.fixture(autouse=True)
def _seed():
    torch.manual_seed(0)
