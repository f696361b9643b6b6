"""``ns2gs-train <method> --help`` for every built-in method: every option has a description, no
reStructuredText markup, no internal fields (``_target``)."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest

from nerf2gs_plugin.registry import ALIASES, BUILTIN_METHODS

_OPTION = re.compile(r"^\s*(-h, )?--[\w.-]+")


def help_text(method: str) -> str:
    env = {**os.environ, "COLUMNS": "100", "NO_COLOR": "1", "TERM": "dumb"}
    proc = subprocess.run([sys.executable, "-m", "nerf2gs_plugin.cli.train", method, "--help"],
                          capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def undescribed(text: str) -> list[str]:
    """Options whose help is only ``(default: ...)`` or ``(fixed ...)`` (tyro prints the
    description, if any, on the lines between the option and its default). An option line ending in
    a comma lists an alias: the option's own line follows."""
    lines = [re.sub(r"[│╭╮╰╯─]", " ", line).rstrip() for line in text.splitlines()]
    missing = []
    for i, line in enumerate(lines):
        if not _OPTION.match(line) or line.strip().startswith("-h") or line.endswith(","):
            continue
        following = next((l.strip() for l in lines[i + 1:] if l.strip()), "")
        if following.startswith("(default") or following.startswith("(fixed") or _OPTION.match(following) or not following:
            missing.append(line.strip().split()[0])
    return missing


@pytest.mark.parametrize("method", sorted([*BUILTIN_METHODS, *ALIASES]))
def test_help_is_clean(method):
    text = help_text(method)
    assert "--max-num-iterations" in text
    assert "``" not in text, "reStructuredText markup in --help"
    assert "_target" not in text and "{fixed}" not in text, "internal fields in --help"
    assert undescribed(text) == [], f"options without a description: {undescribed(text)}"


def test_docs_augment_table_lists_every_flag():
    import dataclasses
    from pathlib import Path

    from nerf2gs_plugin.augment.datamanager import AugmentConfig

    guide = (Path(__file__).resolve().parents[2] / "docs" / "augmentation.md").read_text()
    rows = set(re.findall(r"^\| `--augment\.([\w-]+)`", guide, flags=re.M))
    flags = {f.name.rstrip("_").replace("_", "-") for f in dataclasses.fields(AugmentConfig)}  # raise_: --augment.raise
    assert flags - rows == set(), f"docs/augmentation.md's --augment.* table lacks {sorted(flags - rows)}"
