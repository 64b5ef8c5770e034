"""``python -m irtps.cli``: the ``irtps`` command."""

import sys

from irtps.cli.main import main

if __name__ == "__main__":
    sys.exit(main())
