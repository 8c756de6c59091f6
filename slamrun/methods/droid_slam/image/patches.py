"""DROID-SLAM @ 2dfd39f with lietorch @ 7f68764 in thirdparty/lietorch, for today's PyTorch (2.x with CUDA 13), applied
by `slamrun native-build droid_slam` and by the image. The tree is DROID-SLAM's with lietorch's archive unpacked into
its (empty) submodule folder thirdparty/lietorch; pytorch_scatter's is not needed (below).

- lietorch's dispatch macro reads `::detail::scalar_type(the_type)`, gone from ATen/Dispatch.h: it takes the ScalarType
  as it is (every call already passes `x.scalar_type()` at this commit).
- `#include <THC/THCAtomics.cuh>` (altcorr_kernel.cu): THC is gone; ATen/cuda/Atomic.cuh holds the same atomicAdd.
- lietorch's setup.py hard-codes `-gencode` for compute capability 6.0 to 7.5 (CUDA 13 compiles none below 7.5, and a
  -gencode in the flags makes PyTorch ignore TORCH_CUDA_ARCH_LIST): the flags go, so both extensions are built for the
  targets of $TORCH_CUDA_ARCH_LIST. Its second extension, lietorch_extras, goes too: DROID-SLAM never imports it.
- Eigen from the lietorch/eigen submodule (empty in the archive): the folder named by $EIGEN_INCLUDE_DIR (the builds
  set it), else Debian's /usr/include/eigen3.
- torch_scatter (a compiled package PyPI serves as source only) is used for scatter_mean (droid_net.py) and scatter_sum
  (geom/ba.py) alone, and both are pure Python in pytorch_scatter itself (torch_scatter/scatter.py, on PyTorch's
  scatter_add_): they become droid_slam/_scatter.py (slamrun/methods/recipes/torch_cuda/torch_scatter_compat.py, DPVO's too). Compiling
  pytorch_scatter's own CUDA kernels, which these two never call, would cost build time for nothing.
- factor_graph.py imports matplotlib.pyplot and never uses it; data_readers/rgbd_utils.py (imported through
  geom/graph_utils.py by droid_net.py) imports scipy for one training-data helper: the first import goes, the second
  moves into that helper, so the SLAM runs headless without matplotlib or scipy (the visualizer, open3d, is imported
  only without --disable_vis, which slamrun's process always sets).
usage: patches.py DROID_TREE    (thirdparty/lietorch already unpacked)
"""
import os
import shutil
import sys

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(here, "..", "common"))
sys.path.insert(1, os.path.join(here, "..", "..", "recipes", "common"))  # in slamrun's tree
from patchlib import patch, sub  # noqa: E402

COMPAT = os.path.join(here, "..", "torch_cuda", "torch_scatter_compat.py")  # in the image (the recipe's copy)
if not os.path.isfile(COMPAT):  # in slamrun's tree
    COMPAT = os.path.join(here, "..", "..", "recipes", "torch_cuda", "torch_scatter_compat.py")
LIETORCH = "thirdparty/lietorch"
EIGEN = (
    "import os\n"
    "EIGEN = os.environ.get('EIGEN_INCLUDE_DIR') or '/usr/include/eigen3'  # slamrun: no eigen submodule\n"
)
LAZY_SCIPY = "    from scipy.spatial.transform import Rotation  # slamrun: training data only\n"


def lietorch(root):
    """lietorch's dispatch for today's ATen; its extension for $TORCH_CUDA_ARCH_LIST; lietorch_backends alone."""
    patch(root, LIETORCH + "/lietorch/include/dispatch.h", "replace",
          "at::ScalarType _st = ::detail::scalar_type(the_type);", "at::ScalarType _st = the_type;")
    setup = LIETORCH + "/setup.py"
    sub(root, setup, r"[ \t]*'-gencode=arch=compute_\d+,code=(?:sm|compute)_\d+',[ \t]*\n", "", min_count=10)
    sub(root, setup, r"(?s)        CUDAExtension\('lietorch_extras', .*?\}\),\n", "", min_count=1)
    patch(root, setup, "after", "ROOT = osp.dirname(osp.abspath(__file__))\n", EIGEN)
    patch(root, setup, "replace", "osp.join(ROOT, 'eigen')", "EIGEN")


def droid_backends(root):
    """droid_backends: Eigen from $EIGEN_INCLUDE_DIR; ATen's atomics instead of THC's."""
    patch(root, "setup.py", "after", "ROOT = osp.dirname(osp.abspath(__file__))\n", EIGEN)
    patch(root, "setup.py", "replace", "osp.join(ROOT, 'thirdparty/lietorch/eigen')", "EIGEN")
    patch(root, "src/altcorr_kernel.cu", "replace", "#include <THC/THCAtomics.cuh>", "#include <ATen/cuda/Atomic.cuh>")


def scatter(root):
    """torch_scatter's scatter_mean and scatter_sum from droid_slam/_scatter.py (PyTorch's own scatter ops)."""
    shutil.copyfile(COMPAT, os.path.join(root, "droid_slam", "_scatter.py"))
    print("patch: droid_slam/_scatter.py (scatter_sum, scatter_mean on PyTorch's scatter ops)")
    patch(root, "droid_slam/droid_net.py", "replace", "from torch_scatter import scatter_mean\n",
          "from _scatter import scatter_mean  # slamrun: torch_scatter's, on PyTorch's scatter ops\n")
    patch(root, "droid_slam/geom/ba.py", "replace", "from torch_scatter import scatter_sum\n",
          "from _scatter import scatter_sum  # slamrun: torch_scatter's, on PyTorch's scatter ops\n")


def headless(root):
    """No matplotlib (never used), scipy only where training data is read."""
    patch(root, "droid_slam/factor_graph.py", "replace", "import matplotlib.pyplot as plt\n", "")
    rgbd = "droid_slam/data_readers/rgbd_utils.py"
    patch(root, rgbd, "replace", "from scipy.spatial.transform import Rotation\n", "")
    patch(root, rgbd, "after", '    """ convert 4x4 pose matrix to (t, q) """\n', LAZY_SCIPY)


def droid_slam(root):
    if not os.path.isfile(os.path.join(root, LIETORCH, "setup.py")):
        sys.exit("patch: %s: %s/setup.py missing: unpack lietorch's archive there first" % (root, LIETORCH))
    lietorch(root)
    droid_backends(root)
    scatter(root)
    headless(root)


if __name__ == "__main__":
    droid_slam(sys.argv[1])
