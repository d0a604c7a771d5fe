"""The README is a front page (issue 25): at most 200 lines, and every link it has stays in the
repository and resolves. The docs site itself is built with ``mkdocs build --strict`` by
``make test``, which fails on a broken link or a missing reference."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_the_readme_is_a_front_page() -> None:
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 200
    for heading in ("## Quick start", "## Example", "## Results", "## Documentation"):
        assert heading in readme
    assert readme.count("![") == 1, "one figure"


def test_every_readme_link_resolves_inside_the_repository() -> None:
    readme = (ROOT / "README.md").read_text()
    targets = re.findall(r"\]\(([^)\s]+)\)", readme)
    assert targets
    for target in targets:
        assert not re.match(r"[a-z]+://", target), f"a link outside the repository: {target}"
        path = (ROOT / target.split("#")[0]).resolve()
        assert path.is_relative_to(ROOT), target
        assert path.exists(), target


def test_every_docs_page_is_in_the_site_nav() -> None:
    nav = (ROOT / "mkdocs.yml").read_text()
    for page in ("index.md", "design.md", "reference.md", "benchmarks.md", "reproduction.md"):
        assert page in nav
    for folder in ("concepts", "guides"):
        for page in (ROOT / "docs" / folder).glob("*.md"):
            assert f"{folder}/{page.name}" in nav, page


def test_the_api_table_is_up_to_date() -> None:
    """docs/api.md is generated from the code (scripts/api_table.py) and must match HEAD."""
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "api_table.py"), "--check"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, (
        done.stdout + done.stderr + "\nregenerate: python scripts/api_table.py"
    )


def test_the_layout_map_is_the_tree() -> None:
    """docs/design.md's file map is generated from the tree (scripts/layout_map.py): a file
    added, moved or re-documented without regenerating it fails here."""
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "layout_map.py"), "--check"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr


def test_every_tlshield_name_the_docs_and_the_help_give_resolves() -> None:
    """A dotted ``tlshield.x.y`` name in the README, the docs, the examples or the package's
    own text (docstrings, error messages, the command line's help) imports: a user who copies
    it finds it (issue 32 found ``tlshield.FsaAugmented``, which lives in tlshield.wrappers)."""
    import importlib
    import re

    texts = [ROOT / "README.md", *ROOT.glob("docs/**/*.md"), *ROOT.glob("examples/*.py")]
    texts += list((ROOT / "python" / "tlshield").rglob("*.py"))
    names = set()
    for path in texts:
        names.update(re.findall(r"\btlshield(?:\.[A-Za-z_]\w*)+", path.read_text()))
    assert len(names) > 50, names  # the scan finds the names at all
    missing = []
    for name in sorted(names):
        parts = name.split(".")
        for k in range(len(parts), 0, -1):
            try:
                obj = importlib.import_module(".".join(parts[:k]))
            except ImportError:
                continue
            rest = parts[k:]
            break
        for attr in rest:
            if not hasattr(obj, attr):
                missing.append(name)
                break
            obj = getattr(obj, attr)
    assert not missing, f"names that do not resolve: {missing}"
