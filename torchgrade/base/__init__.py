"""The base every stage is built on: image checks, parameter broadcasting and the dtype policy (:mod:`.core`), the
``Stage`` base and its table of controls (:mod:`.stage`), and configs read within bounds (:mod:`.config`).

Write a stage of your own on :class:`Stage` and :class:`Control` (see :mod:`torchgrade.base.stage`).
"""

from .controls import Control
from .stage import Stage

__all__ = ["Control", "Stage"]
