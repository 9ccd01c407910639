"""``python -m phantomtouch`` runs the command line."""

import sys

from phantomtouch.cli import main

sys.exit(main())
