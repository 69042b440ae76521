"""``python -m relight`` (and ``torchrun ... -m relight train``): the ``relight`` command."""

__all__: list[str] = []

import sys

from relight.cli import main

if __name__ == "__main__":
    sys.exit(main())
