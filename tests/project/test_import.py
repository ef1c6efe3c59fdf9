"""What ``import torchgrade`` loads beside what ``import torch`` loaded: torchgrade's own modules and the standard
library's, nothing else. ONNX and onnxruntime, the OpenEXR bindings, kornia, Pillow, SciPy and the subpackages behind
them (file formats, export, integrations, test support) load at the first call that needs them. Counted in a fresh
process, not timed (``benchmarks/bench_import.py`` times the import)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import torchgrade
from benchmarks.bench_import import LOADED_AT_FIRST_USE

ROOT = Path(__file__).resolve().parents[2]

_IMPORT = """
import json, sys
import torch
before = set(sys.modules)
import torchgrade
print(json.dumps({"new": sorted(set(sys.modules) - before), "all": sorted(sys.modules)}))
"""


def test_import_torchgrade_loads_its_own_modules_and_the_standard_library_only():
    result = subprocess.run([sys.executable, "-c", _IMPORT], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    loaded = json.loads(result.stdout.strip().splitlines()[-1])
    others = {name.split(".")[0] for name in loaded["new"]} - {"torchgrade"} - set(sys.stdlib_module_names)
    assert sorted(others) == []
    at_first_use = [name for name in loaded["all"]
                    if any(name == first or name.startswith(first + ".") for first in LOADED_AT_FIRST_USE)]
    assert at_first_use == []
    lazy = [f"torchgrade.{name}" for name in torchgrade._LAZY_MODULES]
    assert [name for name in loaded["new"] if name in lazy] == []
