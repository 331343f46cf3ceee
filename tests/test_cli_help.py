"""Every `mocap` command's --help formats: argparse %-formats help texts, so a stray "%" in one breaks it."""
import argparse

from mocap_cli.main import build_parser


def _parsers(parser, path=()):
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _parsers(sub, path + (name,))


def test_every_commands_help_formats():
    seen = []
    for path, parser in _parsers(build_parser()):
        text = parser.format_help()
        assert "usage:" in text, path
        seen.append(" ".join(path))
    assert {"eval gaps", "bag play", "launch"} <= set(seen), seen
