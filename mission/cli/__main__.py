"""``python -m mission.cli``: the ``marsupial`` command."""
from mission.cli import console

console()
