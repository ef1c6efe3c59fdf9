"""Hostile input, tried in a child process with a memory cap: what it cost, and how it ended.

:func:`run_bounded` runs Python statements in a fresh interpreter whose address space may grow by ``cap_bytes`` over
what it holds after ``import torchgrade`` (a reader that allocates past that fails there, not on the machine), and
returns the CPU seconds the statements took (``time.process_time``: the work done, which a busy machine does not
stretch as it stretches the wall clock), the peak resident memory they added and their outcome: the value of
``result`` they set, or the exception's ``"Type: message"`` (shortened). The timeout only stops a child that hangs
(a reader waiting on a pipe).

Imported as ``from bounded import run_bounded``: pytest puts the ``tests`` folder on ``sys.path``.
"""

import json
import subprocess
import sys

CHILD = r"""
import json, resource, sys, time
import torch, torchgrade as tg

def status(key):
    return int(next(line for line in open("/proc/self/status") if line.startswith(key)).split()[1]) * 1024

code, cap = sys.argv[1], int(sys.argv[2])
resource.setrlimit(resource.RLIMIT_AS, (status("VmSize") + cap, resource.RLIM_INFINITY))
with open("/proc/self/clear_refs", "w") as clear:
    clear.write("5")  # the peak (VmHWM) starts again at the resident size
before, started = status("VmRSS"), time.process_time()
scope = {"tg": tg, "torch": torch}
try:
    exec(code, scope)
    outcome = repr(scope.get("result"))[:2000]
except BaseException as error:
    outcome = f"{type(error).__name__}: {str(error)[:2000]}"
print(json.dumps([time.process_time() - started, status("VmHWM") - before, outcome]))
"""


def run_bounded(code: str, cap_bytes: int = 1 << 30, timeout: float = 60.0) -> tuple:
    """``(CPU seconds, peak bytes added, outcome)`` of ``code`` run in a child process (see the module docstring).

    A child that overruns ``timeout`` is killed and reported as ``(timeout, None, "timed out")``.
    """
    try:
        done = subprocess.run([sys.executable, "-c", CHILD, code, str(cap_bytes)], capture_output=True, text=True,
                              timeout=timeout)
    except subprocess.TimeoutExpired:
        return timeout, None, "timed out"
    if done.returncode != 0 or not done.stdout.strip():
        return None, None, f"child failed ({done.returncode}): {done.stderr[-2000:]}"
    seconds, peak, outcome = json.loads(done.stdout.strip().splitlines()[-1])
    return seconds, peak, outcome
