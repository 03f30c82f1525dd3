"""MkDocs hooks of the jaxrb site (see mkdocs.yml).

- The notebooks' jupytext sources, `notebooks/[0-9][0-9]_*.py`, join the site's files as
  `notebooks/NAME.py`; the mkdocs-jupyter plugin renders them (before it sees the files, hence
  the priority).
- A line `<!-- jaxrb-cli-help -->` in a page becomes the `--help` text of `jaxrb` and of every
  subcommand, taken from the command line's own parser, so the reference cannot go stale.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from mkdocs.plugins import event_priority
from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOK_GLOB = "[0-9][0-9]_*.py"
CLI_MARKER = "<!-- jaxrb-cli-help -->"
HELP_WIDTH = 100  # columns of the --help text, whatever the terminal building the site


@event_priority(100)
def on_files(files, config):
    for path in sorted((ROOT / "notebooks").glob(NOTEBOOK_GLOB)):
        files.append(
            File(
                f"notebooks/{path.name}",
                src_dir=str(ROOT),
                dest_dir=config["site_dir"],
                use_directory_urls=config["use_directory_urls"],
            )
        )
    return files


def on_page_markdown(markdown, page, config, files):
    if CLI_MARKER not in markdown:
        return markdown
    return markdown.replace(CLI_MARKER, _cli_reference())


def _cli_reference() -> str:
    from jaxrb._cli import build_parser

    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(HELP_WIDTH)
    try:
        sections = list(_help_texts(build_parser()))
    finally:
        if old is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = old
    return "\n".join(f"### `{prog}`\n\n```text\n{text.rstrip()}\n```\n" for prog, text in sections)


def _help_texts(parser: argparse.ArgumentParser):
    """(prog, help text) of `parser` and, depth first, of each of its subcommands."""
    yield parser.prog, parser.format_help()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            seen = set()
            for sub in action.choices.values():
                if id(sub) not in seen:  # aliases share one parser
                    seen.add(id(sub))
                    yield from _help_texts(sub)
