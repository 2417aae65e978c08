"""``python -m mission.cli``: the ``marsupial`` command."""
import sys

from mission.cli import main

sys.exit(main())
