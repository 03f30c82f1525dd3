"""Example scenes shipped with jaxrb (`jaxrb/scenes/*.toml`), found by name.

`jaxrb run NAME` and `jaxrb sweep NAME` take an example's name where a scene file is
expected; `jaxrb run --list` lists them. An existing file of that name takes precedence.
"""

from __future__ import annotations

import importlib.resources
import tomllib
from pathlib import Path

# name -> file in jaxrb/scenes/; the first is the default scene of `jaxrb run`
EXAMPLES = {
    "die": "default.toml",
    "coin": "coin.toml",
    "pendulum": "pendulum.toml",
    "heavy_top": "heavy_top.toml",
    "ball_in_bowl": "ball_in_bowl.toml",
    "thick_coin": "thick_coin.toml",
    "roulette": "roulette.toml",
}


def example_path(name: str) -> Path:
    """Path of the shipped example scene `name` (a key of `EXAMPLES`)."""
    return Path(str(importlib.resources.files("jaxrb") / "scenes" / EXAMPLES[name]))


def scene_path(arg: str | None) -> Path:
    """The scene file for a command-line argument: None -> the default (the die); an existing
    file; else an example's name; else the path as given (reading it reports it missing)."""
    if arg is None:
        return example_path(next(iter(EXAMPLES)))
    if not Path(arg).exists() and arg in EXAMPLES:
        return example_path(arg)
    return Path(arg)


def example_titles() -> list[tuple[str, str]]:
    """(name, title) of every shipped example, in `EXAMPLES` order."""
    rows = []
    for name in EXAMPLES:
        data = tomllib.loads(example_path(name).read_text(encoding="utf-8"))
        rows.append((name, data.get("title", "")))
    return rows
