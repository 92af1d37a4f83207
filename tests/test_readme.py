"""README's set-up commands are the ones CI runs; README's and the docs pages' code runs and their links resolve."""

import pathlib
import re

import pytest
from urllib.parse import unquote

ROOT = pathlib.Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
README_LIMIT = 12_000  # characters: a README a newcomer reads in five minutes (issue 24); the rest is in docs/


def _docs_pages():
    """The docs pages: ``docs/*.md`` (not ``docs/devlog/``, which records what was tried)."""
    return sorted((ROOT / "docs").glob("*.md"))


def test_ci_runs_the_readme_test_command():
    readme = README.read_text()
    ci_command = (ROOT / ".ci" / "run").read_text().strip().splitlines()[-1]
    assert ci_command in readme


def test_readme_main_job_command_is_the_installed_entry_point():
    readme = README.read_text()
    assert "python3 -m venv .venv && .venv/bin/pip install -e '.[test]' && .venv/bin/sintercond run" in readme


@pytest.mark.slow
def test_every_python_block_of_the_readme_and_the_docs_runs_as_written():
    """Issue 10: README snippets used undefined names (jnp, centres, capacity, T0, readings). The ```python
    blocks of README.md and of every docs/*.md page run in order, each file in its own namespace, as a reader
    pasting one page's blocks into one session would (```py blocks, e.g. the cluster start-up, are shown but
    not run)."""
    counts = {}
    for path in [README, *_docs_pages()]:
        name = path.relative_to(ROOT).as_posix()
        blocks = re.findall(r"```python\n(.*?)```", path.read_text(), flags=re.S)
        counts[name] = len(blocks)
        namespace = {"__name__": f"doc_{path.stem}"}
        for k, block in enumerate(blocks):
            try:
                exec(compile(block, f"{name} python block {k}", "exec"), namespace)
            except ValueError as err:
                # the neck block ends on a call documented to raise
                last = block.strip().splitlines()[-1]
                assert "validate_neck_inputs" in last and "max_overlap" in str(err), (name, k, err)
    assert counts["README.md"] >= 1, counts
    assert sum(counts.values()) >= 8, counts


def _slug(heading):
    """GitHub's anchor of a Markdown heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _without_fences(text):
    """``text`` without its fenced code blocks (whose ``#`` lines are comments, not headings)."""
    return re.sub(r"^ *(```+|~~~+)[^`\n]*\n.*?^ *\1 *$", "", text, flags=re.S | re.M)


def _prose(text):
    """``text`` without its fenced code blocks and inline code (where ``](`` is not a link)."""
    return re.sub(r"(`+).+?\1", "", _without_fences(text))


def _anchors(path):
    anchors, seen = set(), {}
    for heading in re.findall(r"^#{1,6} +(.+?) *#*$", _without_fences(path.read_text()), flags=re.M):
        slug = _slug(heading)
        anchors.add(slug if slug not in seen else f"{slug}-{seen[slug]}")
        seen[slug] = seen.get(slug, 0) + 1
    return anchors


def test_every_relative_link_of_the_readme_and_the_docs_resolves():
    """Links in README.md, CONTRIBUTING.md and docs/*.md (docs/devlog/ excluded) point at files that exist,
    and an anchor into a Markdown file at one of its headings; web links are not followed."""
    pages = [README, ROOT / "CONTRIBUTING.md", *_docs_pages()]
    broken, checked = [], 0
    for page in pages:
        for target in re.findall(r"\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)", _prose(page.read_text())):
            if re.match(r"[a-z][a-z0-9+.-]*:", target, flags=re.I):  # http:, https:, mailto:
                continue
            file_part, _, anchor = target.partition("#")
            path = (page.parent / unquote(file_part)).resolve() if file_part else page
            checked += 1
            if not path.exists():
                broken.append(f"{page.relative_to(ROOT)}: {target} (no such file)")
            elif anchor and path.suffix == ".md" and anchor not in _anchors(path):
                broken.append(f"{page.relative_to(ROOT)}: {target} (no heading #{anchor} in {path.name})")
    assert not broken, broken
    assert checked >= 20, checked  # the pages do link to each other: the regex found them


def test_readme_is_short():
    length = len(README.read_text())
    assert length <= README_LIMIT, f"README.md has {length} characters; the limit is {README_LIMIT}: move detail to docs/"


def _doc_scene_blocks():
    """``[(where, raw scene)]``: every ```toml block of README.md and docs/*.md that is a whole scene."""
    import tomllib

    return [(f"{page.name} toml block {k}", tomllib.loads(b)) for page in [README, *_docs_pages()]
            for k, b in enumerate(re.findall(r"```toml\n(.*?)```", page.read_text(), re.S)) if "[packing]" in b]


def _write_doc_packing(raw, tmp_path):
    """A ``kind = "file"`` scene of the docs given a packing to read: 27 touching spheres in a dump at its path."""
    from sintercond.beds import packing_files

    if raw["packing"]["kind"] != "file":
        return
    unit = packing_files.LENGTH_UNITS[raw["packing"].get("length_unit", "m")]
    path = tmp_path / raw["packing"]["path"]
    grid = [[x, y, z] for x in range(3) for y in range(3) for z in range(3)]
    text = "".join(f"{i + 1} 1 {x * 60e-6 / unit!r} {y * 60e-6 / unit!r} {z * 60e-6 / unit!r} {31e-6 / unit!r}\n"
                   for i, (x, y, z) in enumerate(grid))
    path.write_text("ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n27\nITEM: BOX BOUNDS ff ff ff\n0 1\n0 1\n0 1\n"
                    "ITEM: ATOMS id type x y z radius\n" + text)
    raw["packing"]["path"] = str(path)


def test_every_scene_block_of_the_docs_is_a_valid_scene(tmp_path):
    """The ```toml blocks of docs/ are whole scenes: each validates (a file packing against a packing written for it)."""
    from sintercond.scene import validate_scene

    scenes = _doc_scene_blocks()
    assert scenes
    for _, raw in scenes:
        _write_doc_packing(raw, tmp_path)
        validate_scene(raw)
