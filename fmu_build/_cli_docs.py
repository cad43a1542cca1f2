"""docs/cli.md, written from the argument parser itself (so no command or option can be missing).

Run ``python -m fmu_build.__main__ --markdown`` to print it; ``examples/gen_cli_docs.py
--docs`` writes docs/cli.md, and tests/fmu_build/cli/test_cli_docs.py checks the file equals it.
"""
import argparse

HEAD = """\
# Command line

`lsc-fmu` (also `python -m fmu_build`) has one subcommand per task; `lsc-fmu --help` lists them
with an example each, and `lsc-fmu COMMAND --help` their options. This page is generated from
the argument parser by `python examples/gen_cli_docs.py --docs`.

**Output files.** `simulate` and `cosim` never write over one of their inputs (however the path
is spelled), and replace an existing file only when it is an earlier result of the same command:
a CSV whose header row is `time` followed by the columns this run writes (for `cosim` without
`--output`: `time` followed by `component.variable` names). Anything else needs `--force`.
A run that ends before the stop time writes what it computed and exits with status 1, naming
the FMU's reason; a refusal before running exits with status 2.
"""


def _option(action):
    """'`-o`, `--output` CSV' for one argument."""
    if not action.option_strings:
        return f"`{action.metavar or action.dest}`"
    names = ", ".join(f"`{s}`" for s in action.option_strings)
    if action.nargs == 0:
        return names
    metavar = action.metavar or action.dest.upper()
    if isinstance(metavar, tuple):
        metavar = " ".join(metavar)
    return f"{names} {metavar}"


def _help(action):
    text = (action.help or "").replace("|", "\\|")
    if action.choices and not isinstance(action, argparse._SubParsersAction):
        text += " (one of: " + ", ".join(f"`{c}`" for c in action.choices) + ")"
    if action.required and action.option_strings:
        text += " (required)"
    return text


def markdown(parser):
    """The Markdown page of a parser with subcommands: one section per command, options as a table."""
    lines = [HEAD]
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, command in sub.choices.items():
        lines += [f"## `lsc-fmu {name}`", "", command.description or "", ""]
        if command.epilog:
            lines += ["```text", command.epilog.removeprefix("example: "), "```", ""]
        lines += ["| argument | meaning |", "|---|---|"]
        for action in command._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            lines.append(f"| {_option(action)} | {_help(action)} |")
        lines.append("")
    return "\n".join(lines)
