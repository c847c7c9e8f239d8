"""The site's pages read as pages: no rendered paragraph or list item over 150 words, no
Markdown left unrendered (a literal `**`, a `](`, a definition list made by accident),
code blocks that wrap inside their box, and a benchmarks page that says for each figure
whether its target is met.

The site is built once (`mkdocs build --strict`) and its HTML read with the standard
library's parser; only the page's article is read, not the navigation around it.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
# docs/hooks.py, the build hook that draws the benchmarks page and links the citations,
# loaded from its file (docs/ is not a package).
_SPEC = importlib.util.spec_from_file_location("docs_hooks", DOCS / "hooks.py")
assert _SPEC is not None
assert _SPEC.loader is not None
hooks = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(hooks)

MAX_WORDS = 150

BLOCK_TAGS = {"p", "li", "dt", "dd", "td", "th", "h1", "h2", "h3", "h4", "h5", "h6"}
LIST_TAGS = {"ul", "ol", "dl", "table", "pre", "div", "p"}
VOID_TAGS = {"br", "img", "hr", "input", "meta", "link", "wbr", "source", "col", "area"}


class Article(HTMLParser):
    """The text blocks of a page's article: each <p>, <li>, <dt>, <dd> and table cell
    with its own text (a nested list's or paragraph's text is its own block, not its
    parent's), and whether it sits in code (inline code counts as words, but is left out
    of the broken-Markdown check)."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.depth = 0  # > 0 inside the article
        self.stack: list[dict[str, object]] = []
        # (tag, its text with spaces collapsed, its text outside code as written)
        self.blocks: list[tuple[str, str, str]] = []
        self.code = 0
        self.skip = 0  # inside a headerlink or a script

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        classes = (dict(attrs).get("class") or "").split()
        if tag == "article" and "md-content__inner" in classes:
            self.depth = 1
            return
        if not self.depth or tag in VOID_TAGS:
            return
        if tag == "article":
            self.depth += 1
        if tag in ("script", "style") or (tag == "a" and "headerlink" in classes):
            self.skip += 1
            self.stack.append({"tag": tag, "skip": True})
            return
        if tag in ("code", "pre"):
            self.code += 1
        if tag in BLOCK_TAGS:
            self.stack.append({"tag": tag, "text": [], "plain": [], "block": True})
        elif tag in LIST_TAGS:
            self.stack.append({"tag": tag, "barrier": True})
        else:
            self.stack.append({"tag": tag})

    def handle_endtag(self, tag: str) -> None:
        if not self.depth or tag in VOID_TAGS:
            return
        if tag == "article":
            self.depth -= 1
            return
        while self.stack:
            entry = self.stack.pop()
            if entry.get("skip"):
                self.skip -= 1
            if entry["tag"] in ("code", "pre"):
                self.code -= 1
            if entry.get("block"):
                text = " ".join("".join(entry["text"]).split())  # type: ignore[arg-type]
                plain = "".join(entry["plain"]).strip()  # type: ignore[arg-type]
                self.blocks.append((str(entry["tag"]), text, plain))
            if entry["tag"] == tag:
                break

    def handle_data(self, data: str) -> None:
        if not self.depth or self.skip:
            return
        for entry in reversed(self.stack):
            if entry.get("barrier"):
                return
            if entry.get("block"):
                entry["text"].append(data)  # type: ignore[attr-defined]
                entry["plain"].append(" " if self.code else data)  # type: ignore[attr-defined]
                return


def blocks_of(html: str) -> list[tuple[str, str, str]]:
    parser = Article()
    parser.feed(html)
    parser.close()
    return parser.blocks


def words(text: str) -> int:
    return len(text.split())


def source_of(page: Path, site: Path) -> str:
    """The docs/ path of a built page (`site/explanation/models/index.html` is
    `explanation/models.md`)."""
    relative = page.parent.relative_to(site).as_posix()
    return "index.md" if relative == "." else f"{relative}.md"


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    mkdocs = shutil.which("mkdocs", path=str(Path(sys.executable).parent)) or shutil.which("mkdocs")
    assert mkdocs, "mkdocs is in the test extra"
    out = tmp_path_factory.mktemp("site") / "site"
    result = subprocess.run(
        [mkdocs, "build", "--strict", "--site-dir", str(out)],
        cwd=ROOT,
        env=dict(os.environ, NO_MKDOCS_2_WARNING="1"),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr[-4000:]
    return out


def pages(site: Path) -> list[tuple[str, list[tuple[str, str, str]]]]:
    found = []
    for page in sorted(site.rglob("index.html")):
        source = source_of(page, site)
        if not (DOCS / source).is_file():
            continue
        found.append((source, blocks_of(page.read_text(encoding="utf-8"))))
    return found


# The parser, on hand-written HTML.


def test_a_list_items_own_text_leaves_its_nested_list_out() -> None:
    html = (
        '<nav><p>navigation</p></nav><article class="md-content__inner md-typeset">'
        "<ul><li>one two <code>three</code><ul><li>four five</li></ul> six</li></ul>"
        '<h2>Title<a class="headerlink" href="#t">¶</a></h2>'
        "<p>a <strong>b</strong> c</p></article><footer><p>footer</p></footer>"
    )
    blocks = blocks_of(html)
    assert ("li", "four five", "four five") in blocks
    assert ("li", "one two three six", "one two   six") in blocks
    assert ("h2", "Title", "Title") in blocks
    assert ("p", "a b c", "a b c") in blocks
    assert len(blocks) == 4  # nothing from the navigation or the footer


def test_source_of_a_built_page() -> None:
    site = Path("/s")
    assert source_of(site / "index.html", site) == "index.md"
    assert source_of(site / "explanation" / "models" / "index.html", site) == (
        "explanation/models.md"
    )


# The built site.


@pytest.mark.slow
def test_no_paragraph_or_list_item_over_150_words(site: Path) -> None:
    long = [
        f"{source}: <{tag}> of {words(text)} words: {text[:80]}..."
        for source, blocks in pages(site)
        for tag, text, _ in blocks
        if tag in ("p", "li", "dd", "td") and words(text) > MAX_WORDS
    ]
    assert not long, "\n".join(long)


@pytest.mark.slow
def test_no_markdown_left_unrendered(site: Path) -> None:
    broken = []
    for source, blocks in pages(site):
        for tag, text, plain in blocks:
            if "**" in plain or "](" in plain or "``" in plain:
                broken.append(f"{source}: <{tag}> holds raw Markdown: {text[:100]}")
            item = re.search(r"\n[ \t]*(?:[-*+]|\d+\.) \S.{0,60}", plain)
            if item:
                broken.append(f"{source}: a list item inside a <{tag}>: {item.group().strip()}")
            if tag == "p" and plain.startswith(": "):
                broken.append(f"{source}: <p> starts with ': ' (a definition list?): {text[:80]}")
            if tag == "dt" and words(text) > 12:
                broken.append(f"{source}: a sentence rendered as a definition: {text[:80]}")
    assert not broken, "\n".join(broken)


def css_rules(css: str) -> list[tuple[str, dict[str, str]]]:
    """The rules of a style sheet without nesting: (selector, {property: value})."""
    css = re.sub(r"/\*.*?\*/", "", css, flags=re.DOTALL)
    rules = []
    for selector, body in re.findall(r"([^{}]+)\{([^{}]*)\}", css):
        declarations = {}
        for declaration in body.split(";"):
            if ":" in declaration:
                name, value = declaration.split(":", 1)
                declarations[name.strip().lower()] = value.strip().lower()
        rules.append((" ".join(selector.split()), declarations))
    return rules


def test_css_rules_are_read() -> None:
    rules = css_rules("/* c { x: y } */ a > b , c { white-space: pre-wrap; overflow : hidden }")
    assert rules == [("a > b , c", {"white-space": "pre-wrap", "overflow": "hidden"})]


@pytest.mark.slow
def test_code_blocks_wrap_inside_their_box(site: Path) -> None:
    """A code block's long line wraps (so nothing is cut at the right at any width, and
    the copy button over the top right corner hides no text), and no style of the
    site's own clips a block or stops it wrapping."""
    import yaml

    class Loader(yaml.SafeLoader):
        pass

    Loader.add_multi_constructor("", lambda loader, suffix, node: None)
    config = yaml.load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"), Loader=Loader)
    sheets = config.get("extra_css", [])
    assert sheets, "mkdocs.yml has extra_css"
    rules = [rule for sheet in sheets for rule in css_rules((DOCS / sheet).read_text("utf-8"))]
    wrap = [
        declarations
        for selector, declarations in rules
        if any(re.search(r"\bpre\s*>\s*code$", part.strip()) for part in selector.split(","))
    ]
    assert any(d.get("white-space") in ("pre-wrap", "break-spaces") for d in wrap), wrap
    assert any(d.get("overflow-wrap") in ("anywhere", "break-word") for d in wrap), wrap
    for selector, declarations in rules:
        if re.search(r"\b(pre|code|highlight)\b", selector):
            for name in ("overflow", "overflow-x"):
                assert declarations.get(name) not in ("hidden", "clip"), (selector, declarations)
            white_space = declarations.get("white-space")
            assert white_space not in ("pre", "nowrap"), (selector, declarations)
    # Every page links the sheets, and its code blocks are the ones the rule selects
    # (`pre > code` inside the article) with no inline style of their own.
    for page in sorted(site.rglob("index.html")):
        html = page.read_text(encoding="utf-8")
        links = re.findall(r'<link rel="stylesheet" href="([^"]+)"', html)
        theme = [i for i, href in enumerate(links) if "/main." in href or href.startswith("main.")]
        for sheet in sheets:
            ours = [i for i, href in enumerate(links) if href.endswith(sheet)]
            assert ours, f"{page} does not link {sheet}"
            # after the theme's sheet, so that its rules win over the theme's equal ones
            assert theme, f"{page} links no theme CSS"
            assert ours[0] > theme[0], f"{page}: {sheet} before the theme's CSS"
        assert not re.search(r"<(pre|code)[^>]*style=", html), f"{page}: a code block with a style"
        for pre in re.findall(r"<pre[^>]*>(.{0,40})", html):
            assert "<code" in pre, f"{page}: a <pre> without <code> inside: {pre}"


# The benchmarks page: each figure's target and whether it is met.


def figure(target: str = "", check: str = "", unit: str = "", format: str = "") -> dict[str, str]:
    entry = {"what": "a figure", "unit": unit, "target": target, "check": check}
    if format:
        entry["format"] = format
    return entry


@pytest.mark.parametrize(
    ("target", "value", "unit", "format", "met"),
    [
        ("<= 0.5", 0.5, "x", "", "yes"),  # the bound itself meets a <=
        ("<= 0.5", 0.5001, "x", "", "no"),
        ("< 2 ms", 2.0, "ms", "", "no"),  # but not a <
        ("< 2 ms", 1.99, "ms", "", "yes"),
        ("<= 30 s", 24.8, "s", "", "yes"),
        ("<= 30 s", 30.2, "s", "", "no"),
        (">= 10 %", 0.1387, "", ".0%", "yes"),  # a percent target against a fraction
        (">= 10 %", 0.099, "", ".0%", "no"),
        ("<= 5 %", 0.065, "", ".1%", "no"),
        (">= 1.8x", 1.91, "x", "", "yes"),
        (">= 19 of 21 on each seed", "20 of 21", "", "", "yes"),
        (">= 19 of 21 on each seed", "18 of 21", "", "", "no"),
        ("6 of 6 on each seed", 6, "of 6", "", "yes"),  # no sign: equal
        ("6 of 6 on each seed", 5, "of 6", "", "no"),
        ("<= 2 of 27", 4, "of 27", "", "no"),
        ("0.90-0.98", 0.921, "", "", "yes"),
        ("0.90-0.98", 0.99, "", "", "no"),
        ("> 0", -0.01, "", "", "no"),
        ("", 3.0, "s", "", "no target"),
    ],
)
def test_a_target_is_judged_against_the_value(
    target: str, value: object, unit: str, format: str, met: str
) -> None:
    assert hooks.judge(figure(target, unit=unit, format=format), {}, value) == met


def test_a_check_judges_a_target_in_words() -> None:
    data = {"named": ["practice"], "plain": {"rmse": 2.2}}
    near = figure("RMS z near 1", check=">= 0.75 and <= 1.25")
    assert hooks.judge(near, data, "1.86 (8 of 27 beyond 1.96 SE)") == "no"
    assert hooks.judge(near, data, "0.98 (1 of 27 beyond 1.96 SE)") == "yes"
    named = figure(">= 0.30, practice named", check=">= 0.30 and named contains practice")
    assert hooks.judge(named, data, 0.31) == "yes"
    assert hooks.judge(named, data, 0.02) == "no"
    assert hooks.judge(figure("x", check="named contains fatigue"), data, 1.0) == "no"
    against = figure("<= the plain fit's", check="<= @plain.rmse")
    assert hooks.judge(against, data, 1.8) == "yes"
    assert hooks.judge(against, data, 2.3) == "no"


@pytest.mark.parametrize("target", ["about 8 Hz", "near 1", "<= 0.5, and named"])
def test_a_target_the_build_cannot_read_stops_it(target: str) -> None:
    with pytest.raises(ValueError, match="give the figure a check"):
        hooks.judge(figure(target), {}, 1.0)


def test_a_check_the_build_cannot_read_stops_it() -> None:
    with pytest.raises(ValueError, match="is not OP NUMBER, OP @KEY or KEY contains WORD"):
        hooks.judge(figure("near 1", check="about 1"), {}, 1.0)


def test_a_target_in_another_unit_stops_the_build() -> None:
    with pytest.raises(ValueError, match="is in ms, the value in s"):
        hooks.judge(figure("<= 2 ms", unit="s"), {}, 1.0)


def test_the_table_counts_the_misses_and_names_each_area_once(tmp_path: Path) -> None:
    (tmp_path / "r.json").write_text(json.dumps({"a": 0.4, "b": 0.7, "c": 3}), encoding="utf-8")
    index = tmp_path / "index.toml"
    rows = [("Loop", "a", "<= 0.5"), ("Fit", "b", "<= 0.5"), ("Loop", "c", "")]
    index.write_text(
        "".join(
            f'[[figure]]\narea = "{area}"\nwhat = "figure {key}"\nfile = "r.json"\n'
            f'key = "{key}"\ntarget = "{target}"\ncommand = "run {key}"\n\n'
            for area, key, target in rows
        ),
        encoding="utf-8",
    )
    page = hooks.table(hooks.figure_rows(index, tmp_path))
    assert page.startswith("1 of 2 targets met. Missed:\n\n- Fit: figure b (0.7, target <= 0.5)\n")
    assert page.count("### Loop") == 1
    assert page.count("### Fit") == 1
    assert page.index("### Loop") < page.index("### Fit")
    assert "| measure | value | target | met | command |" in page
    assert "| figure a | 0.4 | <= 0.5 | yes | `run a` |" in page
    assert "| figure c | 3 |  | no target | `run c` |" in page


def test_every_figure_of_the_index_is_judged() -> None:
    rows = hooks.figure_rows()
    assert rows
    assert all(row["met"] in ("yes", "no", "no target") for row in rows)
    assert all(row["met"] == "no target" for row in rows if not row["target"])


def test_a_list_swallowed_by_a_paragraph_is_seen() -> None:
    html = (
        '<article class="md-content__inner md-typeset"><p>the end of one item.\n'
        "- <strong>Next</strong> item, read as text</p></article>"
    )
    [(_, _, plain)] = blocks_of(html)
    assert re.search(r"\n[ \t]*(?:[-*+]|\d+\.) \S", plain)


# Citations: every `[key]` of the bibliography a link to its entry.


def test_a_citation_key_becomes_a_link_outside_code_and_links() -> None:
    html = (
        "<p>the drive ([endovascular], III-B) and [notes]; not [other],</p>"
        "<pre><code>[endovascular]</code></pre><p><code>[notes]</code> "
        '<a href="x">[notes]</a> <span title="[notes]">t</span></p>'
    )
    linked = hooks.link_citations(html, ["endovascular", "notes"], "../bibliography/")
    assert linked == (
        '<p>the drive (<a href="../bibliography/#endovascular">[endovascular]</a>, III-B) '
        'and <a href="../bibliography/#notes">[notes]</a>; not [other],</p>'
        "<pre><code>[endovascular]</code></pre><p><code>[notes]</code> "
        '<a href="x">[notes]</a> <span title="[notes]">t</span></p>'
    )
    assert hooks.link_citations(html, [], "b/") == html


def test_the_link_to_the_bibliography_from_any_page() -> None:
    assert hooks.relative_url("bibliography/", "") == "bibliography/"
    assert hooks.relative_url("bibliography/", "explanation/models/") == "../../bibliography/"
    assert hooks.relative_url("bibliography.html", "explanation/models.html") == (
        "../bibliography.html"
    )


def test_the_bibliographys_keys_are_read() -> None:
    keys = hooks.citation_keys()
    assert {"endovascular", "notes", "emps"} <= set(keys)
    entry = hooks.anchor_entries("<li><strong>[notes]</strong> N.</li>", keys)
    assert entry == '<li><strong id="notes">[notes]</strong> N.</li>'


@pytest.mark.slow
def test_every_citation_on_the_site_links_to_its_entry(site: Path) -> None:
    keys = hooks.citation_keys()
    raw = re.compile(r"\[(" + "|".join(map(re.escape, keys)) + r")\]")
    unlinked = []
    for page in sorted(site.rglob("index.html")):
        source = source_of(page, site)
        html = page.read_text(encoding="utf-8")
        if source == "bibliography.md":
            missing = [key for key in keys if f'id="{key}"' not in html]
            assert not missing, f"bibliography entries without an anchor: {missing}"
            continue
        text = re.sub(r"<pre\b.*?</pre>|<code\b.*?</code>|<a\b.*?</a>", "", html, flags=re.DOTALL)
        unlinked += [f"{source}: [{key}]" for key in raw.findall(text)]
    assert not unlinked, "citations that are not links: " + ", ".join(sorted(set(unlinked)))


@pytest.mark.slow
def test_the_built_benchmarks_page_has_each_heading_once_and_a_met_column(site: Path) -> None:
    blocks = blocks_of((site / "benchmarks" / "index.html").read_text(encoding="utf-8"))
    headings = [text for tag, text, _ in blocks if tag in ("h2", "h3")]
    assert len(headings) == len(set(headings)), headings
    header_cells = [text for tag, text, _ in blocks if tag == "th"]
    assert header_cells.count("met") == len(headings)  # one met column per area's table
    counted = [text for tag, text, _ in blocks if tag == "p" and "targets met" in text]
    assert counted, "the page counts the targets met"
