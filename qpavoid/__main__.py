"""``python -m qpavoid``: the command line."""

import sys

from qpavoid.cli.launch import main

sys.exit(main())
