"""Helpers shared by the `jaxrb` commands: the user-error exception, the output directory
(checked before any work, written atomically by `StagedOutput`), one-line messages,
plain-text tables and number formatting.

`_cli.py` (run, sweep, bench, the parser and `main`) and `_cli_fit.py` (`jaxrb fit`) import
them from here.
"""

from __future__ import annotations

import os
import shutil
import tempfile
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


def add_cache_option(parser) -> None:
    """`--no-cache`: the same for every command that compiles a simulation."""
    parser.add_argument(
        "--no-cache",
        action="store_true",
        help="do not read or write compiled programs in the persistent compilation cache "
        "($JAXRB_CACHE_DIR, default ~/.cache/jaxrb/jax), which makes a second run of the "
        "same kind of scene start quicker; the files used longest ago are removed when it "
        "holds more than $JAXRB_CACHE_MAX_MB megabytes (default 1024)",
    )


def _outputs_free(outdir: Path, names, force: bool):
    """Raise a CLIError if any output exists and --force was not given."""
    existing = [outdir / n for n in names if (outdir / n).exists()]
    if existing and not force:
        listing = ", ".join(str(p) for p in existing[:4]) + (" ..." if len(existing) > 4 else "")
        raise CLIError(
            f"output already exists: {listing}; "
            "use --force to overwrite, or -o/--output to write somewhere else"
        )
    outdir.mkdir(parents=True, exist_ok=True)


def one_line(text) -> str:
    """`text` (a message, or an exception's) on one line: its lines joined by spaces."""
    return " ".join(line.strip() for line in str(text).splitlines() if line.strip())


def _existing_ancestor(path: Path) -> Path:
    """The nearest of `path`'s parents that exists (absolute `path`)."""
    for parent in path.parents:
        if os.path.lexists(parent):
            return parent
    return Path(path.anchor)


def check_output(outdir, names, force: bool) -> None:
    """Raise a CLIError unless the files `names` can be written into the directory `outdir`:
    it exists, or can be made where its nearest existing parent is a writable directory; and
    none of `names` exists there unless `force` (then each must be a file, not a directory)."""
    shown = str(outdir)
    if not shown:
        raise CLIError("-o/--output: empty path (give a directory)")
    target = Path(os.path.abspath(outdir))
    if target.is_dir():
        where = target
        clashes = [target / n for n in names if os.path.lexists(target / n)]
        for path in clashes:
            if path.is_dir():
                raise CLIError(f"{path}: is a directory; jaxrb writes a file of that name there")
        if clashes and not force:
            listing = ", ".join(str(Path(shown) / p.name) for p in clashes[:4])
            raise CLIError(
                f"output already exists: {listing}{' ...' if len(clashes) > 4 else ''}; "
                "use --force to overwrite, or -o/--output to write somewhere else"
            )
    elif os.path.lexists(target):
        kind = "a broken symbolic link" if target.is_symlink() else "a file"
        raise CLIError(f"{shown}: is {kind}, not a directory (-o/--output names a directory)")
    else:
        where = _existing_ancestor(target)
        if not where.is_dir():
            raise CLIError(f"{shown}: cannot create it: {where} is not a directory")
    if not os.access(where, os.W_OK | os.X_OK):
        raise CLIError(f"{shown}: cannot write in {where}: permission denied")


class StagedOutput:
    """An output directory written atomically: files go into a temporary directory, `path`,
    and `commit()` moves them into place together once every one is written.

    A new directory is staged as a hidden sibling and renamed into place (its missing
    parents made then). An existing one gets a hidden staging directory inside it; the
    commit moves the files in, each replacing its namesake (allowed by `force`), and puts
    the old files back if a move fails. Leaving the `with` block without a commit (an
    error, a failed run) removes the staging directory: nothing is left behind.
    """

    def __init__(self, outdir, names, force: bool):
        check_output(outdir, names, force)
        self.shown = Path(outdir)
        self.target = Path(os.path.abspath(outdir))
        self.force = force
        new = not self.target.is_dir()
        if new:
            where, prefix = _existing_ancestor(self.target), f".{self.target.name}.partial-"
        else:
            where, prefix = self.target, ".jaxrb-partial-"
        try:
            self.path = Path(tempfile.mkdtemp(prefix=prefix, dir=where))
            if new:  # the permissions of a directory made by mkdir, not mkdtemp's 0o700
                umask = os.umask(0)
                os.umask(umask)
                self.path.chmod(0o777 & ~umask)
        except OSError as e:
            raise CLIError(f"{outdir}: cannot write in {where}: {e.strerror or e}") from None

    def __enter__(self) -> StagedOutput:
        return self

    def __exit__(self, *exc) -> None:
        self.discard()

    def discard(self) -> None:
        """Remove the staging directory and whatever is in it."""
        shutil.rmtree(self.path, ignore_errors=True)

    def commit(self) -> None:
        """Move the staged files into the output directory; a CLIError (nothing changed) if
        that cannot be done."""
        if not os.path.lexists(self.target):
            made = []
            try:
                for parent in reversed(self.target.parents):
                    if not os.path.lexists(parent):
                        parent.mkdir()
                        made.append(parent)
                os.rename(self.path, self.target)
                return
            except OSError as e:
                for parent in reversed(made):
                    parent.rmdir()
                if not os.path.lexists(self.target):
                    raise CLIError(f"{self.shown}: cannot create it: {e.strerror or e}") from None
        self._merge()

    def _merge(self) -> None:
        names = sorted(p.name for p in self.path.iterdir())
        clashes = [n for n in names if os.path.lexists(self.target / n)]
        if clashes and not self.force:
            raise CLIError(
                f"output appeared while running: {self.shown / clashes[0]}; nothing written"
            )
        old = Path(tempfile.mkdtemp(prefix="replaced-", dir=self.path))
        moved = []
        try:
            for name in names:
                if name in clashes:
                    os.replace(self.target / name, old / name)
                os.replace(self.path / name, self.target / name)
                moved.append(name)
        except OSError as e:
            for name in moved:
                os.replace(self.target / name, self.path / name)
            for path in old.iterdir():
                os.replace(path, self.target / path.name)
            raise CLIError(f"{self.shown}: cannot write: {e.strerror or e}") from None
        self.discard()


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
