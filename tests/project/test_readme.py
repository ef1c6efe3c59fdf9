"""The README's examples run as written: its Python blocks, and its command lines on the sample EXRs."""

import re
import shlex
from pathlib import Path

import pytest
from shape_comments import check_shape_comments, shape_claims

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
TEXT = README.read_text()
PYTHON_BLOCKS = re.findall(r"```python\n(.*?)```", TEXT, flags=re.S)
SH_BLOCKS = re.findall(r"```sh\n(.*?)```", TEXT, flags=re.S)
COMMANDS = [line for block in SH_BLOCKS for line in block.splitlines() if line.startswith(".venv/bin/torchgrade ")]


def test_readme_has_python_examples_and_commands():
    assert len(PYTHON_BLOCKS) >= 4 and COMMANDS


@pytest.mark.parametrize("index", range(len(PYTHON_BLOCKS)))
def test_readme_python_examples_run(index, monkeypatch):
    monkeypatch.chdir(ROOT)  # blocks read export/looks/ and ../shared as the README's reader does, from the root
    namespace = {}
    exec(compile(PYTHON_BLOCKS[index], f"README.md, Python block {index + 1}", "exec"), namespace)
    check_shape_comments(PYTHON_BLOCKS[index], namespace)


def test_the_shape_comments_are_checked():
    """The README states shapes in its comments (the serving example's frames and output among them); each is
    compared with what the example returns."""
    claims = [claim for block in PYTHON_BLOCKS for claim in shape_claims(block)]
    assert any(name == "codes" for name, _, _ in claims) and len(claims) >= 2


@pytest.mark.parametrize("line", COMMANDS)
def test_readme_command_lines_run(line, tmp_path, monkeypatch):
    from torchgrade.cli import main

    argv = shlex.split(line, comments=True)[1:]
    for flag in ("-o", "--out", "--output"):
        if flag in argv:
            at = argv.index(flag) + 1
            argv[at] = str(tmp_path / Path(argv[at]).name)  # outputs go to a temporary folder, not the checkout
            output = Path(argv[at])
    monkeypatch.chdir(ROOT)
    assert main(argv) == 0
    assert output.stat().st_size > 0


def test_readme_shows_the_two_commands_first():
    first_block = SH_BLOCKS[0]
    assert first_block.splitlines()[0].startswith("make demo") and first_block.splitlines()[1].startswith("make test")


def _github_anchor(heading: str) -> str:
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def test_readme_links_resolve():
    """Every relative link and picture names a file of the checkout, every #anchor a heading of the README."""
    headings = {_github_anchor(line.lstrip("#")) for line in TEXT.splitlines() if line.startswith("#")}
    targets = re.findall(r"\]\(([^)\s]+)\)", TEXT)
    assert targets
    for target in targets:
        if target.startswith("#"):
            assert target[1:] in headings, target
        elif "://" not in target:
            assert (ROOT / target.split("#")[0]).is_file(), target


def test_readme_has_a_table_of_contents_of_its_sections():
    sections = [_github_anchor(line[3:]) for line in TEXT.splitlines() if line.startswith("## ")]
    contents = TEXT.split("## Contents", 1)[1].split("\n## ", 1)[0]
    assert [anchor for anchor in re.findall(r"\]\(#([^)]+)\)", contents)] == [s for s in sections if s != "contents"]
