"""A fresh user's install of this checkout. The wheel that the package's build makes carries the LUT lookup's C loop
(``setup.py``), and in a fresh environment with no C compiler on ``PATH`` the operator runs it: nothing is compiled at
the first lookup, nothing is loaded from a cache or written to one. Built where no C compiler works (``CC=false``),
the package still installs, and its lookups run the torch form with one warning.

Each case builds a wheel (``pip wheel --no-build-isolation``, about 10 s on a loaded 2-core machine, most of it pip's)
and installs it into a new virtual environment that reaches torch and the other dependencies through this
environment's site-packages (a ``.pth`` line: this environment's editable install is not processed there)."""

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

FIRST_LOOKUPS = """
import json, shutil, warnings
import torch
import torchgrade
from torchgrade.lut import LUT3D, identity_table, operator
from torchgrade.lut.apply import lookup
from torchgrade.lut.lattice import planar_table

table = torch.rand(9, 9, 9, 3, generator=torch.Generator().manual_seed(0))
image = torch.rand(1, 3, 16, 24, generator=torch.Generator().manual_seed(1)) * 1.2 - 0.1
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    first, second = LUT3D(table)(image), LUT3D(table)(image)
expected = lookup(image, planar_table(table), 9, "linear", 0.0, 1.0, "tetrahedral", None, None, (0.0, 1.0), "linear")
print(json.dumps({"package": torchgrade.__file__, "native": getattr(operator.NATIVE, "__file__", None),
                  "compiler": shutil.which("cc") or shutil.which("gcc") or shutil.which("clang"),
                  "warnings": [str(w.message) for w in caught], "equal": torch.equal(first, second),
                  "error": (first - expected).abs().max().item()}))
"""


def build_wheel(folder: Path, environment: dict) -> Path:
    """The wheel of this checkout's package, built in ``folder`` from a copy of its sources (no extension built in
    place comes along) with ``environment``."""
    source = folder / "source"
    source.mkdir()
    for name in ("pyproject.toml", "setup.py", "README.md"):
        shutil.copy(ROOT / name, source / name)
    shutil.copytree(ROOT / "torchgrade", source / "torchgrade", ignore=shutil.ignore_patterns("*.so", "*.pyd", "__pycache__"))
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--no-build-isolation", "--wheel-dir",
                    str(folder / "dist"), str(source)], env=environment, check=True, capture_output=True, text=True)
    return next((folder / "dist").glob("torchgrade-*.whl"))


def first_lookups(folder: Path, wheel: Path) -> dict:
    """What :data:`FIRST_LOOKUPS` reports in a fresh environment holding ``wheel``, with nothing on ``PATH`` and a home
    and cache folder of its own (which must stay empty)."""
    env = folder / "env"
    venv.create(env, with_pip=False)
    python = env / "bin" / "python"
    site = Path(subprocess.run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               capture_output=True, text=True, check=True).stdout.strip())
    (site / "dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-index", "--target", str(site), str(wheel)],
                   check=True, capture_output=True, text=True)
    home, empty = folder / "home", folder / "bin"
    home.mkdir()
    empty.mkdir()
    done = subprocess.run([python, "-c", FIRST_LOOKUPS], cwd=folder, capture_output=True, text=True, check=True,
                          env={"PATH": str(empty), "HOME": str(home), "XDG_CACHE_HOME": str(home / ".cache")})
    assert not any(home.iterdir()), "the first lookups wrote to the user's home"
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert Path(report["package"]).is_relative_to(site)  # the installed wheel ran, not this checkout
    return report


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel the package's build makes where a C compiler works."""
    return build_wheel(tmp_path_factory.mktemp("wheel"), dict(os.environ))


def test_the_wheel_carries_the_package_type_hints_and_the_compiled_loop_stub(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    assert {"torchgrade/py.typed", "torchgrade/lut/_lookup.pyi"} <= names  # PEP 561: type checkers read the hints
    assert any(name.startswith("torchgrade/lut/_lookup.") and name.endswith((".so", ".pyd")) for name in names)


@pytest.mark.skipif(sys.platform != "linux", reason="platform-conditional: the fresh environment's layout is Linux's")
def test_a_fresh_user_without_a_compiler_gets_the_compiled_loop_from_the_wheel(wheel, tmp_path):
    assert "abi3" in wheel.name  # one build for every Python from 3.10 and every torch
    report = first_lookups(tmp_path, wheel)
    assert report["compiler"] is None
    assert report["native"] is not None and Path(report["native"]).is_relative_to(Path(report["package"]).parent)
    assert report["warnings"] == [] and report["equal"]
    assert report["error"] < 1e-6


@pytest.mark.skipif(sys.platform != "linux", reason="platform-conditional: the fresh environment's layout is Linux's")
def test_a_build_without_a_compiler_installs_and_looks_up_in_the_torch_form_with_one_warning(tmp_path):
    wheel = build_wheel(tmp_path, {**os.environ, "CC": "false"})
    report = first_lookups(tmp_path, wheel)
    assert report["native"] is None
    assert len(report["warnings"]) == 1 and "without its compiled LUT loop" in report["warnings"][0]
    assert report["equal"] and report["error"] == 0.0  # the torch form itself
