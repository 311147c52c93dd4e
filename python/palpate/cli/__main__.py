"""``python -m palpate.cli``: the command line (as ``palpate`` and ``python -m palpate``)."""
import sys

from . import main

sys.exit(main())
