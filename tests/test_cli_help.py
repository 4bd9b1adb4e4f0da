"""Every option of every ``hbmp-bench`` command says what it is and what its default is."""

import argparse

import pytest

from hbmp_bench import cli

PARSERS = cli.parsers(cli.build_parser())


def _options(parser):
    return [a for a in parser._actions if not isinstance(a, (argparse._HelpAction, argparse._SubParsersAction))]


def test_every_command_is_walked():
    commands = {prog.removeprefix("hbmp-bench").strip() for prog, _ in PARSERS}
    assert {"", "run", "evaluate", "report", "leaderboard submit", "maps import", "train", "transfer evaluate",
            "bench", "record"} <= commands


@pytest.mark.parametrize("prog,parser", PARSERS, ids=[prog for prog, _ in PARSERS])
def test_every_option_has_help_and_shows_its_default(prog, parser):
    formatter = parser._get_formatter()
    assert isinstance(formatter, cli.HelpFormatter)
    for action in _options(parser):
        name = "/".join(action.option_strings) or action.dest
        assert action.help and action.help != argparse.SUPPRESS, f"{prog} {name}: no help text"
        if action.default in (None, False) or action.nargs == 0:
            continue  # absent by default, or a switch
        shown = formatter._expand_help(action)
        default = action.default
        if isinstance(default, (list, tuple)):
            default = ", ".join(map(str, default))
        assert "default" in shown and str(default) in shown, \
            f"{prog} {name}: help does not show its default {action.default!r}: {shown!r}"
    text = parser.format_help()
    assert text  # renders
