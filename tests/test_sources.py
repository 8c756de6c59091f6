"""Upstream source archives: checked by checksum or tree, taken from a folder, a download cache or a server.

Real archives (shared/upstream); the network path talks to a server on 127.0.0.1 only."""

from __future__ import annotations

import gzip
import io
import json
import re
import shutil
import tarfile
from pathlib import Path

import pytest

from slamrun.images import sources as src
from slamrun.images.sources import SOURCES, SourceError, check_archive, obtain
from tests.conftest import loopback_server, require_upstream


@pytest.fixture(scope="module")
def upstream() -> Path:
    return require_upstream()


def repack(archive: Path, out: Path, edit=None, add: dict[str, bytes] | None = None, level: int = 1) -> Path:
    """Re-pack a real archive (other compression, other member dates), optionally editing one member."""
    buf = io.BytesIO()
    with tarfile.open(archive, "r:gz") as tin, tarfile.open(fileobj=buf, mode="w") as tout:
        top = None
        for m in tin:
            top = top or m.name.split("/")[0]
            data = tin.extractfile(m).read() if m.isfile() else None
            if data is not None and edit is not None:
                data = edit(m.name, data)
                m.size = len(data)
            m.mtime = 1
            tout.addfile(m, io.BytesIO(data) if data is not None else None)
        for rel, data in (add or {}).items():
            info = tarfile.TarInfo(f"{top}/{rel}")
            info.size = len(data)
            tout.addfile(info, io.BytesIO(data))
    out.write_bytes(gzip.compress(buf.getvalue(), compresslevel=level))
    return out


def readme_archives(text: str) -> tuple[dict[str, str], dict[str, str]]:
    """The archives shared/upstream's README records, file name -> sha256: those of the study's table, and those
    it lists apart (the TUM-Mono evaluator's code, the methods after the study), each named in backquotes with a
    `sha256 HEX` after it in the same paragraph or list item."""
    table = {
        cells[4].strip(): cells[5].strip()
        for line in text.splitlines()
        if ".tar.gz |" in line and len(cells := line.split("|")) > 6
    }
    apart = {}
    for item in re.split(r"\n(?=- |\n)", text):
        named = re.match(r"\s*(?:- )?`([^`]+\.tar\.gz)`", item)
        digest = re.search(r"sha256\s+([0-9a-f]{64})", item)
        if named and digest:
            apart[named.group(1)] = digest.group(1)
    return table, apart


def test_every_recorded_source_matches_its_archive(upstream):
    table, apart = readme_archives((upstream / "README.md").read_text())
    assert SOURCES["orb_slam3"].filename in apart and SOURCES["mono_dataset_code"].filename in apart
    # the study's table lists exactly what is pinned of the study; the others are pinned from the README's
    # sections apart (DROID-SLAM's with its two submodules, MASt3R-SLAM's)
    apart_names = ("mono_dataset_code", "orb_slam3", "dpvo", "droid_slam", "lietorch", "pytorch_scatter", "mast3r_slam")
    pinned_apart = {SOURCES[n].filename for n in apart_names}
    assert {s.filename for s in SOURCES.values()} == set(table) | pinned_apart
    for s in SOURCES.values():
        assert {**table, **apart}[s.filename] == s.sha256, s.name
        assert check_archive(s, upstream / s.filename) == "sha256", s.name


def test_orb_slam3_full_archive_matches_though_its_absent_files_are_missing_here(upstream, tmp_path):
    """A complete archive of the commit (with the 446 files the stored one lacks, as its .absent.txt lists them)
    passes the tree check; the absent folders are left out of the digest, a changed file anywhere else is not."""
    orb = SOURCES["orb_slam3"]
    absent = (upstream / orb.filename.replace(".tar.gz", ".absent.txt")).read_text().split()
    assert len(absent) == 446
    assert all(any(a == x or (x.endswith("/") and a.startswith(x)) for x in orb.absent) for a in absent)
    full = repack(upstream / orb.filename, tmp_path / orb.filename, add={a: b"absent here" for a in absent})
    assert check_archive(orb, full) == "tree"
    assert "Vocabulary/ORBvoc.txt.tar.gz" in src.archive_members(full)

    def edit(name, data):
        return data + b"\n" if name.endswith("src/Tracking.cc") else data

    changed = repack(upstream / orb.filename, tmp_path / "changed.tar.gz", edit=edit)
    with pytest.raises(SourceError, match="not the archive of UZ-SLAMLab/ORB_SLAM3"):
        check_archive(orb, changed)


def test_a_repacked_archive_of_the_same_tree_is_accepted(upstream, tmp_path):
    dso = SOURCES["dso"]
    other = repack(upstream / dso.filename, tmp_path / dso.filename, level=9)
    assert src.file_sha256(other) != dso.sha256
    assert check_archive(dso, other) == "tree"


def test_the_full_repository_archive_matches_though_the_vocabulary_is_absent_here(upstream, tmp_path):
    orb = SOURCES["orb_slam2"]
    full = repack(upstream / orb.filename, tmp_path / orb.filename, add={"Vocabulary/ORBvoc.txt.tar.gz": b"voc" * 100})
    assert check_archive(orb, full) == "tree"
    assert "Vocabulary/ORBvoc.txt.tar.gz" in src.archive_members(full)


def test_a_changed_archive_is_refused_naming_the_file(upstream, tmp_path):
    dso = SOURCES["dso"]
    target = "src/util/IndexThreadReduce.h"

    def edit(name, data):
        return data + b"\n// changed\n" if name.endswith(target) else data

    folder = tmp_path / "sources"
    folder.mkdir()
    repack(upstream / dso.filename, folder / dso.filename, edit=edit)
    with pytest.raises(SourceError) as err:
        obtain("dso", sources_dir=folder)
    msg = str(err.value)
    assert str(folder / dso.filename) in msg and dso.commit in msg and dso.sha256 in msg
    # another repository's archive under the pinned name is refused too
    shutil.copyfile(upstream / SOURCES["sophus"].filename, folder / dso.filename)
    with pytest.raises(SourceError, match="not the archive of JakobEngel/dso"):
        obtain("dso", sources_dir=folder)
    (folder / dso.filename).write_bytes(b"not a tarball")
    with pytest.raises(SourceError, match="not a readable .tar.gz"):
        obtain("dso", sources_dir=folder)


def test_a_missing_archive_names_what_to_fetch_and_from_where(tmp_path):
    with pytest.raises(SourceError) as err:
        obtain("ldso", sources_dir=tmp_path)
    msg = str(err.value)
    assert SOURCES["ldso"].filename in msg
    assert "https://github.com/tum-vision/LDSO/archive/9b0c48cfd3b3ee95a8dbf1aef2371ed4fca6f81a.tar.gz" in msg
    with pytest.raises(SourceError, match="unknown source 'nope'"):
        obtain("nope", sources_dir=tmp_path)


@pytest.fixture
def archive_server(upstream):
    """Serves shared/upstream at GitHub's archive addresses, on 127.0.0.1; counts the requests."""
    routes = {f"/{s.repo}/archive/{s.commit}.tar.gz": upstream / s.filename for s in SOURCES.values()}
    with loopback_server(routes) as served:
        yield served


def test_download_into_the_cache_then_reuse(archive_server, tmp_path):
    url, hits = archive_server
    cache = tmp_path / "cache"
    path = obtain("sophus", cache=cache, base_url=url)
    assert path == cache / SOURCES["sophus"].filename and path.is_file()
    assert obtain("sophus", cache=cache, base_url=url) == path
    assert hits == [f"/strasdat/Sophus/archive/{SOURCES['sophus'].commit}.tar.gz"]  # the second came from the cache
    assert not list(cache.glob("*.part"))


def test_an_unreachable_server_names_the_address_and_the_folder_option(archive_server, tmp_path):
    url, _ = archive_server
    with pytest.raises(SourceError) as err:
        obtain("dso", cache=tmp_path, base_url=url + "/missing")
    assert "/missing/JakobEngel/dso/archive/" in str(err.value) and "--sources DIR" in str(err.value)
    assert not list(tmp_path.iterdir())  # no partial download left behind


def test_a_pypi_file_from_a_folder_the_cache_or_the_index(tmp_path):
    from slamrun.images.sources import PypiFile, obtain_pypi

    data = b"not really a wheel " * 5000
    sha = src.hashlib.sha256(data).hexdigest()
    f = PypiFile("demo-1.0-py3-none-any.whl", "demo", "1.0", sha)
    index = {"urls": [{"filename": f.filename, "url": "PLACEHOLDER"}]}
    routes = {"/files/demo.whl": data}
    with loopback_server(routes) as (url, hits):
        index["urls"][0]["url"] = f"{url}/files/demo.whl"
        routes["/pypi/demo/1.0/json"] = json.dumps(index).encode()
        cache = tmp_path / "cache"
        path = obtain_pypi(f, cache=cache, index_url=url)
        assert path.read_bytes() == data and hits == ["/pypi/demo/1.0/json", "/files/demo.whl"]
        assert obtain_pypi(f, cache=cache, index_url=url) == path and len(hits) == 2  # cached
        folder = tmp_path / "given"
        folder.mkdir()
        (folder / f.filename).write_bytes(data + b"x")  # a folder's file is checked too
        with pytest.raises(SourceError, match="expected " + sha):
            obtain_pypi(f, sources_dir=folder, cache=cache, index_url=url)
        bad = PypiFile(f.filename, "demo", "1.0", "0" * 64)
        with pytest.raises(SourceError, match="sha256"):
            obtain_pypi(bad, cache=tmp_path / "other", index_url=url)
        assert not list((tmp_path / "other").glob("*.whl"))  # a wrong download is not kept
    with pytest.raises(SourceError, match="pass its folder with --sources DIR"):
        obtain_pypi(f, cache=tmp_path / "third", index_url=url)  # the server is gone


def test_weights_by_address_need_and_get_their_checksum(tmp_path):
    from slamrun.images.sources import obtain_url

    data = b"weights" * 1000
    sha = src.hashlib.sha256(data).hexdigest()
    with loopback_server({"/w/model.pb": data}) as (url, _):
        path = obtain_url(f"{url}/w/model.pb", sha, cache=tmp_path)
        assert path.read_bytes() == data and path.name.endswith("model.pb")
        with pytest.raises(SourceError, match="expected " + "1" * 64):
            obtain_url(f"{url}/w/model.pb", "1" * 64, cache=tmp_path / "b")
        with pytest.raises(SourceError, match="needs its sha256"):
            obtain_url(f"{url}/w/model.pb", "", cache=tmp_path / "c")


def test_a_pypi_file_from_a_mirror_with_only_the_project_index_and_relative_addresses(tmp_path):
    """A PyPI mirror (as the registry this project is tested behind) may serve /pypi/<project>/json only, with file
    addresses relative to it: the file is still found there."""
    from slamrun.images.sources import PypiFile, obtain_pypi

    data = b"a wheel from a mirror " * 3000
    f = PypiFile("demo-1.0-py3-none-any.whl", "demo", "1.0", src.hashlib.sha256(data).hexdigest())
    project = {
        "info": {"version": "2.0"},
        "urls": [],
        "releases": {"1.0": [{"filename": f.filename, "url": "../../packages/ab/demo-1.0-py3-none-any.whl"}]},
    }
    routes = {"/pypi/demo/json": json.dumps(project).encode(), "/packages/ab/demo-1.0-py3-none-any.whl": data}
    with loopback_server(routes) as (url, hits):
        path = obtain_pypi(f, cache=tmp_path / "cache", index_url=url)
    assert path.read_bytes() == data and hits[-1] == "/packages/ab/demo-1.0-py3-none-any.whl"
