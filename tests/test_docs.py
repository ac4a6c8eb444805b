"""The documentation: the site builds without a warning, every Python block of every page runs, no user page
narrates history.

The site is built by Sphinx from ``docs/`` exactly as the documented command does (warnings are errors, so a
broken internal link, a missing page or a malformed docstring fails). Code blocks are run with Sybil: each
``python`` block of a page runs top to bottom in one namespace per page, in a scratch directory; a block that
starts with ``>>>`` is a doctest, so an output the page states is checked.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
VALIDATION = DOCS / "validation"
GENERATED = (DOCS / "_build", DOCS / "reference" / "api")


def _pages() -> list[Path]:
    pages = [p for p in sorted(DOCS.rglob("*.md")) if not any(g in p.parents for g in GENERATED)]
    return [ROOT / "README.md", *pages]


def _user_pages() -> list[Path]:
    return [p for p in _pages() if VALIDATION not in p.parents]


def _id(path: Path) -> str:
    return str(path.relative_to(ROOT))


# -- every Python block runs ------------------------------------------------------------------------------------
def _sybil():
    from sybil import Sybil
    from sybil.parsers.markdown import PythonCodeBlockParser

    return Sybil(parsers=[PythonCodeBlockParser()], path=str(ROOT))


@pytest.mark.slow
@pytest.mark.parametrize("page", _pages(), ids=_id)
def test_every_python_block_of_the_page_runs(page, tmp_path, monkeypatch):
    pytest.importorskip("sybil", reason="the docs extra: pip install sybil")
    monkeypatch.chdir(tmp_path)  # snippets write files: keep them out of the tree
    if "use_machine_only_config" in page.read_text():
        # liblsl reads its configuration once per process, so a page that sets it runs in a fresh interpreter
        result = subprocess.run([sys.executable, __file__, str(page)], capture_output=True, text=True, timeout=600)
        assert result.returncode == 0, result.stderr[-6000:]
        return
    _run_page(page)


def _run_page(page: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    document = _sybil().parse(page)
    for example in list(document):
        try:
            example.evaluate()
        except Exception as exc:
            raise AssertionError(f"{_id(page)}, line {example.line}: {type(exc).__name__}: {exc}") from exc


def test_the_runner_sees_the_blocks_of_a_page_and_shares_names_between_them(tmp_path):
    pytest.importorskip("sybil")
    page = tmp_path / "page.md"
    page.write_text("text\n\n```python\nx = 2\n```\n\n```bash\nexit 1\n```\n\n```python\n>>> x + 1\n4\n```\n")
    document = _sybil().parse(page)
    examples = list(document)
    assert len(examples) == 2  # the bash block is not run
    examples[0].evaluate()
    with pytest.raises(Exception, match="Expected:\\s+4\\s+Got:\\s+3"):
        examples[1].evaluate()


# -- no user page narrates how settings were tried --------------------------------------------------------------
_ORDINALS = "first|second|third|fourth|fifth|sixth|seventh|eighth|ninth|tenth|eleventh|twelfth|thirteenth|fourteenth"
HISTORY = {
    "a numbered round": re.compile(rf"\b(?:{_ORDINALS}|\d+(?:st|nd|rd|th))\s+round\b|\bround\s+\d+\b", re.I),
    "a numbered session": re.compile(r"\bsessions?\s+\d+", re.I),
    "an issue number": re.compile(r"\b(?:before|since|after|in)\s+issue\s+\d+|\(issue\s+\d+", re.I),
    "a date": re.compile(r"\b20\d\d-\d\d-\d\d\b"),
    "a clock time": re.compile(r"\b\d\d:\d\d(?:[–-]\d\d:\d\d)?\s*UTC\b"),
    "a load average": re.compile(r"\bload average", re.I),
    "a commit hash": re.compile(r"(?<![\w/.-])(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}(?![\w/.-])"),
}


def history_in(text: str) -> list[str]:
    """Every line of ``text`` that narrates how settings were tried, as ``"line N: what: the line"``."""
    found = []
    for number, line in enumerate(text.splitlines(), 1):
        for what, pattern in HISTORY.items():
            if pattern.search(line):
                found.append(f"line {number}: {what}: {line.strip()[:120]}")
    return found


@pytest.mark.parametrize("page", _user_pages(), ids=_id)
def test_no_user_page_narrates_history(page):
    found = history_in(page.read_text(encoding="utf-8"))
    assert not found, f"{_id(page)} narrates history (it belongs in docs/validation/):\n" + "\n".join(found)


@pytest.mark.parametrize(
    ("line", "what"),
    [
        ("### Third round: the judged table", "a numbered round"),
        ("the 12th round kept it", "a numbered round"),
        ("measured in session 16 on seed 9", "a numbered session"),
        ("as declared in e0b7089 from a frozen clone", "a commit hash"),
        ("05:57–06:52 UTC, two processes", "a clock time"),
        ("a load average of 6–7 during the run", "a load average"),
        ("run on 2026-12-03", "a date"),
        ("### Before issue 12: the deliverable's estimator", "an issue number"),
    ],
)
def test_the_history_scan_finds_each_pattern(line, what):
    assert [f.split(": ")[1] for f in history_in(line)] == [what]


def test_the_history_scan_leaves_ordinary_prose_alone():
    text = "Round to 3 digits; float16 weights; seed 9; 1e100; a 10 ms tick; see issue tracker; cafe; 300 s"
    assert history_in(text) == []


def test_the_validation_log_is_not_scanned():
    assert all(VALIDATION not in p.parents for p in _user_pages())
    assert any(VALIDATION in p.parents for p in _pages())


# -- the site builds --------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_the_site_builds_with_warnings_as_errors(tmp_path):
    pytest.importorskip("sphinx", reason="the docs extra: pip install sphinx myst-parser")
    pytest.importorskip("myst_parser", reason="the docs extra: pip install sphinx myst-parser")
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-j", "1", "-q", "-b", "html"]
    cmd += ["-d", str(tmp_path / "doctrees"), str(DOCS), str(tmp_path / "html")]
    result = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr[-6000:]
    html = tmp_path / "html"
    # the generated reference is there: a block's port table, a CLI command
    sync = (html / "reference" / "api" / "cogblocks.sync.html").read_text(encoding="utf-8")
    assert "Ports of OrderParameter" in sync and "Bad data." in sync
    cli = (html / "reference" / "cli.html").read_text(encoding="utf-8")
    assert "cogblocks run sync" in cli and "--policy" in cli


# -- the reference's port tables ---------------------------------------------------------------------------------
def _reference_extension():
    sys.path.insert(0, str(DOCS / "_ext"))
    try:
        import cogblocks_reference
    finally:
        sys.path.remove(str(DOCS / "_ext"))
    return cogblocks_reference


def test_the_port_table_reads_the_declared_specs_of_a_block():
    from cogblocks.sync import OrderParameter

    ports = _reference_extension().declared_ports(OrderParameter)
    assert ports == [
        {"port": "theta", "direction": "input", "shape": "None", "unit": "'rad'", "wrapped": "None"},
        {"port": "r", "direction": "output", "shape": "()", "unit": "'1'", "wrapped": "False"},
    ]


def test_every_literal_spec_in_a_port_table_is_the_spec_the_block_declares():
    # independent check: the blocks that build without arguments declare at run time what the table says
    import ast
    import warnings

    from cogblocks.catalogue import public_blocks

    ext = _reference_extension()
    checked = 0
    for cls in public_blocks().values():
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                block = cls()
        except Exception:  # needs parameters: its specs depend on them, shown as expressions
            continue
        ports = {**block._inputs, **block._outputs}
        for row in ext.declared_ports(cls):
            port = ports.get(row["port"])
            if port is None or port.spec is None:
                continue
            spec = getattr(port, "declared", port.spec)
            for field in ("shape", "unit", "wrapped"):
                try:
                    value = ast.literal_eval(row[field])
                except (KeyError, ValueError, SyntaxError):
                    continue  # generic, or computed from a parameter
                assert getattr(spec, field) == (tuple(value) if field == "shape" and value is not None else value), (
                    cls.__name__,
                    row,
                )
                checked += 1
    assert checked >= 20


def test_the_api_pages_cover_every_public_block():
    from cogblocks.catalogue import package_of, public_blocks

    pages = _reference_extension().api_pages()
    documented = {(module, name) for entries in pages.values() for module, names in entries for name in names}
    missing = [n for n, cls in public_blocks().items() if (package_of(cls), n) not in documented]
    assert not missing


if __name__ == "__main__":  # one page in this interpreter: python tests/test_docs.py PAGE
    _run_page(Path(sys.argv[1]).resolve())


# -- links between pages ------------------------------------------------------------------------------------------
_LINK = re.compile(r"\]\(([^)\s]+)\)")
_FENCE = re.compile(r"^(```|~~~)")


def _anchors(page: Path) -> set[str]:
    """The heading anchors MyST makes for ``page`` (GitHub's slugs: lower case, punctuation dropped, spaces to -)."""
    anchors, fenced = set(), False
    for line in page.read_text(encoding="utf-8").splitlines():
        if _FENCE.match(line):
            fenced = not fenced
        elif not fenced and line.startswith("#"):
            title = line.lstrip("#").strip().lower()
            anchors.add(re.sub(r"\s", "-", re.sub(r"[^\w\s-]", "", title)))
    return anchors


def _broken_links(page: Path) -> list[str]:
    broken, fenced = [], False
    for number, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
        if _FENCE.match(line):
            fenced = not fenced
            continue
        for target in [] if fenced else _LINK.findall(line):
            if re.match(r"[a-z]+:", target):
                continue  # a web address
            path, _, anchor = target.partition("#")
            if path.endswith(".rst") or path.startswith("{"):
                continue  # the generated reference, a role
            file = (page.parent / path).resolve() if path else page
            if not file.exists():
                broken.append(f"line {number}: {target} (no such file)")
            elif anchor and file.suffix == ".md" and anchor not in _anchors(file):
                broken.append(f"line {number}: {target} (no heading #{anchor})")
    return broken


@pytest.mark.parametrize("page", [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))], ids=_id)
def test_every_link_between_pages_reaches_a_page_and_a_heading(page):
    assert _broken_links(page) == []


def test_the_link_check_finds_a_missing_page_and_a_missing_heading(tmp_path):
    (tmp_path / "b.md").write_text("# Real heading, with a comma\n", encoding="utf-8")
    page = tmp_path / "a.md"
    page.write_text(
        "[ok](b.md#real-heading-with-a-comma) [gone](c.md) [wrong](b.md#fake) [web](https://x.org/y.md)\n"
        "```\n[in code](nowhere.md)\n```\n",
        encoding="utf-8",
    )
    assert _broken_links(page) == ["line 1: c.md (no such file)", "line 1: b.md#fake (no heading #fake)"]
