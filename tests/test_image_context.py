"""A method's image builds from its own folder: the build context holds the method's folder as `method/`, the shared
recipe parts and the modules families share, never a sibling's folder; every file a recipe copies is in it, and no
file of a method's folder names another method's folder (issue 64)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import slamrun.methods
from slamrun.images.build import buildable, copy_code, pypi_files_of, recipe_text, sources_of

METHODS = Path(slamrun.methods.__file__).parent
COPY = re.compile(r"^COPY\s+(?!--from)(.+)$", re.MULTILINE)


def copied_sources(text: str) -> list[str]:
    """The context paths a Dockerfile's COPY instructions read (lines joined at their backslashes)."""
    joined = re.sub(r"\\\n\s*", " ", text)
    out = []
    for args in COPY.findall(joined):
        words = [w for w in args.split() if not w.startswith("--")]
        out += words[:-1]  # the last word is the destination
    return out


@pytest.mark.parametrize("name", sorted(buildable()))
def test_every_file_a_recipe_copies_is_in_its_context(name, tmp_path):
    """The context as `slamrun images` assembles it (its code copied for real; the archives, wheels and inputs it
    fetches stand as empty files of their names): each COPY source of the recipe (with its shared stages) exists."""
    dockerfile = buildable()[name][1]
    ctx = tmp_path / "ctx"
    ctx.mkdir()
    copy_code(dockerfile, ctx)
    for folder, files in (
        ("sources", [f"{s}.tar.gz" for s in sources_of(dockerfile)]),
        ("pypi", pypi_files_of(dockerfile)),
    ):
        (ctx / folder).mkdir()
        for f in files:
            (ctx / folder / f).write_bytes(b"")
    (ctx / "inputs").mkdir()
    missing = [src for src in copied_sources(recipe_text(dockerfile)) if not list(ctx.glob(src))]
    assert not missing, f"{name}'s recipe copies what its context does not hold: {missing}"


def test_no_method_folder_names_another_method_folder():
    """A method's folder stands alone: none of its files imports another method's module or names another method's
    folder; what a family shares is in slamrun/methods/*_family.py, gpu_process.py, sfm_process.py and recipes/."""
    names = sorted(p.parent.name for p in METHODS.glob("*/__init__.py"))
    found = []
    for name in names:
        for path in (METHODS / name).rglob("*"):
            if not path.is_file() or "__pycache__" in path.parts:
                continue
            text = path.read_text(errors="replace")
            for other in names:
                if other != name and re.search(rf"slamrun[./]methods[./]{other}\b", text):
                    found.append(f"{path.relative_to(METHODS)} names {other}")
    assert not found, found


def test_a_recipe_outside_a_method_folder_takes_only_its_own_folder(tmp_path):
    """A Dockerfile written anywhere (a test's, a user's) builds with its own folder as `method/`, never the folder
    above it: that may hold anything (a test session's temporary folders held FIFOs, on which a copy blocks)."""
    import os

    (tmp_path / "elsewhere").mkdir()
    os.mkfifo(tmp_path / "elsewhere" / "fifo")
    own = tmp_path / "mine"
    own.mkdir()
    (own / "Dockerfile").write_text("FROM debian:bookworm-slim\n")
    ctx = tmp_path / "ctx"
    ctx.mkdir()
    copy_code(own / "Dockerfile", ctx)
    assert sorted(p.name for p in (ctx / "method").iterdir()) == ["Dockerfile"]
    (tmp_path / "ctx2").mkdir()
    copy_code(buildable()["dso"][1], tmp_path / "ctx2")  # a method's recipe: its whole folder
    assert (tmp_path / "ctx2" / "method" / "image" / "patches.py").is_file()
