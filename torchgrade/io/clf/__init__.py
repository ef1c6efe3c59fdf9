"""Academy/ASC Common LUT Format (CLF 3.0, SMPTE ST 2136-1) files: :func:`write_clf` states any
:class:`~torchgrade.LUT3D` exactly; :func:`read_clf` reads a creative LUT (a ``LUT3D`` node between optional
``Range`` nodes), as colourists and OpenColorIO write them."""

from .read import MAX_CLF_BYTES, read_clf
from .write import clf_text, write_clf

__all__ = ["MAX_CLF_BYTES", "clf_text", "read_clf", "write_clf"]
