"""``python -m uam_studio.cli``: the ``uam-studio`` command, run as a module."""

import sys

from uam_studio.cli import main

if __name__ == "__main__":
    sys.exit(main())
