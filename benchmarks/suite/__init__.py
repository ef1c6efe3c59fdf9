"""The parts of ``benchmarks/run.py``: the workload, the rows, their measurement, the report and the pages' figures.

Run the suite with ``.venv/bin/python -m benchmarks suite [--quick] [--device cpu|cuda] [--out DIR]``; regenerate
the committed results and the pages with ``.venv/bin/python -m benchmarks suite --committed``.
"""
