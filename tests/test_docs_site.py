"""The documentation site as a reader sees it: built with ``mkdocs build --strict`` and every
page opened in headless Chromium at a laptop's width (1280 px) and a phone's (390 px).

Nothing may be cut off: no element whose content is wider than its box without a scrollbar to
reach the rest, nothing sticking out past the edge of the page, and no page that scrolls
sideways. At 1280 px every code block, table and signature fits its box whole: a reader whose
scrollbars show only while scrolling (macOS, phones) would see a command end at ``--o`` with
no sign that it goes on. At 390 px code blocks and tables may scroll sideways; the rest wraps.

Needs the docs extra (``pip install -e ".[docs]"``) and Chromium (tests/conftest.py).
"""

from __future__ import annotations

import html
import io
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"

# Each page of the site: docs/a/b.md is built into a/b/index.html, docs/a/index.md into
# a/index.html; the labs' notebooks are pages as well.
SOURCES = sorted([*DOCS.rglob("*.md"), *(DOCS / "labs").glob("*.ipynb")])


def built_page(source: Path) -> str:
    relative = source.relative_to(DOCS).with_suffix("")
    if relative.name == "index":
        return (relative.parent / "index.html").as_posix().removeprefix("./")
    return (relative / "index.html").as_posix()


PAGES = [built_page(source) for source in SOURCES]
WIDTHS = {"laptop": 1280, "phone": 390}

# What a reader cannot see, found in the page's article (the menus are the theme's own):
#   "page": the page itself is wider than the window, so it scrolls sideways;
#   "clipped": an element cuts its own content off and gives no scrollbar to reach it;
#   "sticks out": an element reaches past the box that holds it (or the window), where that
#       box cuts it off or gives no scrollbar;
#   "scrolls": an element's content is wider than its box, reached through its scrollbar.
FIND_CUT_OFF = """
() => {
  const found = [];
  const width = document.documentElement.clientWidth;
  const wide = Math.max(document.documentElement.scrollWidth, document.body.scrollWidth);
  if (wide > width + 1) found.push({what: "page", detail: `${wide} px in a ${width} px window`});
  const name = (el) => {
    const text = (el.innerText || el.getAttribute("alt") || el.getAttribute("src") || "")
      .trim().replace(/\\s+/g, " ").slice(0, 70);
    return `<${el.tagName.toLowerCase()}> ${text}`;
  };
  const scrolls = (el) => ["auto", "scroll"].includes(getComputedStyle(el).overflowX);
  const article = document.querySelector(".md-content") || document.body;
  for (const el of article.querySelectorAll("*")) {
    const style = getComputedStyle(el);
    const box = el.getBoundingClientRect();
    if (style.visibility === "hidden" || box.width === 0 || box.height === 0) continue;
    const wider = el.scrollWidth > el.clientWidth + 1;
    const sizes = `${el.scrollWidth} px in ${el.clientWidth}: ${name(el)}`;
    if (wider && ["hidden", "clip"].includes(style.overflowX))
      found.push({what: "clipped", detail: sizes});
    if (wider && scrolls(el)) found.push({what: "scrolls", detail: sizes});
    let holder = el.parentElement;
    while (holder && holder !== document.body && getComputedStyle(holder).overflowX === "visible")
      holder = holder.parentElement;
    const held = holder && holder !== document.body;
    const edge = held ? holder.getBoundingClientRect().right : width;
    if (box.right > edge + 1 && !(held && scrolls(holder))) {
      const past = `to ${Math.round(box.right)} px of ${Math.round(edge)}: ${name(el)}`;
      found.push({what: "sticks out", detail: past});
    }
  }
  return found;
}
"""


@pytest.fixture(scope="session")
def site(tmp_path_factory) -> Path:
    """The site, built as CI builds it: a warning (a broken link, a page out of the nav) fails."""
    for module in ("mkdocs", "material", "mkdocstrings", "mkdocs_jupyter"):
        pytest.importorskip(module, reason='builds the docs site: pip install -e ".[docs]"')
    folder = tmp_path_factory.mktemp("site")
    built = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--quiet", "--site-dir", folder],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
        timeout=600,
    )
    assert built.returncode == 0, built.stderr[-3000:]
    return folder


@pytest.fixture(scope="session")
def windows(browser):
    """One browser tab per width. The site asks the network for its fonts only: the pages are
    read with the fonts the machine has, as a reader offline reads them."""
    tabs = {}
    for label, width in WIDTHS.items():
        context = browser.new_context(viewport={"width": width, "height": 900})
        context.route(
            "**/*",
            lambda route: (
                route.continue_()
                if route.request.url.startswith(("file:", "data:", "about:"))
                else route.abort()
            ),
        )
        tabs[label] = context.new_page()
    yield tabs
    for tab in tabs.values():
        tab.context.close()


def test_every_page_of_the_docs_folder_is_a_page_of_the_site(site):
    built = sorted(
        path.relative_to(site).as_posix()
        for path in site.rglob("index.html")
        if path.parent.name not in {"assets", "search"} and path.parent != site / "404"
    )
    assert built == sorted(PAGES)


def cut_off(tab, site: Path, page: str) -> list[dict]:
    tab.goto((site / page).as_uri())
    tab.wait_for_load_state("load")
    return tab.evaluate(FIND_CUT_OFF)


@pytest.mark.parametrize("page", PAGES)
@pytest.mark.parametrize("label", WIDTHS)
def test_nothing_on_the_page_is_cut_off(site, windows, label, page):
    found = cut_off(windows[label], site, page)
    allowed = {"scrolls"} if label == "phone" else set()
    cut = [f"{f['what']}: {f['detail']}" for f in found if f["what"] not in allowed]
    assert not cut, "\n".join(cut)


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES)
@pytest.mark.parametrize("label", WIDTHS)
def test_the_whole_page_screenshot_is_the_windows_width(site, windows, label, page, tmp_path):
    # The reader has nothing to the right to scroll to. FOOSBALL_DOCS_SCREENSHOTS=FOLDER keeps
    # the screenshots there, to look at.
    from PIL import Image

    tab = windows[label]
    tab.goto((site / page).as_uri())
    tab.wait_for_load_state("load")
    shot = Image.open(io.BytesIO(tab.screenshot(full_page=True)))
    folder = Path(os.environ.get("FOOSBALL_DOCS_SCREENSHOTS") or tmp_path)
    folder.mkdir(parents=True, exist_ok=True)
    name = page.removesuffix("index.html").strip("/").replace("/", "_") or "home"
    shot.save(folder / f"{name}-{WIDTHS[label]}.png")
    assert shot.width == WIDTHS[label], shot.size


def test_the_checks_find_a_command_cut_off_and_a_picture_too_wide_for_a_phone(site, windows):
    # A page of the site given a line longer than any code block and a picture 600 px wide.
    text = (site / "getting-started" / "index.html").read_text()
    long_line = "foosball train Foosball-Block-v0" + " --option value" * 30
    text = text.replace(
        "<h1",
        f'<pre><code>{long_line}</code></pre><p><img src="x.png" '
        'style="width: 600px; height: 10px; max-width: none"></p><h1',
        1,
    )
    (site / "getting-started" / "cut-off.html").write_text(text)
    page = "getting-started/cut-off.html"
    laptop = {found["what"] for found in cut_off(windows["laptop"], site, page)}
    phone = {found["what"] for found in cut_off(windows["phone"], site, page)}
    assert laptop == {"scrolls"}, laptop
    assert {"scrolls", "sticks out"} <= phone, phone


BUILTIN = ROOT / "foosball_gym" / "builtin"
SHELL_BLOCK = re.compile(r"^```bash\n(.*?)^```", re.S | re.M)
CODE = re.compile(
    r'<div class="language-bash highlight"><pre><span></span><code>(.*?)</code>', re.S
)


def test_every_shipped_policy_has_a_page_of_the_site():
    shipped = {path.parent.name for path in BUILTIN.glob("*/REPRODUCE.md")}
    pages = {path.stem for path in (DOCS / "results" / "shipped").glob("*.md")}
    assert shipped == pages


@pytest.mark.parametrize("name", sorted(p.parent.name for p in BUILTIN.glob("*/REPRODUCE.md")))
def test_a_shipped_policys_page_gives_the_commands_of_its_reproduce_file(site, name):
    # The page is the file that ships with the policy; a command longer than the page is
    # continued over lines, which the shell joins back into the command as written.
    written = [
        line
        for block in SHELL_BLOCK.findall((BUILTIN / name / "REPRODUCE.md").read_text())
        for line in block.splitlines()
        if line.strip()
    ]
    assert any(line.startswith("foosball ") for line in written), name
    page = (site / "results" / "shipped" / name / "index.html").read_text()
    shown = [html.unescape(re.sub(r"<[^>]+>", "", code)) for code in CODE.findall(page)]
    joined = "\n".join(code.replace(" \\\n  ", " ") for code in shown)
    assert all(line in joined.splitlines() for line in written), (written, shown)
    assert max(len(line) for code in shown for line in code.splitlines()) <= 100
