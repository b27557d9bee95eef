"""``python -m wuerfel_cvx``: the command line, as the ``wuerfel-cvx`` script runs it."""

import sys

from ._entry import main

sys.exit(main())
