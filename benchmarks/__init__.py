"""torchgrade's benchmarks, each run through one door: ``.venv/bin/python -m benchmarks NAME [--quick] [--out DIR]``.

``python -m benchmarks --list`` names them (:data:`benchmarks.__main__.NAMES`); each writes ``NAME.md`` and
``NAME.json`` (or ``NAME_*`` files, or the folder ``NAME/``) to ``--out``, default ``benchmarks/out`` (git-ignored),
and the committed results to ``benchmarks/results`` only when given ``--out benchmarks/results``.
"""
