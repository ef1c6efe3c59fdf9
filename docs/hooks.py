"""MkDocs hooks: the site carries the committed benchmark results its pages link to.

The pages link to ``../benchmarks/results/...`` so that the links also work when the Markdown is read in the
repository; the site copies those files (pictures and result tables) and points the links at its copy.
"""

from pathlib import Path

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"


def on_files(files, config):
    for path in sorted(RESULTS.rglob("*")):
        if path.is_file() and path.suffix in {".md", ".png", ".jpg"}:
            files.append(File(path.relative_to(ROOT).as_posix(), str(ROOT), config["site_dir"], config["use_directory_urls"]))
    return files


def on_page_markdown(markdown, page, config, files):
    if page.file.src_uri.startswith("benchmarks/"):
        return markdown
    return markdown.replace("](../benchmarks/", "](benchmarks/")
