"""Every ``isa-mocap`` command and subcommand prints its help (argparse %-formats help strings:
a bare "%" in one of them made ``isa-mocap bench --help`` crash)."""
from __future__ import annotations

import argparse

import pytest

from isa_mocap_ros.cli.main import build_parser


def _commands(parser: argparse.ArgumentParser, path=()):
    yield path
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _commands(sub, path + (name,))


COMMANDS = list(_commands(build_parser()))


def test_the_command_tree_is_walked():
    assert ("bench", "robustness") in COMMANDS and ("run",) in COMMANDS and len(COMMANDS) > 15


@pytest.mark.parametrize("path", COMMANDS, ids=lambda p: " ".join(p) or "isa-mocap")
def test_help_prints(path, capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args([*path, "--help"])
    assert exc.value.code == 0
    assert "usage: isa-mocap" in capsys.readouterr().out
