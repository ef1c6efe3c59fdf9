"""What a call costs at training sizes, where the frame is small and a call is mostly its overhead: a grade against
kornia's contrast and saturation on a batch of 8x3x32x32, a grade and ACES tone map of a one-pixel frame, and the
guarded square root against ``torch.sqrt``.

    python -m benchmarks per_call [--quick] [--threads N] [--out DIR]

Each case times a loop of calls (a call takes microseconds, a timer's resolution less), the compared calls
alternating round by round (:func:`benchmarks.common.interleaved_ms`); it reports the median time of a call and the
median over rounds of the ratio to its peer, the operations one call dispatches
(:class:`torchgrade.testing.dispatch.DispatchCount`, what ``tests/runtime/test_per_call.py`` holds) and the Python
functions it enters (the interpreter's share, which no operation count shows). Writes
``per_call.json`` and ``per_call.md`` to ``--out`` (default ``benchmarks/out``; the committed ones with
``--out benchmarks/results``).
"""

from __future__ import annotations

import statistics
import sys

import torch

import torchgrade as tg
from benchmarks.common import argument_parser, interleaved_ms, median_ratio, write_results
from torchgrade.color import safe_sqrt
from torchgrade.testing.dispatch import DispatchCount

QUICK = "3 rounds of 20 calls instead of 15 rounds of 200"
COMMAND = "python -m benchmarks per_call --out DIR"
TARGETS = {"grade 8x3x32x32": "at most 1.5 times kornia's", "grade + ACES, one pixel": "at most 0.5 ms",
           "safe_sqrt 8x32x32": "near torch.sqrt's"}
"""What each case is held to (the issue's targets; the time is the machine's, so these are read, not tested)."""


def cases() -> dict:
    """``name -> (ours, peer or None, peer's name)``: each a call of no arguments."""
    import kornia.enhance

    batch = torch.rand(8, 3, 32, 32, generator=torch.Generator().manual_seed(0))
    grade = tg.ColorGrade(contrast=20, saturation=20)
    pixel = torch.rand(1, 3, 1, 1, generator=torch.Generator().manual_seed(1)) * 4
    look = tg.PostFX(grade={"contrast": 20, "saturation": 20}, tonemap="aces")
    planes = torch.rand(8, 32, 32, generator=torch.Generator().manual_seed(2))

    def jiggled():  # kornia's contrast and saturation factors for Unity's 20 (1 + 20 / 100)
        return kornia.enhance.adjust_saturation(kornia.enhance.adjust_contrast(batch, 1.2), 1.2)

    return {
        "grade 8x3x32x32": (lambda: grade(batch), jiggled, "kornia adjust_contrast + adjust_saturation"),
        "grade + ACES, one pixel": (lambda: look(pixel), None, ""),
        "safe_sqrt 8x32x32": (lambda: safe_sqrt(planes), lambda: torch.sqrt(planes), "torch.sqrt"),
    }


def repeated(call, times: int):
    """``call`` run ``times`` times: one timed call of the loop."""
    def run():
        for _ in range(times):
            call()
    return run


def measure(quick: bool) -> list:
    """One row a case: µs a call of ours and of its peer, the median ratio, and the operations a call dispatches."""
    rounds, times = (3, 20) if quick else (15, 200)
    rows = []
    for name, (ours, peer, peer_name) in cases().items():
        calls = {"ours": repeated(ours, times), **({"peer": repeated(peer, times)} if peer else {})}
        timed = interleaved_ms(calls, rounds)
        row = {"case": name, "target": TARGETS[name], "ours_us": round(statistics.median(timed["ours"]) * 1000 / times, 1),
               "operations": _operations(ours), "python_calls": _python_calls(ours)}
        if peer:
            row.update(peer=peer_name, peer_us=round(statistics.median(timed["peer"]) * 1000 / times, 1),
                       peer_operations=_operations(peer), peer_python_calls=_python_calls(peer),
                       ours_over_peer=round(median_ratio(timed, "ours", "peer"), 2))
        rows.append(row)
        print(row, flush=True)
    return rows


def _operations(call) -> int:
    """The operations one call of ``call`` dispatches (after a first call, which builds constants)."""
    with torch.no_grad():
        call()
        with DispatchCount() as counted:
            call()
    return counted.launches


def _python_calls(call) -> int:
    """The Python functions one call of ``call`` enters (after a first call), counted by ``sys.setprofile``: the
    interpreter's share of a small call, which the operations' count leaves out."""
    entered = 0

    def count(frame, event, arg):
        nonlocal entered
        entered += event == "call"

    with torch.no_grad():
        call()
        sys.setprofile(count)
        try:
            call()
        finally:
            sys.setprofile(None)
    return entered


def main(argv=None) -> int:
    parser = argument_parser(__doc__, QUICK)
    parser.add_argument("--threads", type=int, help="torch's intra-op threads (default: torch's own; a DataLoader worker runs 1)")
    args = parser.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    rows = measure(args.quick)
    lines = ["# A call at training sizes", "",
             f"`{COMMAND}`{' --quick' if args.quick else ''}: median µs a call over alternating rounds "
             f"({torch.get_num_threads()} torch threads), the ratio the median over rounds of the two calls' times; "
             "operations: those one call dispatches (`torchgrade.testing.dispatch.DispatchCount`); Python calls: the "
             "Python functions it enters (`sys.setprofile`).", "",
             "| case | target | ours µs | operations | Python calls | peer | peer µs | peer operations | peer Python calls | ours / peer |",
             "| --- | --- | ---: | ---: | ---: | --- | ---: | ---: | ---: | ---: |"]
    for row in rows:
        lines.append(f"| {row['case']} | {row['target']} | {row['ours_us']} | {row['operations']} | {row['python_calls']} | "
                     f"{row.get('peer', '')} | {row.get('peer_us', '')} | {row.get('peer_operations', '')} | "
                     f"{row.get('peer_python_calls', '')} | {row.get('ours_over_peer', '')} |")
    args.out.mkdir(parents=True, exist_ok=True)
    write_results(args.out, "per_call", {"command": COMMAND, "quick": args.quick, "rows": rows}, lines, COMMAND)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
