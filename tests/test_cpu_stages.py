"""The compiled CPU methods' images share their stages (issue 64): Debian's build and runtime stages, Pangolin's and
MonoDepth's, each written once in recipes/<part>/stages.Dockerfile and put ahead of every recipe that starts FROM one
of them (with the stages those start from, dependencies first); a method's own recipe keeps only its own steps."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import slamrun.methods
from slamrun.images.build import FROM_RE, buildable, recipe_text, shared_stages, stage_files

RECIPES = Path(slamrun.methods.__file__).parent / "recipes"
DEBIAN, PANGOLIN, MONODEPTH = (RECIPES / part / "stages.Dockerfile" for part in ("debian", "pangolin", "monodepth"))
RUNTIME = ["FROM debian-runtime", "COPY --from=build /opt/runtime/ /", "RUN slamrun-install-runtime"]


def on_debian_stages() -> dict[str, Path]:
    """The registry's methods whose recipe starts from Debian's shared build stage (directly or through another)."""
    return {name: path for name, (_, path) in sorted(buildable().items()) if DEBIAN in stage_files(path)}


def test_the_compiled_cpu_methods_are_on_the_shared_stages():
    compiled = {"dso", "ldso", "cnn_dso", "dsm", "lsd_slam", "svo", "cnn_svo", "orb_slam2", "df_orb_slam", "orb_slam3"}
    assert set(on_debian_stages()) == compiled  # DynaSLAM's Debian 11 and the Python images have their own


def test_a_stage_file_comes_after_the_files_its_stages_start_from():
    """dso starts FROM pangolin, which starts FROM debian-build: Debian's file first, then Pangolin's, then its own."""
    dso, cnn_dso = on_debian_stages()["dso"], on_debian_stages()["cnn_dso"]
    assert stage_files(dso) == [DEBIAN, PANGOLIN]
    assert stage_files(cnn_dso) == [DEBIAN, MONODEPTH]
    assert recipe_text(dso) == DEBIAN.read_text() + "\n" + PANGOLIN.read_text() + "\n" + dso.read_text()
    assert {"debian-build", "debian-runtime", "pangolin", "monodepth"} <= set(shared_stages())


def test_a_stage_no_file_defines_adds_no_file(tmp_path):
    """A recipe naming a stage no file defines gets no file for it (the build then fails on FROM, naming it)."""
    dockerfile = tmp_path / "Dockerfile"
    dockerfile.write_text("FROM no-such-stage AS build\nFROM debian-runtime\n")
    assert stage_files(dockerfile) == [DEBIAN]


@pytest.mark.parametrize("name", sorted(on_debian_stages()))
def test_a_method_recipe_holds_only_its_own_steps(name):
    """No method writes the shared steps again: no base image, compiler install, Pangolin or TensorFlow build of its
    own (CNN-DSO builds Pangolin on MonoDepth's stage; DSM adds Ceres), and every one ends on the shared runtime:
    what its build stage put together in /opt/runtime, installed, run as the user slam."""
    own = on_debian_stages()[name].read_text()
    bases = [base for base, _ in FROM_RE.findall(own)]
    assert not [b for b in bases if b.startswith("debian:")], bases
    assert "build-essential" not in own and "tf-from-wheel" not in own and "runtime_packages.py" not in own
    assert ("build-pangolin.sh" in own) == (name == "cnn_dso")
    assert ("apt-get install" in own) == (name == "dsm")
    lines = [line for line in own.splitlines() if line and not line.startswith("#")]
    last = max(i for i, line in enumerate(lines) if line.startswith("FROM "))
    assert lines[last : last + 3] == RUNTIME, lines[last:]
    assert "USER slam" in lines[last:] and lines[-1].startswith("CMD [")
    assert re.search(r"/opt/slamrun-build/common/stage-(runtime|orb-slam2)\.sh ", own), "its build stage stages nothing"
