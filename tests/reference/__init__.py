"""Independent references the tests compare torchgrade with, and the samples and tolerances they share.

Imported as ``reference.<module>``: pytest puts the ``tests`` folder (which has a ``conftest.py`` and
no ``__init__.py``) on ``sys.path``, so test files never import one another.

* :mod:`reference.pixels`: test images as rows of float64 RGB, the extremes every op must survive;
* :mod:`reference.tonemap`: every tone mapper written pixel by pixel from its source;
* :mod:`reference.grade`: Unity's colour grade written pixel by pixel;
* :mod:`reference.onnx`: the shapes, tolerances and frames of the ONNX checks.
"""
