"""A method is one folder: a copy of a CPU method's folder under a new name is a new built-in method, listed, buildable
and verified, with no other file touched (slamrun/methods/<name>/: its adapter, its image/ recipe, its declaration)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def slamrun(tree: Path, *args, cwd: Path) -> subprocess.CompletedProcess:
    """slamrun from the copied tree (first on the path: the installed one is an editable finder, consulted last)."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    return subprocess.run(
        [sys.executable, "-m", "slamrun.cli", *map(str, args)], capture_output=True, text=True, env=env, cwd=cwd
    )


def test_a_copied_method_folder_is_listed_buildable_and_verified(tmp_path):
    tree = tmp_path / "tree"
    shutil.copytree(ROOT / "slamrun", tree / "slamrun", ignore=shutil.ignore_patterns("__pycache__"))
    methods = tree / "slamrun" / "methods"
    shutil.copytree(methods / "reference_vo", methods / "my_vo")  # the one change: a folder
    check = subprocess.run(
        [sys.executable, "-c", "import slamrun; print(slamrun.__file__)"],
        capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(tree)}, cwd=tmp_path,
    )  # fmt: skip
    assert check.stdout.strip() == str(tree / "slamrun" / "__init__.py")

    listed = slamrun(tree, "list-methods", "--json", cwd=tmp_path)
    assert listed.returncode == 0, listed.stderr
    mine = json.loads(listed.stdout)["my_vo"]
    assert mine["image"] == "slamrun/my_vo:latest" and mine["native"] and mine["gpu"] == "no"

    images = slamrun(tree, "images", "--list", cwd=tmp_path)
    assert images.returncode == 0, images.stderr
    assert "my_vo: slamrun/my_vo:latest <- my_vo/image/Dockerfile" in images.stdout
    assert "reference_vo: slamrun/reference_vo:latest <- reference_vo/image/Dockerfile" in images.stdout

    data = tmp_path / "data"
    assert slamrun(tree, "synth", "--frames", "20", data / "s", cwd=tmp_path).returncode == 0
    spec = tmp_path / "house.yaml"
    spec.write_text(
        f"name: house\nbackend: local\nmethods:\n  - name: my_vo\n"
        f"datasets:\n  - name: d\n    path: {data}\n    sequences: [s]\n"
    )
    results = tmp_path / "verify"
    out = slamrun(tree, "verify", spec, "--trials", "1", "--frames", "60", "--results", results, cwd=tmp_path)
    assert out.returncode == 0, out.stdout + out.stderr
    (row,) = json.loads((results / "verify.json").read_text())
    assert row["method"] == "my_vo" and row["runs_ok"] == row["runs"] == 4 and row["bound"] == 0.05, row
    assert row["passed"] and row["backend"] == "local", row


def copied_tree(tmp_path: Path, original: str, copy: str) -> Path:
    """slamrun's package with the folder of method `original` copied as `copy`: the one change."""
    tree = tmp_path / "tree"
    shutil.copytree(ROOT / "slamrun", tree / "slamrun", ignore=shutil.ignore_patterns("__pycache__"))
    methods = tree / "slamrun" / "methods"
    shutil.copytree(methods / original, methods / copy, ignore=shutil.ignore_patterns("__pycache__"))
    return tree


def python_in(tree: Path, code: str, cwd: Path) -> str:
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(tree)},
        cwd=cwd,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_a_copied_method_runs_its_own_process(tmp_path):
    """A copy of reference_vo runs its own folder's process (the copy's __main__.py and vo.py, changed here so that
    it says so), never the original's."""
    tree = copied_tree(tmp_path, "reference_vo", "my_vo")
    main = tree / "slamrun" / "methods" / "my_vo" / "__main__.py"
    main.write_text(main.read_text().replace("import cv2\n", "import cv2\n\nprint('MY_VO OWN PROCESS', flush=True)\n"))
    data = tmp_path / "data"
    assert slamrun(tree, "synth", "--frames", "20", data / "s", cwd=tmp_path).returncode == 0
    spec = tmp_path / "own.yaml"
    spec.write_text(
        f"name: own\nbackend: local\nresults: {tmp_path / 'results'}\ncache: {tmp_path / 'cache'}\nreport: false\n"
        f"methods:\n  - name: my_vo\ndatasets:\n  - name: d\n    path: {data}\n    sequences: [s]\n"
        "directions: [forward]\n"
    )
    out = slamrun(tree, "campaign", spec, cwd=tmp_path)
    assert out.returncode == 0, out.stdout + out.stderr
    logs = [p for p in (tmp_path / "results").rglob("log.txt") if "MY_VO OWN PROCESS" in p.read_text(errors="replace")]
    assert logs, "the copy's run log does not show its own process"


def test_a_copied_gpu_method_has_its_own_process_build_folder_and_patches(tmp_path):
    """A copy of dpvo runs its own process module, keeps its native build in a folder of its own (never over dpvo's)
    and unpacks the real pinned archive with its own folder's patches (changed here to leave a mark)."""
    from tests.conftest import require_upstream

    tree = copied_tree(tmp_path, "dpvo", "my_dpvo")
    code = (
        "import slamrun.methods as m; from slamrun.methods.native_gpu import native_root\n"
        "a, b = m.get('my_dpvo')(), m.get('dpvo')()\n"
        "print(a.process); print(a.default_build().relative_to(native_root())); print(b.default_build() != "
        "a.default_build())"
    )
    assert python_in(tree, code, tmp_path).split() == ["slamrun.methods.my_dpvo.process", "my_dpvo", "True"]
    upstream = require_upstream()
    patches = tree / "slamrun" / "methods" / "my_dpvo" / "image" / "patches.py"
    patches.write_text(
        patches.read_text().replace("    unused_imports(root)\n", "    unused_imports(root)\n"
                                    "    open(os.path.join(root, 'MY_DPVO_PATCHES'), 'w').close()\n")
    )  # fmt: skip
    assert "import os" in patches.read_text()
    out = slamrun(tree, "native-build", "my_dpvo", "--unpack-only", "--sources", upstream, "--into", tmp_path / "b",
                  cwd=tmp_path)  # fmt: skip
    assert out.returncode == 0, out.stdout + out.stderr
    assert len(list((tmp_path / "b").glob("*/MY_DPVO_PATCHES"))) == 1


def test_a_copied_docker_method_builds_from_its_own_folder(tmp_path):
    """A copy of dso is listed with its own image, and the build context `slamrun images` assembles for it (what
    Docker is sent) holds the copy's folder (its patches, changed here to leave a mark) and the real pinned archive,
    and no other method's folder: its recipe never builds from dso's."""
    from tests.conftest import require_upstream

    upstream = require_upstream()
    tree = copied_tree(tmp_path, "dso", "my_dso")
    patches = tree / "slamrun" / "methods" / "my_dso" / "image" / "patches.py"
    patches.write_text(patches.read_text() + "\n# MY_DSO PATCHES\n")
    images = slamrun(tree, "images", "--list", cwd=tmp_path)
    assert images.returncode == 0, images.stderr
    assert "my_dso: slamrun/my_dso:latest <- my_dso/image/Dockerfile" in images.stdout
    code = (
        "import sys; from pathlib import Path; from slamrun.images.build import BuildOptions, assemble_context, "
        "buildable\n"
        "tag, dockerfile = buildable()['my_dso']\n"
        f"ctx = Path({str(tmp_path / 'ctx')!r}); ctx.mkdir()\n"
        f"labels = assemble_context('my_dso', dockerfile, BuildOptions(sources_dir=Path({str(upstream)!r})), ctx, "
        "lambda line: None)\n"
        "print(tag, labels['slamrun.method'], sorted(p.name for p in ctx.iterdir()))"
    )
    assert python_in(tree, code, tmp_path).split() == [
        "slamrun/my_dso:latest", "my_dso", "['inputs',", "'method',", "'methods',", "'recipes',", "'sources']"
    ]  # fmt: skip
    ctx = tmp_path / "ctx"
    assert "# MY_DSO PATCHES" in (ctx / "method" / "image" / "patches.py").read_text()
    assert (ctx / "method" / "__init__.py").read_text() == (tree / "slamrun/methods/my_dso/__init__.py").read_text()
    assert sorted(p.name for p in (ctx / "sources").iterdir()) == ["dso.tar.gz", "pangolin-0.6.tar.gz"]
    others = {p.name for p in (ROOT / "slamrun" / "methods").iterdir() if p.is_dir()} - {"recipes", "__pycache__"}
    assert not others & {p.name for p in ctx.rglob("*") if p.is_dir()}, "a method's folder in my_dso's context"
