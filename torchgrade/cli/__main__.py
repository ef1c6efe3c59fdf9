"""``python -m torchgrade.cli``: the ``torchgrade`` command."""

import sys

from . import main

if __name__ == "__main__":
    sys.exit(main())
