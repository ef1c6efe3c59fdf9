"""The parts of ``benchmarks/run.py``: the workload, the methods, their measurement and the report.

Run the suite with ``.venv/bin/python -m benchmarks suite [--quick] [--device cpu|cuda] [--out DIR]``.
"""
