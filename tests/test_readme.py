"""The README stays the user's manual and the docs stay true to the code: generated sections match what
generates them, every command is in the README, every link resolves, and the README stays short."""

from __future__ import annotations

import re
from pathlib import Path

import click
import pytest
from paths import ROOT

from spooflens.attacks.spec import attacks_markdown
from spooflens.cli import cli
from spooflens.schema import schema_markdown

README = (ROOT / "README.md").read_text()
DOCS = ROOT / "docs"
MAX_README_LINES = 300


def _section(path: Path, name: str) -> str:
    found = re.search(rf"<!-- {name}:start[^\n]*-->\n(.*)\n<!-- {name}:end -->", path.read_text(), re.S)
    assert found is not None, f"{path} has no generated {name} section"
    return found.group(1).strip()


def test_schema_section_is_generated_from_the_schema_module() -> None:
    assert _section(DOCS / "epoch-table.md", "schema") == schema_markdown().strip()


def test_attacks_table_is_generated_from_the_kinds_table() -> None:
    assert _section(DOCS / "simulation-and-attacks.md", "attacks") == attacks_markdown().strip()


def test_every_cli_command_is_documented() -> None:
    ctx = click.Context(cli)
    for name in cli.list_commands(ctx):
        command = cli.get_command(ctx, name)
        subs = command.list_commands(ctx) if isinstance(command, click.Group) else []
        for full in [name] if not subs else [f"{name} {s}" for s in subs]:
            words = full.split()
            # a group's subcommands may share a row: `spooflens bench mlrt`, `bench range_rate`, ...
            assert f"spooflens {full}" in README or (len(words) == 2 and f"`{words[0]} {words[1]}`" in README), (
                f"spooflens {full} is not in the README"
            )


def test_ci_blocks_exist_and_install_then_analyse_the_sample() -> None:
    install = re.search(r"<!-- ci:install -->\n```sh\n(.*?)\n```", README, re.S)
    test = re.search(r"<!-- ci:test -->\n```sh\n(.*?)\n```", README, re.S)
    assert install and "pip install -e" in install.group(1) and "spooflens analyze sample_logs/" in install.group(1)
    assert test and "pytest" in test.group(1)


def test_the_readme_is_read_in_ten_minutes() -> None:
    assert len(README.splitlines()) <= MAX_README_LINES


@pytest.mark.parametrize("page", [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))], ids=lambda p: p.name)
def test_every_relative_link_resolves(page: Path) -> None:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)
    broken = []
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+:", target):
            continue  # a web address
        path, _, anchor = target.partition("#")
        where = (page.parent / path).resolve() if path else page
        missing_heading = bool(anchor) and where.suffix == ".md" and anchor not in _anchors(where)
        if not where.exists() or missing_heading:
            broken.append(target)
    assert not broken, f"{page.relative_to(ROOT)}: links that go nowhere: {broken}"


def _anchors(page: Path) -> set[str]:
    """GitHub's anchors of a page's headings (lower case, punctuation dropped, spaces as hyphens)."""
    heads = re.findall(r"^#+ (.*)$", page.read_text(), re.M)
    return {re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-") for h in heads}
