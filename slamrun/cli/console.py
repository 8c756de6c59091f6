"""The console every command prints to: the terminal's width, or 160 columns when not on a terminal.

Made on first use, so a command that prints plain lines (`slamrun evaluate` over 1,000 files, a process a
benchmark times) does not pay for importing rich."""

from __future__ import annotations

import sys


class _LazyConsole:
    def __init__(self):
        self._console = None

    def real(self):
        """rich's Console itself (for rich objects that keep one, like Live)."""
        if self._console is None:
            from rich.console import Console

            class _Console(Console):
                def on_broken_pipe(self) -> None:  # the CLI ends every command alike when its reader is gone
                    self.quiet = True
                    raise BrokenPipeError

            self._console = _Console(stderr=False, width=None if sys.stdout.isatty() else 160)
        return self._console

    def __getattr__(self, name: str):
        return getattr(self.real(), name)


console = _LazyConsole()
