"""``python -m torchgrade.cli``: the ``torchgrade`` command."""

import sys

from . import main

__all__ = []

if __name__ == "__main__":
    sys.exit(main())
