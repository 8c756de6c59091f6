"""The console every command prints to: the terminal's width, or 160 columns when not on a terminal."""

import sys

from rich.console import Console

console = Console(stderr=False, width=None if sys.stdout.isatty() else 160)
