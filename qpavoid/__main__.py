"""``python -m qpavoid``: the command line."""

import sys

from qpavoid.launch import main

sys.exit(main())
