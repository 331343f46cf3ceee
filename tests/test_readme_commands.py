"""Every `mocap` command the README shows parses with the CLI as it is (a renamed flag or command fails here),
and every launch file it names loads."""
import re
import shlex

import pytest

from mocap_cli.launch_file import load_launch_file
from mocap_cli.main import build_parser
from tests.conftest import REPO

README = (REPO / "README.md").read_text()
BLOCKS = re.findall(r"```sh\n(.*?)```", README, re.S)
COMMANDS = [line.split("  #")[0].strip() for block in BLOCKS for line in block.splitlines()
            if line.startswith(".venv/bin/mocap ")]


def test_the_readme_shows_commands():
    assert len(COMMANDS) >= 15, COMMANDS


@pytest.mark.parametrize("command", COMMANDS)
def test_readme_command_parses(command):
    args = shlex.split(command)[1:]
    try:
        build_parser().parse_args(args)
    except SystemExit as e:
        pytest.fail(f"`{command}` does not parse (exit {e.code})")


@pytest.mark.parametrize("path", sorted(set(re.findall(r"launch/[\w.]+\.yaml", README))))
def test_readme_launch_files_load(path):
    load_launch_file(REPO / path)
