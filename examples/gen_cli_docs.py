"""The command-line reference docs/cli.md, generated from lsc-fmu's argument parser.

Run: ``python examples/gen_cli_docs.py`` prints the page; ``--docs`` writes docs/cli.md
(tests/fmu_build/cli/test_cli_docs.py checks that the file equals what the parser generates).
"""
import pathlib
import sys

from fmu_build.__main__ import parser
from fmu_build._cli_docs import markdown

DOCS = pathlib.Path(__file__).resolve().parent.parent / "docs" / "cli.md"


def main(argv):
    text = markdown(parser())
    if "--docs" in argv:
        DOCS.write_text(text)
        print(DOCS)
    else:
        print(text, end="")


if __name__ == "__main__":
    main(sys.argv[1:])
