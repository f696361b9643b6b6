"""Rewrite the figures of the README's checked prose sentences from the results they stand for.

Usage: python benchmarks/readme_prose.py [--check]
Each entry of ``PROSE`` in tests/test_readme_numbers.py (the sentence, the numbers it prints, the
values they stand for) whose printed numbers no longer match is rewritten: every printed number gets
its new value at its own decimals, in the README and in the test's own copy of the sentence. The
words are left alone: a figure whose sign flipped, or a range whose ends swapped, is listed for a
person to reread (the sentence may now say "above" where the result says below). Companion of
``readme_tables.py`` (tables) after a bench is regenerated.
"""
from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TEST = ROOT / "tests" / "test_readme_numbers.py"
sys.path.insert(0, str(ROOT / "tests"))
import test_readme_numbers as checks  # noqa: E402


def _format(value: float, like: str) -> str:
    """``value`` printed as ``like`` is (decimals, thousands commas, a leading minus kept apart)."""
    digits = len(like.split(".")[1]) if "." in like else 0
    text = f"{abs(value):,.{digits}f}" if "," in like else f"{abs(value):.{digits}f}"
    return ("-" if like.startswith("-") else "") + text


def _literal(text: str) -> str:
    """How the test file writes ``text`` (a double-quoted Python string)."""
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'


def rewrite(readme: str, test_src: str) -> tuple[str, str, list[str]]:
    review: list[str] = []
    for text, printed, values in checks.PROSE:
        cells = printed.split()
        got = values()
        if all(checks._matches(c, v) for c, v in zip(cells, got)):
            continue
        new_text, new_cells, pos = text, [], 0
        for cell, value in zip(cells, got):
            bare = cell.lstrip("-")
            new = _format(value, cell)
            if (value < 0) != cell.startswith("-") and abs(value) >= 0.5 * 10 ** -(len(bare.split(".")[1]) if "." in bare else 0):
                review.append(f"sign flipped: {text[:70]!r}: {cell} -> {value:+.3f}")
                new = _format(abs(value), cell)
            new_cells.append(new)
            found = re.compile(rf"(?<![\d.]){re.escape(bare)}(?![\d])").search(new_text, pos)
            if found is None:
                review.append(f"not found: {bare} in {text[:70]!r}")
                continue
            new_bare = new.lstrip("-")
            new_text = new_text[:found.start()] + new_bare + new_text[found.end():]
            pos = found.start() + len(new_bare)
        if text not in readme:
            review.append(f"README no longer has: {text[:70]!r}")
            continue
        lit_text, lit_printed = _literal(text), _literal(printed)
        if test_src.count(lit_text) != 1 or lit_printed not in test_src:
            review.append(f"test copy not found once (edit by hand): {text[:70]!r} -> {new_text!r} / {' '.join(new_cells)}")
            continue
        readme = readme.replace(text, new_text)
        start = test_src.index(lit_text)
        end = test_src.index(lit_printed, start) + len(lit_printed)
        test_src = (test_src[:start] + _literal(new_text) + test_src[start + len(lit_text):end - len(lit_printed)]
                    + _literal(" ".join(new_cells)) + test_src[end:])
        print(f"- {text!r}\n+ {new_text!r}")
    return readme, test_src, review


if __name__ == "__main__":
    readme, test_src, review = rewrite(checks.README, TEST.read_text())
    for line in review:
        print("REVIEW:", line)
    if "--check" in sys.argv:
        sys.exit(1 if readme != checks.README else 0)
    (ROOT / "README.md").write_text(readme)
    TEST.write_text(test_src)
