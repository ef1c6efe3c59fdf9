"""The package's one compiled part: the CPU loops of the LUT lookup operator (``torchgrade/lut/lookup.c``), a plain
CPython extension on the stable ABI (no torch headers: one build serves every torch and Python >= 3.10), built at
install by setuptools. It is optional: where no C compiler works the install goes on without it and the operator
runs its torch form (``torchgrade.lut.operator`` warns once). Everything else is declared in ``pyproject.toml``."""

import sys

from setuptools import Extension, setup

if sys.platform == "win32":
    COMPILE, LINK = ["/O2", "/openmp"], []
elif sys.platform == "darwin":  # Apple's clang has no -fopenmp: the loops run on one thread
    COMPILE, LINK = ["-O3", "-ffp-contract=off", "-fno-wrapv"], []
else:  # OpenMP binds to the libgomp.so.1 torch has loaded (lookup.c); no -ffast-math, no -march=native. Python's own
    # CFLAGS carry -fwrapv, under which GCC 12 vectorises the 32-bit index arithmetic worse: the same values bit for bit,
    # more slowly (benchmarks/bench_lut_cpu.py); 3 S^3 < 2^31, so no index overflows.
    COMPILE, LINK = ["-O3", "-ffp-contract=off", "-fno-wrapv", "-fopenmp"], ["-fopenmp"]

setup(
    ext_modules=[Extension("torchgrade.lut._lookup", ["torchgrade/lut/lookup.c"], extra_compile_args=COMPILE,
                           extra_link_args=LINK, py_limited_api=True, optional=True)],
    options={"bdist_wheel": {"py_limited_api": "cp310"}},
)
