"""``python -m palpate``: the command line (see :mod:`palpate.cli`)."""
from .cli import main

raise SystemExit(main())
