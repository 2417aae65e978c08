"""Write the configuration reference (``mission.config.reference.markdown_table``) into
docs/configuration.md between its ``config-reference`` markers.

    python scripts/config_reference.py
"""
from __future__ import annotations

from pathlib import Path

from mission.config.reference import markdown_table

DOC = Path(__file__).resolve().parents[1] / "docs" / "configuration.md"
START, END = "<!-- config-reference:start -->\n", "\n<!-- config-reference:end -->"


def main() -> None:
    text = DOC.read_text()
    head, rest = text.split(START, 1)
    _, tail = rest.split(END, 1)
    DOC.write_text(head + START + markdown_table() + END + tail)


if __name__ == "__main__":
    main()
