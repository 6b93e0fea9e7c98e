"""The README stays the user's manual: its schema section and its commands match the code."""

from __future__ import annotations

import re

import click
from paths import ROOT

from spooflens.attacks.spec import attacks_markdown
from spooflens.cli import cli
from spooflens.schema import schema_markdown

README = (ROOT / "README.md").read_text()


def test_schema_section_is_generated_from_the_schema_module() -> None:
    section = re.search(r"<!-- schema:start[^\n]*-->\n(.*)\n<!-- schema:end -->", README, re.S)
    assert section is not None
    assert section.group(1).strip() == schema_markdown().strip()


def test_attacks_table_is_generated_from_the_kinds_table() -> None:
    section = re.search(r"<!-- attacks:start[^\n]*-->\n(.*)\n<!-- attacks:end -->", README, re.S)
    assert section is not None
    assert section.group(1).strip() == attacks_markdown().strip()


def test_every_cli_command_is_documented() -> None:
    """In the README or in the docs/ page it links for the command's topic."""
    documented = README + "".join(p.read_text() for p in sorted((ROOT / "docs").glob("*.md")))
    ctx = click.Context(cli)
    for name in cli.list_commands(ctx):
        command = cli.get_command(ctx, name)
        subs = command.list_commands(ctx) if isinstance(command, click.Group) else []
        for full in [name] if not subs else [f"{name} {s}" for s in subs]:
            assert f"spooflens {full}" in documented, full


def test_ci_blocks_exist_and_install_then_analyse_the_sample() -> None:
    install = re.search(r"<!-- ci:install -->\n```sh\n(.*?)\n```", README, re.S)
    test = re.search(r"<!-- ci:test -->\n```sh\n(.*?)\n```", README, re.S)
    assert install and "pip install -e" in install.group(1) and "spooflens analyze sample_logs/" in install.group(1)
    assert test and "pytest" in test.group(1)
