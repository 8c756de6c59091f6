"""MASt3R-SLAM @ b0ae540 with lietorch @ 7f68764 in thirdparty/lietorch, for today's PyTorch (2.11 with CUDA 13),
headless and offline, applied by `slamrun native-build mast3r_slam` and by the image. The tree is MASt3R-SLAM's with
lietorch's archive unpacked into thirdparty/lietorch (its pyproject installs lietorch from GitHub).

- Its own backend (setup.py) is compiled only when `torch.cuda.is_available()` at build time, and only for sm_60-86 by
  hard-coded -gencode flags: it is compiled always (the CUDA sources with it), for $TORCH_CUDA_ARCH_LIST (the flags
  go: a -gencode in the flags makes PyTorch ignore the list, and CUDA 13 compiles nothing below 7.5), with Eigen from
  $EIGEN_INCLUDE_DIR (else Debian's /usr/include/eigen3) instead of the thirdparty/eigen submodule (empty).
- croco's curope (the RoPE kernels the ViT uses; without them croco falls back to a slower PyTorch RoPE) takes its
  targets from `torch.cuda.get_gencode_flags()`, which is empty on a machine without a GPU: $TORCH_CUDA_ARCH_LIST too.
- `AT_DISPATCH_FLOATING_TYPES_AND_HALF(x.type(), ...)` (matching_kernels.cu, curope's kernels.cu): the DeprecatedType
  overload is gone from today's ATen: `x.scalar_type()`, which every other dispatch here already passes. gn_kernels.cu
  calls `torch::linalg::linalg_norm`, whose header (torch/linalg.h) PyTorch 2.11's C++ frontend no longer has: it calls
  `at::linalg_norm`, the ATen function that one forwarded to, with the same arguments.
- lietorch as DROID-SLAM's patches make it (its dispatch macro for today's ATen, no hard-coded -gencode, Eigen from
  $EIGEN_INCLUDE_DIR, lietorch_backends alone: MASt3R-SLAM imports no lietorch_extras).
- The checkpoints hold argparse Namespaces: PyTorch >= 2.6 loads with weights_only=True, which refuses them; the two
  torch.load calls (mast3r/model.py, mast3r/retrieval/processor.py) say weights_only=False, as they meant under the
  PyTorch they were written for (the checkpoints are the user's own files).
- dust3r's model class mixes in huggingface_hub's PyTorchModelHubMixin (download from the Hub by name, which a
  container without network cannot use; slamrun loads files by path through mast3r's load_model): the mixin, its
  import and its version assertion go, so huggingface_hub (and requests) are not needed.
- mast3r_slam/dataloader.py imports pyrealsense2 (a RealSense camera) and torchcodec (videos) at the top: they are
  imported where those two datasets are opened, so image folders load without them.
- main.py imports the viewer (imgui, moderngl: a window) at the top and uses it only when run as a program without
  --no-viz: the import moves under `if __name__ == "__main__"`, so slamrun's process imports main's backend and
  relocalization as they are.
usage: patches.py MAST3R_SLAM_TREE    (thirdparty/lietorch already unpacked)
"""
import os
import sys

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(here, "..", "common"))
sys.path.insert(1, os.path.join(here, "..", "..", "recipes", "common"))  # in slamrun's tree
from patchlib import patch, sub  # noqa: E402

LIETORCH = "thirdparty/lietorch"
CROCO = "thirdparty/mast3r/dust3r/croco"
DUST3R = "thirdparty/mast3r/dust3r/dust3r"
EIGEN_PY = "os.environ.get('EIGEN_INCLUDE_DIR') or '/usr/include/eigen3'"


def lietorch(root):
    """lietorch's dispatch for today's ATen; its extension for $TORCH_CUDA_ARCH_LIST; lietorch_backends alone."""
    patch(root, LIETORCH + "/lietorch/include/dispatch.h", "replace",
          "at::ScalarType _st = ::detail::scalar_type(the_type);", "at::ScalarType _st = the_type;")
    setup = LIETORCH + "/setup.py"
    sub(root, setup, r"[ \t]*'-gencode=arch=compute_\d+,code=(?:sm|compute)_\d+',[ \t]*\n", "", min_count=10)
    sub(root, setup, r"(?s)        CUDAExtension\('lietorch_extras', .*?\}\),\n", "", min_count=1)
    patch(root, setup, "after", "ROOT = osp.dirname(osp.abspath(__file__))\n",
          "import os\nEIGEN = %s  # slamrun: no eigen submodule\n" % EIGEN_PY)
    patch(root, setup, "replace", "osp.join(ROOT, 'eigen')", "EIGEN")


def backend(root):
    """mast3r_slam_backends: always with its CUDA sources, for $TORCH_CUDA_ARCH_LIST, Eigen from the system."""
    patch(root, "setup.py", "replace", "has_cuda = torch.cuda.is_available()",
          "has_cuda = True  # slamrun: compiled without a GPU, for $TORCH_CUDA_ARCH_LIST")
    sub(root, "setup.py", r'[ \t]*"-gencode=arch=compute_\d+,code=sm_\d+",\n', "", min_count=6)
    patch(root, "setup.py", "replace", 'os.path.join(ROOT, "thirdparty/eigen")', EIGEN_PY)
    patch(root, "mast3r_slam/backend/src/matching_kernels.cu", "replace",
          "AT_DISPATCH_FLOATING_TYPES_AND_HALF(D11.type(),", "AT_DISPATCH_FLOATING_TYPES_AND_HALF(D11.scalar_type(),")
    sub(root, "mast3r_slam/backend/src/gn_kernels.cu", r"torch::linalg::linalg_norm\(", "at::linalg_norm(", min_count=3)


def curope(root):
    """croco's RoPE kernels for $TORCH_CUDA_ARCH_LIST, on today's ATen."""
    folder = CROCO + "/models/curope/"
    patch(root, folder + "setup.py", "replace",
          "all_cuda_archs = cuda.get_gencode_flags().replace('compute=','arch=').split()",
          "all_cuda_archs = []  # slamrun: $TORCH_CUDA_ARCH_LIST (no GPU to ask at build time)")
    patch(root, folder + "kernels.cu", "replace",
          "AT_DISPATCH_FLOATING_TYPES_AND_HALF(tokens.type(),", "AT_DISPATCH_FLOATING_TYPES_AND_HALF(tokens.scalar_type(),")


def checkpoints(root):
    """The checkpoints' Namespaces load (weights_only=False); no huggingface_hub."""
    patch(root, "thirdparty/mast3r/mast3r/model.py", "replace",
          "ckpt = torch.load(model_path, map_location='cpu')",
          "ckpt = torch.load(model_path, map_location='cpu', weights_only=False)  # slamrun: a Namespace inside")
    patch(root, "thirdparty/mast3r/mast3r/retrieval/processor.py", "replace",
          "ckpt = torch.load(modelname, 'cpu')",
          "ckpt = torch.load(modelname, 'cpu', weights_only=False)  # slamrun: a Namespace inside")
    model = DUST3R + "/model.py"
    patch(root, model, "replace", "import huggingface_hub\n", "")
    sub(root, model, r"hf_version_number = huggingface_hub.__version__\nassert [^\n]*\n[^\n]*\n", "", min_count=1)
    patch(root, model, "replace", "    huggingface_hub.PyTorchModelHubMixin,\n", "")
    patch(root, model, "replace", '    library_name="dust3r",\n    repo_url="https://github.com/naver/dust3r",\n'
          '    tags=["image-to-3d"],\n', "")


def headless(root):
    """No RealSense, video decoder or viewer unless they are used."""
    loader = "mast3r_slam/dataloader.py"
    patch(root, loader, "replace", "import pyrealsense2 as rs\n", "")
    patch(root, loader, "replace", "from torchcodec.decoders import VideoDecoder\n", "")
    patch(root, loader, "after", "class RealsenseDataset(MonocularDataset):\n    def __init__(self):\n",
          "        global rs\n        import pyrealsense2 as rs  # slamrun: only for a RealSense camera\n\n")
    patch(root, loader, "after", "class MP4Dataset(MonocularDataset):\n    def __init__(self, dataset_path):\n",
          "        from torchcodec.decoders import VideoDecoder  # slamrun: only for a video\n\n")
    patch(root, "main.py", "replace", "from mast3r_slam.visualization import WindowMsg, run_visualization\n", "")
    patch(root, "main.py", "after", 'if __name__ == "__main__":\n',
          "    from mast3r_slam.visualization import WindowMsg, run_visualization  # slamrun: a window's only\n\n")


def mast3r_slam(root):
    if not os.path.isfile(os.path.join(root, LIETORCH, "setup.py")):
        sys.exit("patches: %s holds no lietorch: unpack lietorch's archive into it first" % LIETORCH)
    lietorch(root)
    backend(root)
    curope(root)
    checkpoints(root)
    headless(root)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    mast3r_slam(sys.argv[1])
