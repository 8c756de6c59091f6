"""The upstream sources the method images build from, each named once by its full commit (in the declaration of the
method that builds from it, or among the libraries several share: slamrun/methods/libraries.py).

A source is the archive GitHub serves for a commit (`https://github.com/<owner>/<repo>/archive/<commit>.tar.gz`,
one top folder `<repo>-<commit>/`). It comes from a folder (`slamrun images --sources DIR`) or from the network
(then kept in a download cache). Each archive is checked before a build: by its SHA-256 where the project
records one, and, since GitHub's archives are not byte-stable, by a digest of the tree it holds (every path,
its executable bit and its content), which any faithful archive of the commit reproduces.
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import tarfile
import tempfile
import urllib.error
import urllib.parse
import urllib.request
from dataclasses import dataclass
from pathlib import Path

import slamrun.methods
from slamrun.errors import SlamRunError
from slamrun.methods.declare import GITHUB, Source, declared
from slamrun.methods.libraries import LIBRARIES

PYPI = "https://pypi.org"


class SourceError(SlamRunError):
    """A source archive is missing, unreachable or not the pinned tree."""


def _declared_sources() -> dict[str, Source]:
    """Every pinned source: the libraries several images share, then each method's own (its folder's declaration).
    A name two declarations give different pins is refused."""
    out: dict[str, Source] = {}
    methods_sources = (s for cls in slamrun.methods.REGISTRY.values() for s in declared(cls, "sources", ()))
    for s in (*LIBRARIES, *methods_sources):
        if out.setdefault(s.name, s) != s:
            raise SlamRunError(f"source {s.name!r} is declared twice with different pins: {out[s.name]} and {s}")
    return out


SOURCES: dict[str, Source] = _declared_sources()


def tree_digest(archive: Path, exclude: tuple[str, ...] = ()) -> str:
    """SHA-256 over the archive's tree (paths below the top folder, executable bits, contents, link targets),
    leaving out the paths in `exclude` (one ending in "/" leaves out every file below that folder).

    Independent of compression, member order and timestamps, so any faithful archive of a commit gives it.
    """
    entries = []
    folders = tuple(e for e in exclude if e.endswith("/"))
    try:
        with tarfile.open(archive, "r:gz") as tar:
            for m in tar:
                parts = m.name.split("/", 1)
                if len(parts) < 2 or not parts[1] or m.isdir():
                    continue
                rel = parts[1].rstrip("/")
                if rel in exclude or (folders and rel.startswith(folders)):
                    continue
                if m.isfile():
                    data = tar.extractfile(m).read()
                    kind = "x" if m.mode & 0o111 else "f"
                    entries.append(f"{kind} {rel} {hashlib.sha256(data).hexdigest()}")
                elif m.issym() or m.islnk():
                    entries.append(f"l {rel} {m.linkname}")
    except (tarfile.TarError, OSError, EOFError) as exc:
        raise SourceError(f"{archive}: not a readable .tar.gz archive ({exc})") from None
    return hashlib.sha256("\n".join(sorted(entries)).encode()).hexdigest()


def file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def check_archive(source: Source, path: Path) -> str:
    """Raise SourceError unless `path` holds the pinned tree; returns how it was checked."""
    actual = file_sha256(path)
    if source.sha256 and actual == source.sha256:
        return "sha256"
    tree = tree_digest(path, source.absent)
    if source.tree and tree == source.tree:
        return "tree"
    expected = f"sha256 {source.sha256}" + (f" or tree digest {source.tree}" if source.tree else "")
    raise SourceError(
        f"{path}: not the archive of {source.repo} @ {source.commit} (sha256 {actual}, tree digest {tree}; "
        f"expected {expected}); replace it with {source.url()}"
    )


def archive_members(path: Path) -> set[str]:
    """Paths below the archive's top folder (to see whether a vocabulary is in the source)."""
    with tarfile.open(path, "r:gz") as tar:
        return {m.name.split("/", 1)[1] for m in tar if "/" in m.name and m.isfile()}


def default_cache() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "slamrun" / "sources"


def obtain(
    name: str,
    sources_dir: Path | None = None,
    cache: Path | None = None,
    base_url: str | None = None,
    timeout_s: float = 60.0,
) -> Path:
    """The checked archive of source `name`: from `sources_dir` when given, else the download cache, else the
    network (`base_url`, default GitHub, or $SLAMRUN_SOURCES_URL)."""
    try:
        source = SOURCES[name]
    except KeyError:
        raise SourceError(f"unknown source {name!r} (known: {', '.join(sorted(SOURCES))})") from None
    if sources_dir is not None:
        path = Path(sources_dir) / source.filename
        if not path.is_file():
            raise SourceError(
                f"{path}: missing; {source.repo} @ {source.commit} is needed: fetch {source.url()} into {sources_dir} "
                f"(or build without --sources to download it)"
            )
        check_archive(source, path)
        return path
    cache = Path(cache or default_cache())
    path = cache / source.filename
    if path.is_file():
        check_archive(source, path)
        return path
    url = source.url(base_url or os.environ.get("SLAMRUN_SOURCES_URL") or GITHUB)
    try:
        _download(url, path, f"{source.repo} @ {source.commit}")
    except SourceError as exc:
        raise SourceError(
            f"{exc}; put {source.filename} into a folder and pass it with --sources DIR (make images SOURCES=DIR)"
        ) from None
    try:
        check_archive(source, path)
    except SourceError:
        path.unlink()
        raise
    return path


@dataclass(frozen=True)
class PypiFile:
    """A file published on PyPI that an image build uses (the build context's pypi/<filename>)."""

    filename: str
    project: str
    version: str
    sha256: str

    def url(self, base: str = PYPI) -> str:
        return f"{base.rstrip('/')}/pypi/{self.project}/{self.version}/json"

    def project_url(self, base: str = PYPI) -> str:
        return f"{base.rstrip('/')}/pypi/{self.project}/json"

    def entries(self, index: dict) -> list[dict]:
        """This release's files in a version index (`urls`) or a project index (`releases[version]`)."""
        return list(index.get("urls") or []) + list((index.get("releases") or {}).get(self.version) or [])


# DynaSLAM's Python 2.7 (Mask R-CNN in the image's embedded python2.7): every file pip installs there, as
# "file name" then its SHA-256 on the next line; project and version come from the file name (pypi_file()).
# Found with `pip download` run by a Python 2.7.18 (pip 20.3.4) on the top-level pins; the build installs exactly
# these with --no-index --require-hashes (slamrun/methods/dynaslam/image/requirements-py27.txt, checked against this
# list).
PY27_DYNASLAM = """
# pip: the last pip for Python 2: installs everything below with --no-index --require-hashes
pip-20.3.4-py2.py3-none-any.whl
    217ae5161a0e08c0fb873858806e3478c9775caffce5168b50ec885e358c199d
# setuptools: the last setuptools for Python 2: builds the pure-Python sdists below (no wheel for Python 2)
setuptools-44.1.1-py2.py3-none-any.whl
    27a714c09253134e60a6fa68130f78c7037e5562c4f21f8f318f2ae900d152d5
# wheel: the last wheel for Python 2
wheel-0.37.1-py2.py3-none-any.whl
    4bdcd7d840138086126cd09254dc6195fb4fc6f01c050a1d7236f2630db1d22a
# tensorflow-cpu: the last TensorFlow 1.x (cp27mu manylinux2010), CPU-only (111 MB, tensorflow's is 412 MB)
tensorflow_cpu-1.15.0-cp27-cp27mu-manylinux2010_x86_64.whl
    cd42c0b1d0aa6724909c28923a167e5211a1cf10df11149a503f5ba210a4fcf2
# keras: the Keras DynaSLAM's users run: matterport's model.py needs keras.engine.topology (gone in 2.2)
Keras-2.1.6-py2.py3-none-any.whl
    a7abff3e87b6706764fbbd0521ba8f54c48f0720fd0495860cd3d2fd67899d48
# numpy: the last numpy for Python 2; its C headers build DynaSLAM's numpy<->cv::Mat conversion
numpy-1.16.6-cp27-cp27mu-manylinux1_x86_64.whl
    1680c8d5086a88d293dfd1a10b6429a09140cacee878034fa2308472ec835db4
# h5py: the last h5py for Python 2: Keras reads mask_rcnn_coco.h5 with it
h5py-2.10.0-cp27-cp27mu-manylinux1_x86_64.whl
    cbf28ae4b5af0f05aa6e7551cee304f1d317dbed1eb7ac1d827cee2f1ef97a99
# scipy: the last scipy for Python 2 with scipy.misc.imresize (gone in 1.3), which Mask R-CNN resizes with
scipy-1.2.3-cp27-cp27mu-manylinux1_x86_64.whl
    e870dfd006ab657f9cc48b099646c5ceb4e812e59a7d460dc80ac9a659f089dc
# scikit-image: the last scikit-image for Python 2 (MaskRCNN.py, utils.py import it)
scikit_image-0.14.5-cp27-cp27mu-manylinux1_x86_64.whl
    152052ebb27e03f3a1643dedefca18edd110d7e5bef7cb0e0869d5e0219580cc
# matplotlib: the last matplotlib for Python 2 (MaskRCNN.py imports pyplot; MPLBACKEND=Agg)
matplotlib-2.2.5-cp27-cp27mu-manylinux1_x86_64.whl
    57077b4023f1af0151b6b580bccfcff2e3ec1e0f689ef58e4d1e751cdfbf13f0
# pillow: the last Pillow for Python 2: scipy.misc.imresize works through it
Pillow-6.2.2-cp27-cp27mu-manylinux1_x86_64.whl
    e3a797a079ce289e59dbd7eac9ca3bf682d52687f718686857281475b7ca8e6a
# grpcio: TensorFlow's: the last release with a cp27mu wheel (1.41 is source only: a long C++ build)
grpcio-1.39.0-cp27-cp27mu-manylinux2010_x86_64.whl
    4039645b8b5d19064766f3a6fa535f1db52a61c4d4de97a6a8945331a354d527
# python-dateutil: matplotlib's: 2.8.2, the last for Python 2 (3.x would be resolved otherwise)
python_dateutil-2.8.2-py2.py3-none-any.whl
    961d03dc3453ebbc59dbdea9e4e11c5651520a876d0f4db161e8674aae935da9
# the rest: their dependencies, as pip 20.3.4 resolves them for Python 2.7 (sdists where PyPI has no
# Python 2 wheel: pure Python, built in the image by setuptools 44)
absl-py-0.15.0.tar.gz
    72d782fbeafba66ba3e525d46bccac949b9a174dbf66233e50ece09ee688dc81
astor-0.8.1-py2.py3-none-any.whl
    070a54e890cefb5b3739d19f30f5a5ec840ffc9c50ffa7d23cc9fc1a38ebbfc5
backports.functools_lru_cache-1.6.6-py2.py3-none-any.whl
    77e27d0ffbb463904bdd5ef8b44363f6cd5ef503e664b3f599a3bf5843ed37cf
backports.weakref-1.0.post1-py2.py3-none-any.whl
    81bc9b51c0abc58edc76aefbbc68c62a787918ffe943a37947e162c3f8e19e82
cloudpickle-1.3.0-py2.py3-none-any.whl
    8664761f810efc07dbb301459e413c99b68fcc6d8703912bd39d86618ac631e3
cycler-0.10.0-py2.py3-none-any.whl
    1d8a5ae1ff6c5cf9b93e8811e581232ad8920aeec647c37316ceac982b08cb2d
decorator-4.4.2-py2.py3-none-any.whl
    41fa54c2a0cc4ba648be4fd43cff00aedf5b9465c9bf18d64325bc225f08f760
enum34-1.1.10-py2-none-any.whl
    a98a201d6de3f2ab3db284e70a33b0f896fbf35f8086594e8c9e74b909058d53
funcsigs-1.0.2-py2.py3-none-any.whl
    330cc27ccbf7f1e992e69fef78261dc7c6569012cf397db8d3de0234e6c937ca
functools32-3.2.3-2.tar.gz
    f6253dfbe0538ad2e387bd8fdfd9293c925d63553f5813c4e587745416501e6d
futures-3.4.0-py2-none-any.whl
    5ec20fa8bdccf96ac9bf9fb2473f51b14c117db638aa8a4a6c27b43532a0efe9
gast-0.2.2.tar.gz
    fe939df4583692f0512161ec1c880e0a10e71e6a232da045ab8edd3756fbadf0
google_pasta-0.2.0-py2-none-any.whl
    4612951da876b1a10fe3960d7226f0c7682cf901e16ac06e473b267a5afa8954
Keras_Applications-1.0.8.tar.gz
    5579f9a12bcde9748f4a12233925a59b93b73ae6947409ff34aa2ba258189fe5
Keras_Preprocessing-1.1.2-py2.py3-none-any.whl
    7b82029b130ff61cc99b55f3bd27427df4838576838c5b2f65940e4fcec99a7b
kiwisolver-1.1.0-cp27-cp27mu-manylinux1_x86_64.whl
    05b5b061e09f60f56244adc885c4a7867da25ca387376b02c1efc29cc16bcd0f
Markdown-3.1.1-py2.py3-none-any.whl
    56a46ac655704b91e5b7e6326ce43d5ef72411376588afa1dd90e881b83c7e8c
mock-3.0.5-py2.py3-none-any.whl
    d157e52d4e5b938c550f39eb2fd15610db062441a9c2747d3dbfa9298211d0f8
networkx-2.2.zip
    45e56f7ab6fe81652fb4bc9f44faddb0e9025f469f602df14e3b2551c2ea5c8b
opt_einsum-2.3.2.tar.gz
    d3d464b4da7ef09e444c30e4003a27def37f85ff10ff2671e5f7d7813adac35b
protobuf-3.17.3-cp27-cp27mu-manylinux_2_5_x86_64.manylinux1_x86_64.whl
    13ee7be3c2d9a5d2b42a1030976f760f28755fcf5863c55b1460fd205e6cd637
pyparsing-2.4.7-py2.py3-none-any.whl
    ef9d7589ef3c200abe66653d3f1ab1033c3c419ae9b9bdb1240a85b024efc88b
pytz-2026.6-py2.py3-none-any.whl
    7fed3fee8fd6bd4a2b7b75a8d56021d0624127bf69bd5691f115db929ac570b3
PyWavelets-1.0.3-cp27-cp27mu-manylinux1_x86_64.whl
    e89551257233a3da717a9e6e2e303243df75faffe0b6781d21c15eb9d682ec6d
PyYAML-5.4.1-cp27-cp27mu-manylinux1_x86_64.whl
    bb4191dfc9306777bc594117aee052446b3fa88737cd13b7188d0e7aa8162185
six-1.17.0-py2.py3-none-any.whl
    4721f391ed90541fddacab5acf947aa0d3dc7d27b2e1e8eda2be8970586c3274
subprocess32-3.5.4-cp27-cp27mu-manylinux2014_x86_64.whl
    e45d985aef903c5b7444d34350b05da91a9e0ea015415ab45a21212786c649d0
tensorboard-1.15.0-py2-none-any.whl
    612b789386aa1b2c4804e1961273b37f8e4dd97613f98bc90ff0402d24627f50
tensorflow_estimator-1.15.1-py2.py3-none-any.whl
    8853bfb7c3c96fbdc80b3d66c37a10af6ccbcd235dc87474764270c02a0f86b9
termcolor-1.1.0.tar.gz
    1d6d69ce66211143803fbc56652b41d73b4a400a2891d7bf7a1cdf4c02de613b
Werkzeug-1.0.1-py2.py3-none-any.whl
    2de2a5db0baeae7b2d2664949077c2ac63fbd16d98da0ff71837f7d1dea3fd43
wrapt-1.15.0-cp27-cp27mu-manylinux2010_x86_64.whl
    58d7a75d731e8c63614222bcb21dd992b4ab01a399f1f09dd82af17bbfc2368a
"""


# The torch-cuda stages DPVO's and DROID-SLAM's images share (slamrun/methods/recipes/torch_cuda/stages.Dockerfile: one
# list for both): PyTorch 2.11.0, the PyPI build for CUDA 13.0
# (cp311, Debian 12's Python), with every file pip resolves for it, and the CUDA 13.0 compiler as PyPI wheels (no GPU
# needed to compile). CUDA 13 because PyPI's CUDA 12 compiler wheels (nvidia-cuda-nvcc-cu12, 12.1 to 12.9) hold ptxas
# alone, no nvcc or cicc.
# Found with `pip download --only-binary=:all: --python-version 3.11 --platform manylinux_2_{5..36}_x86_64
# torch==2.11.0 'cuda-toolkit[nvcc,cccl,crt,nvvm]==13.0.2' ninja==1.13.0 numpy==2.2.6
# opencv-python-headless==4.11.0.86` (and pip==26.3). The runtime stage keeps DPVO_TORCH only
# (slamrun/methods/recipes/torch_cuda/requirements.txt); DPVO_TOOLCHAIN compiles the extensions in the build stage and
# is uninstalled before the runtime stage copies the environment
# (slamrun/methods/recipes/torch_cuda/requirements-build.txt); tests/test_dpvo_image.py checks both files against these
# lists.
DPVO_TORCH = """
# pip: installs everything below with --no-index --require-hashes (Debian's venv has no pip of its own)
pip-26.3-py3-none-any.whl
    f3b60b20ffaadd4415ed7957212a38ac63fa4c5fa375bd0f4a797777940fad13
# torch: the PyPI build for CUDA 13.0 (torch.version.cuda 13.0: kernels for compute capability 7.5 to 12.0); its CUDA
# libraries come as cuda-toolkit 13.0.2's wheels, which pins each one
torch-2.11.0-cp311-cp311-manylinux_2_28_x86_64.whl
    7aa2f9bbc6d4595ba72138026b2074be1233186150e9292865e04b7a63b8c67a
cuda_toolkit-13.0.2-py2.py3-none-any.whl
    b198824cf2f54003f50d64ada3a0f184b42ca0846c1c94192fa269ecd97a66eb
# the CUDA 13.0 runtime libraries cuda-toolkit 13.0.2 names for torch (the extras cublas, cudart, cufft, cufile,
# cupti, curand, cusolver, cusparse, nvjitlink, nvrtc, nvtx)
nvidia_cuda_runtime-13.0.96-py3-none-manylinux2014_x86_64.manylinux_2_17_x86_64.whl
    7f82250d7782aa23b6cfe765ecc7db554bd3c2870c43f3d1821f1d18aebf0548
nvidia_cuda_nvrtc-13.0.88-py3-none-manylinux2010_x86_64.manylinux_2_12_x86_64.whl
    ad9b6d2ead2435f11cbb6868809d2adeeee302e9bb94bcf0539c7a40d80e8575
nvidia_cuda_cupti-13.0.85-py3-none-manylinux_2_25_x86_64.whl
    4eb01c08e859bf924d222250d2e8f8b8ff6d3db4721288cf35d14252a4d933c8
nvidia_cublas-13.1.0.3-py3-none-manylinux_2_27_x86_64.whl
    ee8722c1f0145ab246bccb9e452153b5e0515fd094c3678df50b2a0888b8b171
nvidia_cufft-12.0.0.61-py3-none-manylinux2014_x86_64.manylinux_2_17_x86_64.whl
    6c44f692dce8fd5ffd3e3df134b6cdb9c2f72d99cf40b62c32dde45eea9ddad3
nvidia_cufile-1.15.1.6-py3-none-manylinux2014_x86_64.manylinux_2_17_x86_64.whl
    08a3ecefae5a01c7f5117351c64f17c7c62efa5fffdbe24fc7d298da19cd0b44
nvidia_curand-10.4.0.35-py3-none-manylinux_2_27_x86_64.whl
    1aee33a5da6e1db083fe2b90082def8915f30f3248d5896bcec36a579d941bfc
nvidia_cusolver-12.0.4.66-py3-none-manylinux_2_27_x86_64.whl
    0a759da5dea5c0ea10fd307de75cdeb59e7ea4fcb8add0924859b944babf1112
nvidia_cusparse-12.6.3.3-py3-none-manylinux2014_x86_64.manylinux_2_17_x86_64.whl
    2b3c89c88d01ee0e477cb7f82ef60a11a4bcd57b6b87c33f789350b59759360b
nvidia_nvjitlink-13.0.88-py3-none-manylinux2010_x86_64.manylinux_2_12_x86_64.whl
    13a74f429e23b921c1109976abefacc69835f2f433ebd323d3946e11d804e47b
nvidia_nvtx-13.0.85-py3-none-manylinux1_x86_64.manylinux_2_5_x86_64.whl
    4936d1d6780fbe68db454f5e72a42ff64d1fd6397df9f363ae786930fd5c1cd4
# the libraries torch 2.11.0 pins beside cuda-toolkit: cuDNN, cuSPARSELt, NCCL, NVSHMEM, CUDA's Python bindings
nvidia_cudnn_cu13-9.19.0.56-py3-none-manylinux_2_27_x86_64.whl
    d20e1734305e9d68889a96e3f35094d733ff1f83932ebe462753973e53a572bf
nvidia_cusparselt_cu13-0.8.0-py3-none-manylinux2014_x86_64.whl
    25e30a8a7323935d4ad0340b95a0b69926eee755767e8e0b1cf8dd85b197d3fd
nvidia_nccl_cu13-2.28.9-py3-none-manylinux_2_18_x86_64.whl
    e4553a30f34195f3fa1da02a6da3d6337d28f2003943aa0a3d247bbc25fefc42
nvidia_nvshmem_cu13-3.4.5-py3-none-manylinux2014_x86_64.manylinux_2_17_x86_64.whl
    290f0a2ee94c9f3687a02502f3b9299a9f9fe826e6d0287ee18482e78d495b80
cuda_bindings-13.5.0-cp311-cp311-manylinux_2_24_x86_64.manylinux_2_28_x86_64.whl
    08b7e8d674c3266facb00453a7e34ea7d3ea965c2f594bb728f269f45f39fbe2
cuda_pathfinder-1.9.1-py3-none-any.whl
    b743c132f90ad2d1e71d43fd28f31ebcde518f943e50fd44aca62b2a80d5230d
# triton: a requirement of torch on Linux (torch.compile only; DPVO does not use it)
triton-3.6.0-cp311-cp311-manylinux_2_27_x86_64.manylinux_2_28_x86_64.whl
    e8e323d608e3a9bfcc2d9efcc90ceefb764a82b99dea12a86d643c72539ad5d3
# torch's pure-Python requirements (setuptools: torch 2.11 requires it, <82; it also runs DPVO's setup.py)
filelock-4.3.1-py3-none-any.whl
    79e43df8e9fe509cd83a3899a7c186c8077cbbe4d200a1ed3705c2f3bb6bc487
fsspec-2026.9.0-py3-none-any.whl
    8dd6e646e99ea382bd85f97a45e6b526a442d79423a7dc673f1e2756d05fcb5f
jinja2-3.1.6-py3-none-any.whl
    85ece4451f492d0c13c5dd7c13a64681a86afae63a5f347908daf103ce6d2f67
markupsafe-3.0.4-cp311-cp311-manylinux2014_x86_64.manylinux_2_17_x86_64.manylinux_2_28_x86_64.whl
    6da83a088f8ef93b2d483a8232a4dbf4d69d3d8496b568a03c56becac43e1808
mpmath-1.3.0-py3-none-any.whl
    a0b2b9fe80bbcd81a6647ff13108738cfb482d481d826cc0e02f5b35e5c88d2c
networkx-3.6.1-py3-none-any.whl
    d47fbf302e7d9cbbb9e2555a0d267983d2aa476bac30e90dfbe5669bd57f3762
setuptools-81.0.0-py3-none-any.whl
    fdd925d5c5d9f62e4b74b30d6dd7828ce236fd6ed998a08d81de62ce5a6310d6
sympy-1.14.0-py3-none-any.whl
    e091cc3e99d2141a0ba2847328f5479b05d94a6635cb96148ccb3f34671bd8f5
typing_extensions-4.16.0-py3-none-any.whl
    481caa481374e813c1b176ada14e97f1f67a4539ce9cfeb3f350d78d6370c2e8
# what slamrun's DPVO process reads frames with (the same files as the reference VO's image)
numpy-2.2.6-cp311-cp311-manylinux_2_17_x86_64.manylinux2014_x86_64.whl
    ba10f8411898fc418a521833e014a77d3ca01c15b0c6cdcce6a0d2897e6dbbdf
opencv_python_headless-4.11.0.86-cp37-abi3-manylinux_2_17_x86_64.manylinux2014_x86_64.whl
    0e0a27c19dd1f40ddff94976cfe43066fbbe9dfbb2ec1907d66c19caef42a57b
"""
DPVO_TOOLCHAIN = """
# the CUDA 13.0 compiler as cuda-toolkit 13.0.2 pins it (its extras nvcc, crt, nvvm, cccl): nvcc, ptxas, fatbinary
# and cudafe++; the crt headers; nvvm (cicc, libdevice); cccl (thrust, cub, libcu++). All land in nvidia/cu13
# beside the runtime's headers and libraries: that folder is CUDA_HOME
nvidia_cuda_nvcc-13.0.88-py3-none-manylinux2014_x86_64.manylinux_2_17_x86_64.whl
    56fe502eb77625a12f25172caa3cdddb4e4c8ba2c8c17dba44b164761b380f03
nvidia_cuda_crt-13.0.88-py3-none-manylinux2014_x86_64.manylinux_2_17_x86_64.whl
    2c8043c7c9e02492716426e9919fc78d2c5b3b2a7a768a88e952676b08aa55a4
nvidia_nvvm-13.0.88-py3-none-manylinux2010_x86_64.manylinux_2_12_x86_64.whl
    c5f41ffeb6466944a026dfa5317d7d85355c119bbec279205d22f1869d1054e0
nvidia_cuda_cccl-13.0.85-py3-none-manylinux2014_x86_64.manylinux_2_17_x86_64.whl
    e0da7ad981f3a8aff08241b5bfc1af868742a63e2762f53a5171c492ef242649
# ninja: PyTorch's BuildExtension compiles in parallel with it (MAX_JOBS)
ninja-1.13.0-py3-none-manylinux2014_x86_64.manylinux_2_17_x86_64.whl
    fb46acf6b93b8dd0322adc3a4945452a4e774b75b91293bafcc7b7f8e6517dfa
"""

# What DPV-SLAM's loop closure imports beside PyTorch (DPVO's dpvo/loop_closure/optim_utils.py, imported by
# PatchGraph.edges_loop when `loop_closure: true`): installed into the same environment with pip --no-index
# --require-hashes --no-deps (slamrun/methods/recipes/torch_cuda/requirements-loop-closure.txt): pypose declares pytest
# as a requirement, for its own tests, and imports only torch and packaging. Found with `pip download
# --only-binary=:all: --python-version 3.11 --no-deps` on the pins below; numba 0.61.2 takes numpy < 2.3 (2.2.6 here).
DPVO_LOOP_CLOSURE = """
# numba: reduce_edges (the loop edges' non-maximum suppression) is @njit; llvmlite is its compiler
numba-0.61.2-cp311-cp311-manylinux2014_x86_64.manylinux_2_17_x86_64.whl
    3945615cd73c2c7eba2a85ccc9c1730c21cd3958bfcf5a44302abae0fb07bb60
llvmlite-0.44.0-cp311-cp311-manylinux_2_17_x86_64.manylinux2014_x86_64.whl
    c5d22c3bfc842668168a786af4205ec8e3ad29fb1bc03fd11fd48460d0df64c1
# pypose: the Sim(3) poses of the classical loop closure's pose graph (imported by the module); packaging: its import
pypose-0.9.5-py3-none-any.whl
    ba9e8babbf5b54b1d54168fb030458d8ef84e66f7d5d013d5263eec27b70bed1
packaging-25.0-py3-none-any.whl
    29572ef2b1f17581046b3a2227d5c611fb25ec70ca1ba8554b24b0e69331a484
# einops: the patch graph's reductions; scipy: the module's Rotation import (the same file as the reference VO's)
einops-0.8.2-py3-none-any.whl
    54058201ac7087911181bfec4af6091bb59380360f069276601256a76af08193
scipy-1.15.3-cp311-cp311-manylinux_2_17_x86_64.manylinux2014_x86_64.whl
    39cb9c62e471b1bb3750066ecc3a3f3052b37751c7c3dfd0fd7e48900ed52982
"""

# MASt3R-SLAM's image (slamrun/methods/mast3r_slam/image/Dockerfile): what its modules import beside PyTorch, NumPy,
# OpenCV, einops, scipy and packaging (the torch-cuda stage's), installed into its runtime with --require-hashes
# --no-deps (slamrun/methods/mast3r_slam/image/requirements.txt). Not pinned by upstream (its pyproject names numpy
# 1.26.4, which today's PyTorch wheels are not built for, and no versions for the rest): today's releases for
# Python 3.11, found with `pip download --only-binary=:all: --python-version 3.11 --no-deps`. Left out: pyrealsense2
# and torchcodec (a camera and videos: imported only for them, patches.py), huggingface_hub (the Hub mixin, removed
# by patches.py), evo, pykdtree, roma and trimesh (neither the SLAM nor its network imports them), the viewer's imgui
# and moderngl.
MAST3R_SLAM = """
# torchvision: dust3r's image normalisation (torchvision.transforms), the release built with PyTorch 2.11.0 (CUDA 13.0)
torchvision-0.26.0-cp311-cp311-manylinux_2_28_x86_64.whl
    fd10b5f994c210f4f6d6761cf686f82d748554adf486cb0979770c3252868c8f
# Pillow: MASt3R's resize (mast3r_utils.resize_img) and torchvision's
pillow-13.0.0-cp311-cp311-manylinux_2_27_x86_64.manylinux_2_28_x86_64.whl
    a625df9a2a5597fa5e5266e01aefc82604bb85d291e3547981e863560d75da6c
# faiss-cpu: asmk's codebook index (the retrieval of loop candidates; faiss-gpu is not on PyPI, and processor.py
# falls back to the CPU index)
faiss_cpu-1.15.1-cp310-abi3-manylinux_2_27_x86_64.manylinux_2_28_x86_64.whl
    f2c31b7f2f6647eb76829a5cfe3c398fb9346df9f26b1d4db35269c91eb58c33
# PyYAML: its config files and asmk's parameters; tqdm, natsort, plyfile: imported at the top of main.py, the retrieval
# model, the dataloader and evaluate.py
pyyaml-6.0.4-cp311-cp311-manylinux2014_x86_64.manylinux_2_17_x86_64.manylinux_2_28_x86_64.whl
    622aa875fa6533f25fedcffe23079357d65a690d462200afed5d8e9d0e01ebee
tqdm-4.70.1-py3-none-any.whl
    c293e525e6fef9c20e8728fd4612df02a0aa31bb5fe91ecd93e123b1b7bffa73
natsort-8.4.0-py3-none-any.whl
    4732914fb471f56b5cce04d7bae6f164a592c7712e1c85f9ef585e197299521c
plyfile-1.1.5-py3-none-any.whl
    675c0fc22b949c49398f5ed6725a1d781f6a9f7625b42232c02198f6509c4ae3
"""


def pypi_file(filename: str, sha256: str) -> PypiFile:
    """A PyPI file named by the conventions of wheels (`<project>-<version>-<tags>.whl`) and sdists
    (`<project>-<version>.tar.gz|.zip`), its project name normalised as PyPI does."""
    if filename.endswith(".whl"):
        project, version = filename.split("-")[:2]
    else:
        m = re.fullmatch(r"(.+?)-(\d[^-]*(?:-\d+)?)\.(?:tar\.gz|zip)", filename)
        if not m:
            raise SourceError(f"{filename}: not a wheel or sdist file name")
        project, version = m.groups()
    return PypiFile(filename, re.sub(r"[-_.]+", "-", project).lower(), version, sha256)


def pypi_table(text: str) -> tuple[PypiFile, ...]:
    """The files of a table like PY27_DYNASLAM (comments left out)."""
    words = [w for line in text.splitlines() if not line.lstrip().startswith("#") for w in line.split()]
    return tuple(pypi_file(name, sha) for name, sha in zip(words[::2], words[1::2], strict=True))


def requirements(files: list[PypiFile]) -> str:
    """A pip requirements file pinning `files` by version and SHA-256 (`pip install --require-hashes`)."""
    return "".join(f"{f.project}=={f.version} --hash=sha256:{f.sha256}\n" for f in files)


PYPI_FILES: dict[str, PypiFile] = {
    f.filename: f
    for f in (
        # TensorFlow 2 C++ (libtensorflow_cc.so.2, libtensorflow_framework.so.2, headers) for CNN-DSO and CNN-SVO
        PypiFile(
            "tensorflow_cpu-2.21.0-cp311-cp311-manylinux_2_27_x86_64.whl",
            "tensorflow-cpu",
            "2.21.0",
            "2b847d217b02ee7731ed91431daf3250daa0196c3c94614d23be27232e6e5b6c",
        ),
        # The reference VO's image: NumPy, SciPy and OpenCV (headless: its own libraries inside, no VTK, GDAL or
        # Qt) as wheels on Debian 12's Python 3.11, instead of Debian's python3-opencv and python3-scipy (2 GB)
        PypiFile(
            "numpy-2.2.6-cp311-cp311-manylinux_2_17_x86_64.manylinux2014_x86_64.whl",
            "numpy",
            "2.2.6",
            "ba10f8411898fc418a521833e014a77d3ca01c15b0c6cdcce6a0d2897e6dbbdf",
        ),
        PypiFile(
            "scipy-1.15.3-cp311-cp311-manylinux_2_17_x86_64.manylinux2014_x86_64.whl",
            "scipy",
            "1.15.3",
            "39cb9c62e471b1bb3750066ecc3a3f3052b37751c7c3dfd0fd7e48900ed52982",
        ),
        PypiFile(
            "opencv_python_headless-4.11.0.86-cp37-abi3-manylinux_2_17_x86_64.manylinux2014_x86_64.whl",
            "opencv-python-headless",
            "4.11.0.86",
            "0e0a27c19dd1f40ddff94976cfe43066fbbe9dfbb2ec1907d66c19caef42a57b",
        ),
        *pypi_table(PY27_DYNASLAM),
        *pypi_table(DPVO_TORCH),
        *pypi_table(DPVO_TOOLCHAIN),
        *pypi_table(DPVO_LOOP_CLOSURE),
        *pypi_table(MAST3R_SLAM),
    )
}


def obtain_pypi(
    file: str | PypiFile, sources_dir: Path | None = None, cache: Path | None = None, index_url: str | None = None
) -> Path:
    """The checked PyPI file: from `sources_dir` when it holds it, else the download cache, else PyPI (its JSON
    API names the file's address; `index_url` or $SLAMRUN_PYPI_URL for a mirror)."""
    if isinstance(file, PypiFile):
        f = file
    elif file in PYPI_FILES:
        f = PYPI_FILES[file]
    else:
        raise SourceError(f"unknown PyPI file {file!r} (known: {', '.join(sorted(PYPI_FILES))})")
    filename = f.filename

    def checked(path: Path) -> Path:
        actual = file_sha256(path)
        if actual != f.sha256:
            raise SourceError(f"{path}: sha256 {actual}, expected {f.sha256} ({f.project} {f.version}); replace it")
        return path

    if sources_dir is not None and (Path(sources_dir) / filename).is_file():
        return checked(Path(sources_dir) / filename)
    cache = Path(cache or default_cache())
    path = cache / filename
    if path.is_file():
        return checked(path)
    base = index_url or os.environ.get("SLAMRUN_PYPI_URL") or PYPI
    url = _pypi_file_url(f, base)
    _download(url, path, f"{filename} ({f.project}=={f.version})")
    try:
        return checked(path)
    except SourceError:
        path.unlink()
        raise


def _pypi_file_url(f: PypiFile, base: str) -> str:
    """The address of `f` by PyPI's JSON API: the release's index, else the project's (mirrors may serve only that
    one, with addresses relative to it)."""
    import json

    index, problem = f.url(base), ""
    for index in (f.url(base), f.project_url(base)):
        try:
            with urllib.request.urlopen(index, timeout=60) as resp:
                listing = json.load(resp)
        except (urllib.error.URLError, OSError, ValueError) as exc:
            problem = str(getattr(exc, "reason", exc))
            continue
        entry = next((u for u in f.entries(listing) if u.get("filename") == f.filename), None)
        if entry is not None:
            return urllib.parse.urljoin(index, entry["url"])
        problem = f"it does not list {f.filename}"
    raise SourceError(
        f"cannot find {f.filename} at {index} ({problem}): it is needed; download it from PyPI "
        f"({f.project}=={f.version}) and pass its folder with --sources DIR"
    )


def _download(url: str, dest: Path, what: str, timeout_s: float = 60.0) -> None:
    dest.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=dest.parent, prefix=dest.name, suffix=".part")
    try:
        with os.fdopen(fd, "wb") as out, urllib.request.urlopen(url, timeout=timeout_s) as resp:
            shutil.copyfileobj(resp, out, 1 << 20)
        os.replace(tmp, dest)
    except (urllib.error.URLError, OSError) as exc:
        raise SourceError(f"cannot download {url} ({getattr(exc, 'reason', exc)}): {what} is needed") from None
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def obtain_url(url: str, sha256: str, cache: Path | None = None) -> Path:
    """A file given by address and SHA-256 (weights a user publishes), downloaded once into the cache."""
    if not re.fullmatch(r"[0-9a-f]{64}", sha256 or ""):
        raise SourceError(f"{url}: a file by address needs its sha256 (URL#sha256=<64 hex digits>)")
    path = Path(cache or default_cache()) / "files" / f"{sha256[:16]}-{Path(urllib.parse.urlparse(url).path).name}"
    if not path.is_file():
        _download(url, path, "a weights file")
    actual = file_sha256(path)
    if actual != sha256:
        path.unlink()
        raise SourceError(f"{url}: sha256 {actual}, expected {sha256}: refusing it")
    return path
