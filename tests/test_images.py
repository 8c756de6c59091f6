"""The image build path against a real Docker engine: build arguments, sources and labels reach the build,
a failing step is named with the end of its output, and every build keeps its log."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

from slamrun.errors import InfraError, SlamRunError
from slamrun.images.build import BuildOptions, build, build_one, image_labels, sources_of, vocabulary_choice
from slamrun.images.sources import SOURCES
from tests.conftest import UPSTREAM, recipe, require_upstream
from tests.test_docker import engine_with_base

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def client():
    require_upstream()
    return engine_with_base()


@pytest.fixture
def opts(tmp_path) -> BuildOptions:
    return BuildOptions(sources_dir=UPSTREAM, log_dir=tmp_path / "logs", march="x86-64-v3", jobs=3)


def test_dockerfiles_name_their_sources():
    assert sources_of(recipe("dso") / "Dockerfile") == ["pangolin-0.6", "dso"]
    for dockerfile in (ROOT / "docker").glob("*/Dockerfile"):
        assert all(s in SOURCES for s in sources_of(dockerfile)), dockerfile  # raises on an unknown name


def test_build_arguments_sources_and_labels_reach_the_image(client, opts, tmp_path):
    dockerfile = tmp_path / "Dockerfile"
    dockerfile.write_text(
        "FROM debian:bookworm-slim\nARG MARCH\nARG JOBS\nARG VOCABULARY\nARG EXTRA=unset\n"
        "COPY sources/sophus.tar.gz /tmp/\n"
        'RUN echo "$MARCH $JOBS $VOCABULARY $EXTRA" > /args && tar -tzf /tmp/sophus.tar.gz | head -1 > /top\n'
    )
    opts.build_args = {"EXTRA": "given"}
    tag = "slamrun-test/args:latest"
    try:
        record = build_one(client, "args-test", tag, dockerfile, opts, log=lambda m: None)
        out = _run(client, tag, "cat /args /top")
        assert out.split("\n")[0] == "x86-64-v3 3 none given"
        assert out.split("\n")[1].split("/")[0] == SOURCES["sophus"].top
        labels = image_labels(client, tag)
        assert json.loads(labels["slamrun.sources"]) == {"sophus": f"strasdat/Sophus@{SOURCES['sophus'].commit}"}
        assert labels["slamrun.march"] == "x86-64-v3"
        assert Path(record.log).read_text().count("Step ") >= 7
        saved = json.loads((opts.log_dir / "args-test.json").read_text())
        assert saved["tag"] == tag and saved["seconds"] > 0 and saved["size_mb"] > 0
    finally:
        client.remove_image(tag, force=True)


def test_a_cached_rebuild_keeps_the_record_of_the_build_that_made_the_image(client, opts, tmp_path):
    """Building again with every step cached makes no new image: its record (the build time the verification
    table shows) and its log stay the ones of the build that made the image, not the cache look-up's."""
    dockerfile = tmp_path / "Dockerfile"
    dockerfile.write_text(f"FROM debian:bookworm-slim\nRUN sleep 3 && echo {tmp_path.name} > /made\n")
    tag = "slamrun-test/cached:latest"
    try:
        first = build_one(client, "cached-test", tag, dockerfile, opts, log=lambda m: None)
        lines = []
        again = build_one(client, "cached-test", tag, dockerfile, opts, log=lines.append)
        assert first.seconds >= 3 and again == first
        saved = json.loads((opts.log_dir / "cached-test.json").read_text())
        assert saved["seconds"] == first.seconds and saved["image_id"] == client.inspect_image(tag)["Id"]
        assert any("unchanged" in line for line in lines), lines
        assert "Using cache" not in Path(again.log).read_text()  # the log is still the one of the real build
    finally:
        client.remove_image(tag, force=True)


def test_a_patch_whose_anchor_is_missing_fails_the_build_naming_step_and_file(client, opts, tmp_path):
    """The real DSO archive and patch script, with the anchor's line changed as an upstream edit would."""
    if not client.images(name="slamrun/reference_vo:latest"):
        build(["reference_vo"], log=lambda m: None)  # a small image with python3
    folder = tmp_path / "anchor_test" / "image"  # a method's folder: its image's recipe and DSO's real patches
    folder.mkdir(parents=True)
    shutil.copyfile(recipe("dso") / "patches.py", folder / "patches.py")
    dockerfile = folder / "Dockerfile"
    dockerfile.write_text(
        "FROM slamrun/reference_vo:latest\nUSER root\n"
        "COPY recipes/common /b/common\nCOPY method/image /b/dso\n"
        "COPY sources/dso.tar.gz /b/\n"
        "RUN /b/common/unpack.sh /b/dso.tar.gz /opt/dso "
        "&& sed -i 's|\"boost/thread.hpp\"|<boost/thread.hpp>|' /opt/dso/src/util/IndexThreadReduce.h "
        "&& python3 /b/dso/patches.py /opt/dso\n"
    )
    with pytest.raises(InfraError) as err:
        build_one(client, "anchor-test", "slamrun-test/anchor:latest", dockerfile, opts, log=lambda m: None)
    msg = str(err.value)
    assert re.search(r"failed at Step 6/\d+ : RUN /b/common/unpack.sh", msg)
    assert "src/util/IndexThreadReduce.h" in msg and "found 0 times" in msg
    log = opts.log_dir / "anchor-test.log"
    assert str(log) in msg and "found 0 times" in log.read_text()
    assert not client.images(name="slamrun-test/anchor:latest")


def test_a_build_refuses_a_damaged_source_before_docker_runs(client, opts, tmp_path):
    folder = tmp_path / "sources"
    folder.mkdir()
    (folder / SOURCES["sophus"].filename).write_bytes((UPSTREAM / SOURCES["dso"].filename).read_bytes())
    opts.sources_dir = folder
    dockerfile = tmp_path / "Dockerfile"
    dockerfile.write_text("FROM debian:bookworm-slim\nCOPY sources/sophus.tar.gz /tmp/\n")
    with pytest.raises(SlamRunError, match=f"{folder / SOURCES['sophus'].filename}: not the archive of strasdat"):
        build_one(client, "bad-source", "slamrun-test/bad:latest", dockerfile, opts, log=lambda m: None)


def test_vocabulary_choice(tmp_path):
    archives = {"ldso": require_upstream(UPSTREAM / SOURCES["ldso"].filename)}
    assert vocabulary_choice("dso", archives, BuildOptions()) == ("none", "")
    kind, detail = vocabulary_choice("ldso", archives, BuildOptions())
    assert kind == "trained" and "not the study's" in detail  # the archive here lacks vocab/orbvoc.dbow3
    given = tmp_path / "orbvoc.dbow3"
    given.write_bytes(b"vocabulary")
    kind, detail = vocabulary_choice("ldso", archives, BuildOptions(vocabulary={"ldso": given}))
    assert kind == "given" and "sha256" in detail
    with pytest.raises(SlamRunError) as err:
        vocabulary_choice("ldso", archives, BuildOptions(train_vocabulary=False))
    assert "vocab/orbvoc.dbow3" in str(err.value) and "--vocabulary ldso=FILE" in str(err.value)


def _run(client, tag: str, cmd: str) -> str:
    container = client.create_container(
        tag, ["sh", "-c", cmd], host_config=client.create_host_config(network_mode="none")
    )
    try:
        client.start(container)
        client.wait(container, timeout=60)
        return client.logs(container).decode().strip()
    finally:
        client.remove_container(container, force=True)


def test_the_network_an_image_holds_is_given_a_stand_in_or_a_clear_error(tmp_path):
    from slamrun.images.build import model_choice

    assert model_choice("dso", BuildOptions()) == ("none", "")
    with pytest.raises(SlamRunError) as err:
        model_choice("cnn_dso", BuildOptions())
    msg = str(err.value)
    assert "model_city2kitti.pb" in msg and "--weights model_city2kitti.pb=FILE" in msg and "monodepth-cpp" in msg
    kind, detail = model_choice("cnn_svo", BuildOptions(standin_model=True))
    assert kind == "standin" and "NOT the trained network" in detail
    given = BuildOptions(weights={"model_city2kitti.pb": tmp_path / "m.pb"})
    assert model_choice("cnn_dso", given)[0] == "given"
    with pytest.raises(SlamRunError, match="mask_rcnn_coco.h5.*matterport"):
        model_choice("dynaslam", BuildOptions())
    # slamrun/methods/dynaslam/image makes one
    assert model_choice("dynaslam", BuildOptions(standin_model=True))[0] == "standin"


def test_every_pypi_file_of_a_continued_copy_is_found(tmp_path):
    """A COPY continued over several lines names a wheel on each: every one goes into the build context (the
    reference VO's image copies three)."""
    from slamrun.images.build import pypi_files_of

    dockerfile = tmp_path / "Dockerfile"
    dockerfile.write_text("FROM x\nCOPY pypi/a-1-py3-none-any.whl \\\n     pypi/b-2-py3-none-any.whl /tmp/\nRUN true\n")
    assert pypi_files_of(dockerfile) == ["a-1-py3-none-any.whl", "b-2-py3-none-any.whl"]

    assert len(pypi_files_of(recipe("reference_vo") / "Dockerfile")) == 3


def test_each_recipe_names_the_debian_base_slamrun_makes_when_missing():
    from slamrun.images.build import buildable, debian_bases

    bases = {name: debian_bases(dockerfile) for name, (_, dockerfile) in buildable().items()}
    assert bases.pop("dynaslam") == {"debian:bullseye-slim"}  # Python 2.7 for its embedded Mask R-CNN
    assert all(b == {"debian:bookworm-slim"} for b in bases.values()), bases
