"""The documentation site builds with warnings as errors, and no link of it or of README.md is broken.

``mkdocs build --strict`` (mkdocs.yml at the repository root, the pages in docs/) into a temporary directory:
with ``validation:`` in mkdocs.yml, a link to a page, an image or an anchor that does not exist is a warning,
and --strict makes it an error (a copy of the pages with three broken links shows that it does). README.md is not
a page of the site, so its links are checked here: each reaches a file of the repository and, into docs/, a
heading of the built page. Every page is in the navigation and linked from README.md, and the built site loads
nothing from the network (no fonts or scripts from a CDN).
"""
from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from graphproc import REPO

pytestmark = pytest.mark.unit

CONFIG = REPO / "mkdocs.yml"
DOCS = REPO / "docs"
README = REPO / "README.md"
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
THE_TWO_COMMANDS = ("scripts/run_experiment.sh", "scripts/test.sh")


def build(config: Path, site: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(config),
                           "--site-dir", str(site)], capture_output=True, text=True, timeout=120, cwd=config.parent)


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp("site")
    r = build(CONFIG, out)
    assert r.returncode == 0 and "WARNING" not in r.stderr, r.stderr
    return out


def config():
    return yaml.safe_load(CONFIG.read_text())


def nav_pages(nav):
    for item in nav:
        for value in (item.values() if isinstance(item, dict) else [item]):
            yield from (nav_pages(value) if isinstance(value, list) else [value])


@pytest.mark.cli
def test_the_site_builds_with_warnings_as_errors(site):
    pages = sorted(p.stem for p in DOCS.glob("*.md"))
    assert sorted(p.stem for p in site.glob("*.html") if p.stem not in ("404", "search")) == pages


def test_every_page_is_in_the_navigation_and_broken_anchors_are_errors():
    c = config()
    assert c["docs_dir"] == "docs"
    assert sorted(nav_pages(c["nav"])) == sorted(p.name for p in DOCS.glob("*.md"))
    links = c["validation"]["links"]
    assert links["not_found"] == links["anchors"] == "warn", links   # warnings, so --strict fails on them


@pytest.mark.cli
def test_a_broken_link_fails_the_build(tmp_path):
    """Not vacuous: a missing page, a missing anchor and a missing image each fail the strict build."""
    shutil.copytree(DOCS, tmp_path / "docs")
    shutil.copy(CONFIG, tmp_path / "mkdocs.yml")
    page = tmp_path / "docs" / "index.md"
    page.write_text(page.read_text() + "\n[a](no-such-page.md) [b](laws.md#no-such-heading) ![c](figures/none.png)\n")
    r = build(tmp_path / "mkdocs.yml", tmp_path / "site")
    assert r.returncode != 0, r.stderr
    for target in ("no-such-page.md", "#no-such-heading", "figures/none.png"):
        assert target in r.stderr, (target, r.stderr)


def anchors(html: Path):
    return set(re.findall(r'\bid="([^"]+)"', html.read_text()))


def broken_links(text: str, base: Path, site: Path):
    """Every relative link of the Markdown ``text`` (a file in ``base``) that reaches no file, or, into docs/, no
    heading of the built page."""
    bad = []
    for target in LINK.findall(text):
        if re.match(r"[a-z]+:", target):
            continue   # a URL
        path, _, anchor = target.partition("#")
        file = (base / path).resolve() if path else None
        if file is None or not file.exists():
            bad.append(f"{target}: no file {path!r}")
        elif anchor and file.parent == DOCS and file.suffix == ".md":
            if anchor not in anchors(site / (file.stem + ".html")):
                bad.append(f"{target}: {path} has no heading #{anchor}")
    return bad


@pytest.mark.cli
def test_every_readme_link_reaches_a_file_and_a_heading(site):
    text = README.read_text()
    assert LINK.findall(text)
    assert broken_links(text, REPO, site) == []


@pytest.mark.cli
def test_a_broken_readme_link_is_caught(site):
    bad = broken_links("[x](docs/laws.md#over-the-sweeps) [y](docs/laws.md#no-such) [z](docs/none.md) "
                       "[w](config/none.yaml) [v](https://example.com/x)", REPO, site)
    assert bad == ["docs/laws.md#no-such: docs/laws.md has no heading #no-such", "docs/none.md: no file 'docs/none.md'",
                   "config/none.yaml: no file 'config/none.yaml'"]


def test_the_readme_is_the_door_the_two_commands_and_every_page():
    text = README.read_text()
    first_screen = "\n".join(text.splitlines()[:25])
    for command in THE_TWO_COMMANDS:
        assert re.search(rf"^{re.escape(command)}\s+#", first_screen, re.M), command
    linked = {Path(t.partition("#")[0]).name for t in LINK.findall(text) if t.startswith("docs/")}
    assert linked >= {p for p in nav_pages(config()["nav"]) if p != "index.md"}, linked
    assert len(text.splitlines()) <= 60


@pytest.mark.cli
def test_the_site_loads_nothing_from_the_network(site):
    remote = re.compile(r"""<(?:link|script|img)\b[^>]*\b(?:href|src)=["'](?:https?:)?//|@import\s+url\(["']?"""
                        r"""(?:https?:)?//|url\(["']?(?:https?:)?//""", re.I)
    found = [f"{p.relative_to(site)}: {m.group(0)}" for p in site.rglob("*") if p.suffix in (".html", ".css")
             for m in remote.finditer(p.read_text(errors="replace"))]
    assert found == []
    assert remote.search('<script src="https://cdnjs.example/highlight.min.js">')   # the pattern finds one
