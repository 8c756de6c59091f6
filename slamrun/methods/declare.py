"""What a method declares beside its adapter's behaviour: the pinned sources its image builds from, a vocabulary, a
trained network, how `slamrun native-build` makes it. Values only; the toolchain (slamrun/images/) reads them.

A declaration belongs to the class that writes it: `declared(cls, "vocabulary")` never returns a base class's
(DF-ORB-SLAM subclasses ORB-SLAM2's adapter, yet builds from its own archive and vocabulary)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

GITHUB = "https://github.com"


@dataclass(frozen=True)
class Source:
    """An upstream source archive, pinned by commit and checked by the SHA-256 of the stored archive and the digest of
    its tree (tree_digest in slamrun/images/sources.py: the same files whoever packed the archive)."""

    name: str  # the name Dockerfiles use: COPY sources/<name>.tar.gz
    repo: str  # owner/name on GitHub
    commit: str  # full 40-hex commit
    sha256: str  # of the archive as stored in the study's folder of upstream archives
    tree: str  # tree_digest() of its content
    absent: tuple[str, ...] = ()  # files the stored archives lack (vocabularies, GIFs); "dir/": all files below

    @property
    def filename(self) -> str:
        return f"{self.repo.split('/')[1]}-{self.commit}.tar.gz"

    @property
    def top(self) -> str:
        return f"{self.repo.split('/')[1]}-{self.commit}"

    def url(self, base: str = GITHUB) -> str:
        return f"{base.rstrip('/')}/{self.repo}/archive/{self.commit}.tar.gz"


@dataclass(frozen=True)
class Vocabulary:
    """A bag-of-words vocabulary a method loads: where its source tree keeps it, and its format."""

    source: str  # the source archive that normally holds it
    path: str  # its path in that tree
    format: str  # dbow3 (LDSO) or dbow2-text (ORB-SLAM2 family)


@dataclass(frozen=True)
class Weights:
    """A trained network an image needs (`--weights NAME=FILE`), where its authors publish it, and whether an
    untrained stand-in with the same interface can replace it for plumbing tests (`--standin-model`)."""

    name: str
    published: str
    standin: bool = False
    arg: str = "MONODEPTH_MODEL"  # the build argument that says given or standin
    # files given with it, each by its own --weights NAME=FILE (MASt3R-SLAM's retrieval head and codebook); a stand-in
    # makes them too
    companions: tuple[str, ...] = ()

    @property
    def files(self) -> tuple[str, ...]:
        return (self.name, *self.companions)


@dataclass(frozen=True)
class NativeMethod:
    """How `slamrun native-build <name>` makes a method: its archives, patches, extensions and stand-in network."""

    label: str  # as messages name it
    source: str  # the main archive (a declared Source); its top folder is the tree
    parts: tuple[tuple[str, str], ...]  # (source, folder of the tree): archives unpacked into submodule folders
    patches: Path
    setups: tuple[tuple[str, tuple[str, ...]], ...]  # (folder of the tree holding a setup.py, the extensions it makes)
    import_path: tuple[str, ...]  # folders of the tree on sys.path for the import check
    weights_name: str
    standin: Path
    standin_args: tuple[str, ...]  # after TREE OUT: the seed and the stand-in's scale
    standin_note: str  # what the stand-in is, {out} its script's last line (the gain it applied)

    @property
    def extensions(self) -> tuple[str, ...]:
        return tuple(e for _, exts in self.setups for e in exts)

    @property
    def archives(self) -> tuple[str, ...]:
        """The sources it unpacks: the main one, then the parts."""
        return (self.source, *(s for s, _ in self.parts))


@dataclass(frozen=True)
class VerifyScope:
    """What a method's verification (`slamrun verify`) runs where the default (both rooms, forward and backward, two
    trials of 300 frames) would take too long; stated in its row."""

    sequences: tuple[str, ...]
    trials: int
    frames: int
    why: str
    timeout_s: float = 900.0  # one run's limit

    def __str__(self) -> str:
        trials = f"{self.trials} trial" + ("s" if self.trials > 1 else "")
        return f"{', '.join(self.sequences)} only, {trials}, {self.frames} frames: {self.why}"


def declared(cls: type, attr: str, default=None):
    """What `cls` itself declares as `attr` (its class body), never what a base class does."""
    return vars(cls).get(attr, default)


ADDED = "added"  # a parameter's json_schema_extra key: the date it was added to a method that had runs before


def added(date: str) -> dict:
    """json_schema_extra of a parameter added to a method after runs were made with it: left out of the settings'
    name while at its default (engine.plan.hashed), so those runs keep theirs."""
    return {ADDED: date}
