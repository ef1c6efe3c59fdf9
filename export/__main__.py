"""``python -m export``: the same as ``python export/export_onnx.py``."""

import sys

from export.export_onnx import main

sys.exit(main())
