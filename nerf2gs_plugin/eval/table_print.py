"""Printing rich tables so that they are complete wherever they go.

Rich fits a table to the console width and cuts cells with an ellipsis; when the output is piped
(``make demo | tee log``) it assumes 80 columns, so labels and whole columns were lost. Here a
console that is not a terminal is as wide as the table needs, and on a narrow terminal cells wrap
(fold) instead of being cut.
"""

from __future__ import annotations

import sys
from typing import Optional, TextIO

from rich.console import Console
from rich.table import Table

PIPED_WIDTH = 1000  # wider than any table here; rich does not pad a table to the console width


def table_console(file: Optional[TextIO] = None) -> Console:
    """A console on ``file`` (stdout): the terminal's width on a terminal, else :data:`PIPED_WIDTH`."""
    console = Console(file=file or sys.stdout)
    if console.is_terminal or console.is_jupyter:
        return console
    return Console(file=file or sys.stdout, width=PIPED_WIDTH)


def print_table(table: Table, file: Optional[TextIO] = None) -> None:
    """Print ``table`` whole: no column is dropped and no cell ends in an ellipsis."""
    for column in table.columns:
        column.overflow = "fold"
        column.no_wrap = False
    table_console(file).print(table)
