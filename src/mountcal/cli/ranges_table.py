"""The table of docs/reliability.md, the ranges every command checks: ``python -m mountcal.cli.ranges_table``."""

from __future__ import annotations

from mountcal.cli import build_parser
from mountcal.core.ranges import markdown

if __name__ == "__main__":
    print(markdown(build_parser()), end="")
