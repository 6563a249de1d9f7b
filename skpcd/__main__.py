"""``python -m skpcd`` runs the command line."""

import sys

from skpcd.cli import main

sys.exit(main())
