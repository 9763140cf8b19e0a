"""What the benchmark commands share: argument types and the error exit."""

from __future__ import annotations

import argparse
import sys

from clrt.errors import ClrtError


def parse_size(text: str) -> tuple[int, int]:
    """argparse type for an image size 'WxH'."""
    try:
        w, h = (int(x) for x in text.lower().split("x"))
        return w, h
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WxH, got {text!r}") from None


def exit_code(run, *args, **kwargs) -> int:
    """Call ``run``; a ClrtError becomes one line on stderr and its exit code."""
    try:
        run(*args, **kwargs)
    except ClrtError as exc:
        print(f"clrt: {exc}", file=sys.stderr)
        return exc.exit_code
    return 0
