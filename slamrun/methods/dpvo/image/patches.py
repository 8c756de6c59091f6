"""DPVO @ 859bbbf for today's PyTorch (2.x with CUDA 12/13), applied by `slamrun native-build dpvo` and by the image.

- AT_DISPATCH and lietorch's own dispatch macro take `x.type()` (a DeprecatedTypeProperties that recent PyTorch's
  dispatch no longer accepts): `x.scalar_type()`, and the macro reads the ScalarType as it is (`::detail::scalar_type`
  is gone from ATen/Dispatch.h).
- `#include <THC/THCAtomics.cuh>`: THC is gone; ATen/cuda/Atomic.cuh holds the same atomicAdd overloads.
- setup.py looks for Eigen in thirdparty/eigen-3.4.0 (a zip its install script downloads): the folder named by
  $EIGEN_INCLUDE_DIR (the native build sets it), else Debian's /usr/include/eigen3. The extensions are built for the
  targets of $TORCH_CUDA_ARCH_LIST, as PyTorch's BuildExtension does.
- torch_scatter (a compiled package PyPI serves as source only) is used for scatter_sum and scatter_softmax alone:
  they become dpvo/_scatter.py, the same two functions on PyTorch's own scatter_add_ and scatter_reduce.
- patchgraph.py imports einops and the loop-closure module (numba, pypose) at the top, for DPV-SLAM's loop closure
  only: the imports move into PatchGraph.edges_loop, so the VO runs without them.
- `torch.cuda.amp.autocast` (deprecated, a FutureWarning at every call site): `torch.autocast("cuda", ...)`.
- net.py imports matplotlib.pyplot and never uses it: the import goes (the image has no matplotlib).
usage: patches.py DPVO_ROOT
"""
import os
import shutil
import sys

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(here, "..", "common"))
sys.path.insert(1, os.path.join(here, "..", "..", "recipes", "common"))  # in slamrun's tree
COMPAT = os.path.join(here, "..", "torch_cuda", "torch_scatter_compat.py")  # in the image (the recipe's copy)
if not os.path.isfile(COMPAT):  # in slamrun's tree
    COMPAT = os.path.join(here, "..", "..", "recipes", "torch_cuda", "torch_scatter_compat.py")
from patchlib import patch, sub  # noqa: E402

AUTOCAST = 'autocast = lambda **kw: torch.autocast("cuda", **kw)  # slamrun: torch.cuda.amp.autocast is deprecated\n'
EIGEN = (
    "EIGEN = os.environ.get('EIGEN_INCLUDE_DIR') or '/usr/include/eigen3'  # slamrun: no thirdparty/eigen-3.4.0\n"
)
LAZY_LOOP_IMPORTS = (
    "        from einops import asnumpy, reduce, repeat  # slamrun: loop closure only\n"
    "        from .loop_closure.optim_utils import reduce_edges  # slamrun: numba, pypose: loop closure only\n"
)


def dispatch(root):
    """x.type() -> x.scalar_type() in every dispatch; lietorch's macro takes the ScalarType as it is."""
    sub(root, "dpvo/altcorr/correlation_kernel.cu", r"(AT_DISPATCH_FLOATING_TYPES_AND_HALF\(\w+)\.type\(\)",
        r"\1.scalar_type()", min_count=4)
    for path in ("dpvo/lietorch/src/lietorch_gpu.cu", "dpvo/lietorch/src/lietorch_cpu.cpp"):
        sub(root, path, r"(DISPATCH_GROUP_AND_FLOATING_TYPES\(group_id, \w+)\.type\(\)", r"\1.scalar_type()",
            min_count=19)
    patch(root, "dpvo/lietorch/include/dispatch.h", "replace",
          "at::ScalarType _st = ::detail::scalar_type(the_type);", "at::ScalarType _st = the_type;")
    patch(root, "dpvo/altcorr/correlation_kernel.cu", "replace",
          "#include <THC/THCAtomics.cuh>", "#include <ATen/cuda/Atomic.cuh>")


def eigen(root):
    """Eigen from $EIGEN_INCLUDE_DIR or Debian's libeigen3-dev instead of the downloaded thirdparty/eigen-3.4.0."""
    patch(root, "setup.py", "after", "ROOT = osp.dirname(osp.abspath(__file__))\n", "import os\n" + EIGEN)
    sub(root, "setup.py", r"osp\.join\(ROOT, 'thirdparty/eigen-3\.4\.0'\)", "EIGEN", min_count=2)


def scatter(root):
    """torch_scatter's two functions from dpvo/_scatter.py (PyTorch's own scatter ops)."""
    shutil.copyfile(COMPAT, os.path.join(root, "dpvo", "_scatter.py"))
    print("patch: dpvo/_scatter.py (scatter_sum, scatter_softmax on PyTorch's scatter ops)")
    patch(root, "dpvo/blocks.py", "replace", "import torch_scatter\n", "from . import _scatter as torch_scatter\n")
    patch(root, "dpvo/net.py", "replace", "import torch_scatter\nfrom torch_scatter import scatter_sum\n",
          "from . import _scatter as torch_scatter\nfrom ._scatter import scatter_sum\n")
    patch(root, "dpvo/ba.py", "replace", "from torch_scatter import scatter_sum\n", "from ._scatter import scatter_sum\n")


def lazy_loop_closure(root):
    """einops, numba and pypose only when DPV-SLAM's loop closure runs."""
    patch(root, "dpvo/patchgraph.py", "replace", "from einops import asnumpy, reduce, repeat\n", "")
    patch(root, "dpvo/patchgraph.py", "replace", "from .loop_closure.optim_utils import reduce_edges\n", "")
    patch(root, "dpvo/patchgraph.py", "after", '        """ Adding edges from old patches to new frames """\n',
          LAZY_LOOP_IMPORTS)


def autocast(root):
    for path in ("dpvo/dpvo.py", "dpvo/net.py"):
        patch(root, path, "replace", "autocast = torch.cuda.amp.autocast\n", AUTOCAST)


def unused_imports(root):
    patch(root, "dpvo/net.py", "replace", "import matplotlib.pyplot as plt\n", "")


def dpvo(root):
    dispatch(root)
    eigen(root)
    scatter(root)
    lazy_loop_closure(root)
    autocast(root)
    unused_imports(root)


if __name__ == "__main__":
    dpvo(sys.argv[1])
