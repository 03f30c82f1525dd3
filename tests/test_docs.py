"""The documentation site builds with `mkdocs build --strict` (notebooks rendered, not run).

The same build backs the other checks: every public name has an entry in the API reference,
every notebook and the command line's help have pages, the home page's quick start is the
README's.
"""

import importlib
import os
import re
import subprocess
import sys
import types
from pathlib import Path

import pytest

pytest.importorskip("mkdocs", reason="the docs test needs the [test] extra (mkdocs and plugins)")
pytest.importorskip("mkdocs_jupyter", reason="the docs test needs the [test] extra")
pytest.importorskip("mkdocstrings_handlers.python", reason="the docs test needs the [test] extra")

ROOT = Path(__file__).resolve().parent.parent
SUBPACKAGES = ("analytic", "contact", "dice", "fit", "inertia", "plotting")  # each has its API page


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp("docs") / "site"
    env = {k: v for k, v in os.environ.items() if k != "JAXRB_DOCS_EXECUTE"}
    env["NO_MKDOCS_2_WARNING"] = "1"  # the theme's banner, not a warning about the site
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, f"mkdocs build --strict failed:\n{proc.stdout}\n{proc.stderr}"
    return out


def _public_names(module) -> list[str]:
    names = getattr(module, "__all__", None) or dir(module)
    return [
        n
        for n in names
        if not n.startswith("_") and not isinstance(getattr(module, n), types.ModuleType)
    ]


def _anchors(site) -> set[str]:
    text = "".join(p.read_text(encoding="utf-8") for p in (site / "api").rglob("index.html"))
    return set(re.findall(r'id="(jaxrb\.[\w.]+)"', text))


def test_site_builds(site):
    for page in ("index", "cli/index", "scene-files/index", "theory/index", "contact/index"):
        assert (site / f"{page}.html").is_file(), page
    assert (site / "img" / "contact_throws.png").is_file()
    assert (site / "img" / "contact_throws_polyhedra.png").is_file()


def test_api_reference_covers_public_api(site):
    import jaxrb

    anchors = _anchors(site)
    expected = [f"jaxrb.{n}" for n in _public_names(jaxrb)]
    for sub in SUBPACKAGES:
        module = importlib.import_module(f"jaxrb.{sub}")
        expected += [f"jaxrb.{sub}.{n}" for n in _public_names(module)]
    missing = [name for name in expected if name not in anchors]
    assert not missing, f"public names without an entry in docs/api/: {missing}"


def test_every_notebook_has_a_page(site):
    notebooks = sorted((ROOT / "notebooks").glob("[0-9][0-9]_*.py"))
    assert notebooks
    home = (site / "index.html").read_text(encoding="utf-8")
    for nb in notebooks:
        assert (site / "notebooks" / nb.stem / "index.html").is_file(), nb.name
        assert f"notebooks/{nb.stem}/" in home, f"{nb.name} is not in the site's navigation"


def test_cli_page_has_the_help(site):
    page = (site / "cli" / "index.html").read_text(encoding="utf-8")
    for command in ("jaxrb", "jaxrb run", "jaxrb sweep", "jaxrb fit", "jaxrb bench"):
        assert f"usage: {command} " in page, command


def test_home_page_quick_start_is_the_readmes():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    home = (ROOT / "docs" / "index.md").read_text(encoding="utf-8")
    quick_start = readme.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```bash\n(.*?)```", quick_start, flags=re.S)
    assert blocks
    for block in blocks:
        assert block in home, f"docs/index.md lacks the README's quick-start command {block!r}"
