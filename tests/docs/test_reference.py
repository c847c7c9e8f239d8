"""The reference pages cover what the tool accepts: every command, every design-file
key, every campaign-file key; the site builds without a warning."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import click
import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"


def command_paths(group: click.Group, prefix: str = "study") -> list[str]:
    """Every command path of the `study` command tree (`study tlx enter`, ...)."""
    ctx = click.Context(group, info_name=prefix)
    paths = []
    for name in group.list_commands(ctx):
        command = group.get_command(ctx, name)
        assert command is not None, name
        path = f"{prefix} {name}"
        paths.append(path)
        if isinstance(command, click.Group):
            paths += command_paths(command, path)
    return paths


def test_every_command_is_in_the_generated_cli_reference() -> None:
    from study.cli import cli
    from study.commands.reference import cli_reference

    expected = set(command_paths(cli))  # loads every lazy command, as a build's first look does
    lines = cli_reference(cli)
    documented = set(re.findall(r"^#+ (study[\w -]*?) \{ #", lines, re.MULTILINE))
    missing = sorted(expected - documented)
    assert not missing, f"commands missing from the CLI reference: {missing}"
    page = (DOCS / "reference" / "cli.md").read_text(encoding="utf-8")
    assert "<!-- cli-reference -->" in page


def documented_keys(page: Path) -> set[str]:
    """The keys in the first column of a reference page's first table."""
    text = page.read_text(encoding="utf-8")
    return set(re.findall(r"^\| `([a-z_]+)` \|", text, re.MULTILINE))


def test_every_design_file_key_is_documented() -> None:
    from study.protocol import design

    documented = documented_keys(DOCS / "reference" / "design-file.md")
    accepted = set(design._KEYS)
    assert documented == accepted, (
        f"undocumented: {sorted(accepted - documented)}; "
        f"documented but not accepted: {sorted(documented - accepted)}"
    )


def test_every_key_of_the_design_files_sub_tables_is_documented() -> None:
    from dataclasses import fields

    from study.protocol import design

    text = (DOCS / "reference" / "design-file.md").read_text(encoding="utf-8")
    documented = set(re.findall(r"^\| `(\w+\.\w+)` \|", text, re.MULTILINE))
    from study.probes import probe_names

    accepted = {f"lsl.{f.name}" for f in fields(design.LslSettings)}
    accepted |= {"probes.before_block", *(f"probes.{name}" for name in probe_names())}
    from study.protocol.design_sensors import SensorSettings

    accepted |= {f"sensors.{f.name}" for f in fields(SensorSettings)}
    assert accepted <= documented, f"undocumented: {sorted(accepted - documented)}"


def test_every_campaign_file_key_and_factor_is_documented() -> None:
    from study.campaign import spec

    documented = documented_keys(DOCS / "reference" / "campaign-file.md")
    accepted = set(spec._KEYS) | set(spec.FACTORS)
    assert documented == accepted, (
        f"undocumented: {sorted(accepted - documented)}; "
        f"documented but not accepted: {sorted(documented - accepted)}"
    )


@pytest.mark.slow
def test_the_site_builds_strict(tmp_path: Path) -> None:
    mkdocs = shutil.which("mkdocs", path=str(Path(sys.executable).parent)) or shutil.which("mkdocs")
    assert mkdocs, "mkdocs is in the test extra"
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    result = subprocess.run(
        [mkdocs, "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr[-4000:]
    assert (tmp_path / "site" / "reference" / "cli" / "index.html").is_file()
