"""Helpers shared by the `jaxrb` commands: the user-error exception, the output-directory
check, plain-text tables and number formatting.

`_cli.py` (run, sweep, bench, the parser and `main`) and `_cli_fit.py` (`jaxrb fit`) import
them from here.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

DEFAULT_OUTPUT = "jaxrb-output"


class CLIError(Exception):
    """A user error on the command line: printed as `jaxrb: error: ...`, exit status 2."""


def add_output_options(parser) -> None:
    """`-o/--output DIR` and `-f/--force`, the same for every command that writes files."""
    parser.add_argument(
        "-o",
        "--output",
        default=DEFAULT_OUTPUT,
        metavar="DIR",
        help=f"output directory (default: {DEFAULT_OUTPUT}/)",
    )
    parser.add_argument(
        "-f", "--force", action="store_true", help="overwrite existing output files"
    )


def _outputs_free(outdir: Path, names, force: bool):
    """Raise a CLIError if any output exists and --force was not given."""
    existing = [outdir / n for n in names if (outdir / n).exists()]
    if existing and not force:
        listing = ", ".join(str(p) for p in existing[:4]) + (" ..." if len(existing) > 4 else "")
        raise CLIError(
            f"output already exists: {listing}\n"
            "  use --force to overwrite, or -o/--output to write somewhere else"
        )
    outdir.mkdir(parents=True, exist_ok=True)


def _table(rows, header=None, right=True) -> str:
    """A plain-text table; the first column left-aligned, the others right-aligned if `right`."""
    rows = [[str(c) for c in r] for r in rows]
    if header:
        rows = [list(header)] + rows
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = []
    for j, r in enumerate(rows):
        cells = [r[0].ljust(widths[0])] + [
            c.rjust(w) if right else c.ljust(w) for c, w in zip(r[1:], widths[1:], strict=True)
        ]
        lines.append("  ".join(cells).rstrip())
        if header and j == 0:
            lines.append("  ".join("-" * w for w in widths))
    return "\n".join(lines)


def _fmt(x, digits=6):
    x = np.asarray(x, dtype=float)
    if x.ndim == 0:
        return f"{float(x):.{digits}g}"
    return "(" + ", ".join(f"{v:.{digits}g}" for v in x.reshape(-1)) + ")"
