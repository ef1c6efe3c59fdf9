import os
from pathlib import Path

import pytest
import torch

EXR_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "exr"


def chosen_device() -> torch.device:
    """The device named by ``TG_TEST_DEVICE`` (``cpu`` when unset); naming CUDA on a machine without it is an error."""
    name = os.environ.get("TG_TEST_DEVICE") or "cpu"
    try:
        device = torch.device(name)
    except RuntimeError:
        raise pytest.UsageError(f"TG_TEST_DEVICE must be cpu, cuda or cuda:N, got {name!r}") from None
    if device.type not in ("cpu", "cuda"):
        raise pytest.UsageError(f"TG_TEST_DEVICE must be cpu, cuda or cuda:N, got {name!r}")
    if device.type == "cuda" and not torch.cuda.is_available():
        raise pytest.UsageError(f"TG_TEST_DEVICE={name} but CUDA is not available (torch {torch.__version__}, "
                                f"built with CUDA {torch.version.cuda}); unset it to test on the CPU")
    if device.type == "cuda" and (device.index or 0) >= torch.cuda.device_count():
        raise pytest.UsageError(f"TG_TEST_DEVICE={name} but this machine has {torch.cuda.device_count()} CUDA device(s)")
    return device


def pytest_configure(config):
    chosen_device()  # a wrong TG_TEST_DEVICE stops the run before any test
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    if workers > 1:  # pytest-xdist (`make test`): the cores shared among the workers, not each worker taking them all
        torch.set_num_threads(max(1, torch.get_num_threads() // workers))


def pytest_report_header(config):
    return f"torchgrade test device: {chosen_device()} (TG_TEST_DEVICE)"


@pytest.fixture(scope="session")
def device() -> torch.device:
    """The device the module tests run on: ``TG_TEST_DEVICE`` (``cpu`` by default, ``cuda`` to test on a GPU)."""
    return chosen_device()


@pytest.fixture(scope="session")
def exr_dir() -> Path:
    """The sample OpenEXR images beside the checkout (``../shared/data/exr``); missing data is an error."""
    assert EXR_DIR.is_dir(), f"sample images not found at {EXR_DIR}"
    return EXR_DIR


@pytest.fixture(autouse=True, scope="session")
def _config_home(tmp_path_factory):
    """A folder of the run's as ``XDG_CONFIG_HOME``: a key a test makes (a signed compile cache's) never lands in the
    user's ``~/.config``, for the tests and the processes they start."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("XDG_CONFIG_HOME", str(tmp_path_factory.mktemp("config")))
        yield


@pytest.fixture(autouse=True)
def _seed():
    torch.manual_seed(0)
