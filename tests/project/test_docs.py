"""The documentation site: every Python example on its pages runs, blocks left out say why, the gallery's pictures
are the ones its script writes, and ``mkdocs build --strict`` (links, anchors, the nav, the API pages made from the
docstrings) passes without a warning."""

import importlib
import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest
from shape_comments import check_shape_comments

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "torchgrade"
DOCS = ROOT / "docs"
PAGES = sorted(DOCS.rglob("*.md"))
BLOCKS = [(page, index, block) for page in PAGES
          for index, block in enumerate(re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.S))]
NOT_RUN = [(page, block) for page in PAGES for block in re.findall(r"```py\n(.*?)```", page.read_text(), flags=re.S)]


def test_docs_have_python_examples():
    """The pattern finds the pages' examples: each page of a stage or a use shows one."""
    with_examples = {page.name for page, _, _ in BLOCKS}
    assert {"index.md", "tonemap.md", "grading.md", "bloom.md", "exposure.md", "lut.md", "onnx.md", "augment.md",
            "saving.md", "match.md"} <= with_examples


@pytest.mark.parametrize("page, index, block", BLOCKS, ids=[f"{p.relative_to(DOCS)}-{i + 1}" for p, i, _ in BLOCKS])
def test_docs_python_examples_run(page, index, block, monkeypatch):
    monkeypatch.chdir(ROOT)  # blocks read export/looks/ and ../shared from the repository's root
    namespace = {}
    exec(compile(block, f"{page.relative_to(ROOT)}, Python block {index + 1}", "exec"), namespace)
    check_shape_comments(block, namespace)


def test_blocks_left_out_say_why():
    """A block fenced ``py`` (not ``python``) is not run; its first line says why, on the page."""
    for page, block in NOT_RUN:
        assert block.startswith("# not run by the tests: "), page
    assert not [page for page in PAGES if re.search(r"```(python3|py3|pycon|ipython)\n", page.read_text())]


def _resolves(dotted: str) -> bool:
    """Whether ``dotted`` names a module, or a name a module holds (found without importing an old module path)."""
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            spec = importlib.util.find_spec(".".join(parts[:cut]))
        except ImportError:  # a parent that is a module, not a package
            spec = None
        if spec is not None:
            held = importlib.import_module(".".join(parts[:cut])) if cut < len(parts) else None
            for name in parts[cut:]:
                if not hasattr(held, name):
                    return False
                held = getattr(held, name)
            return True
    return False


def test_the_layout_page_names_files_modules_and_names_that_exist():
    """Every file and folder ``docs/layout.md`` names exists: a path from the repository or the package, or a file of
    the package (in a row of the package table, of the packages that row is about); and every ``torchgrade.`` name it
    gives is a module or a name a module holds."""
    missing = []
    for line in (DOCS / "layout.md").read_text().splitlines():
        within = [PACKAGE]
        if line.startswith("| `"):  # a row of the package table
            within = [PACKAGE / name for name in re.findall(r"`(\w+)/`", line.split("|")[1])] or within
        for name in re.findall(r"`([\w/.]+(?:\.py|\.c|/))`", line):
            found = (ROOT / name).exists() or (PACKAGE / name).exists()
            if not (found or any(any(package.rglob(name.rstrip("/"))) for package in within)):
                missing.append(name)
        missing += [name for name in re.findall(r"`(torchgrade(?:\.\w+)+)`", line) if not _resolves(name)]
    assert missing == []


def test_gallery_pictures_are_the_scripts(tmp_path):
    """The gallery page shows what docs/gallery.py writes, the committed pictures stay small, and the script runs."""
    sys.path.insert(0, str(DOCS))
    try:
        import gallery
    finally:
        sys.path.remove(str(DOCS))
    names = gallery.sheet_names()
    shown = re.findall(r"\]\(gallery/([^)]+)\)", (DOCS / "gallery.md").read_text())
    committed = sorted(path.name for path in (DOCS / "gallery").iterdir())
    assert sorted(shown) == sorted(names) == committed
    assert sum((DOCS / "gallery" / name).stat().st_size for name in committed) < 2 * 1024 * 1024
    written = gallery.main(["--out", str(tmp_path), "--images", "CandleGlass", "--tile", "24", "--modes", "none", "agx",
                            "--exr-dir", str(ROOT.parent / "shared" / "data" / "exr")])
    assert [path.name for path in written] == gallery.sheet_names(["CandleGlass"])
    assert all(path.stat().st_size > 0 for path in written)


def test_the_gallery_writes_no_sheet_whose_frame_glows_at_an_edge(tmp_path, monkeypatch):
    """A look whose frames are brighter along one edge than the turned render (today's bloom fixed, a stand-in for a
    regression) stops the script before any sheet is written, naming the frame and the edge."""
    sys.path.insert(0, str(DOCS))
    try:
        import gallery
    finally:
        sys.path.remove(str(DOCS))
    real = gallery.through_look

    def glowing(look, image):
        frame = real(look, image).clone()
        frame[..., -16:] += 0.05
        return frame

    monkeypatch.setattr(gallery, "through_look", glowing)
    with pytest.raises(gallery.EdgeCheckError, match=r"cinematic on CandleGlass: the right edge differs .* by \+"):
        gallery.main(["--out", str(tmp_path), "--images", "CandleGlass", "--tile", "24", "--modes", "none",
                      "--exr-dir", str(ROOT.parent / "shared" / "data" / "exr")])
    assert not list(tmp_path.iterdir())


def test_docs_build_strict(tmp_path):
    """``mkdocs build --strict``: a broken link or anchor, a page outside the nav or a docstring the API pages cannot
    read is a warning, and a warning fails the build."""
    run = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0 and "WARNING" not in run.stderr, run.stderr[-4000:]
    assert (tmp_path / "site" / "api" / "grading" / "index.html").read_text().count("ColorGrade") > 1
    # the docstrings' Sphinx roles render as links or code (docs/griffe_roles.py), never as ":class:`X`" text
    raw = {page.parent.name: re.findall(r":(?:class|func|meth|mod|data|attr|exc|obj|const):`?[\w.~]+", page.read_text())
           for page in (tmp_path / "site" / "api").rglob("index.html")}
    assert not any(raw.values()), {name: roles[:3] for name, roles in raw.items() if roles}
    bloom = (tmp_path / "site" / "api" / "bloom" / "index.html").read_text()
    assert 'href="#torchgrade.bloom.bloom"><code>bloom</code></a>' in bloom  # a role became a link to its entry
