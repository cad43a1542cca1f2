"""lsc-fmu documents itself: every subcommand's --help has a description and an example, and
docs/cli.md is exactly what the argument parser generates (so it cannot miss a command)."""
import argparse
import subprocess
import sys

import pytest

from fmu_build.__main__ import COMMANDS, main, parser
from fmu_build._cli_docs import markdown

from tests.support import ROOT


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_subcommand_help_has_a_description_and_an_example(command, capsys):
    sub = next(a for a in parser()._actions if isinstance(a, argparse._SubParsersAction)).choices[command]
    assert sub.description and len(sub.description) > 40, command
    assert sub.epilog and sub.epilog.startswith("example: ") and "lsc-fmu " + command in sub.epilog, command
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = capsys.readouterr().out
    assert "example: " in text and sub.description.split()[0] in text


def test_docs_cli_md_is_generated_from_the_parser():
    text = (ROOT / "docs" / "cli.md").read_text()
    assert text == markdown(parser()), "docs/cli.md is stale: run python examples/gen_cli_docs.py --docs"
    for command in COMMANDS:
        assert f"## `lsc-fmu {command}`" in text
        for action in next(a for a in parser()._actions
                           if isinstance(a, argparse._SubParsersAction)).choices[command]._actions:
            for option in ([] if isinstance(action, argparse._HelpAction) else action.option_strings):
                assert f"`{option}`" in text, (command, option)


def test_markdown_flag_prints_the_page():
    run = subprocess.run([sys.executable, "-m", "fmu_build", "--markdown"], capture_output=True, text=True,
                         timeout=120, cwd=ROOT)
    assert run.returncode == 0, run.stderr
    assert run.stdout == markdown(parser())
