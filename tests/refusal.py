"""The CLI's contract for bad input, shared by the command tests: exit 2 and one stderr line."""

from __future__ import annotations

import pytest

from elevens.cli import main


def refused(argv: list[str], command: str, capsys: pytest.CaptureFixture[str]) -> str:
    """Run ``elevens argv``; assert it exits 2 with one stderr line starting with
    ``elevens COMMAND: error: ``, and return that line."""
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith(f"elevens {command}: error: ") and "\n" not in error
    return error
