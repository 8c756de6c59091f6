"""The image's check, run at build time without a GPU: the compiled parts (lietorch_backends, mast3r_slam_backends,
croco's curope, asmk's hamming) and MASt3R-SLAM's modules import headless (main.py without its viewer), the network
loads through mast3r's load_model and the retrieval head and codebook through MASt3R-SLAM's load_retriever, as its
backend loads them, and lietorch's Sim3 on the CPU keeps the conventions slamrun's process relies on (a frame's pose
relative to its keyframe, composed back with the keyframe's, is the frame's; as_SE3 keeps translation and rotation).
Nothing touches CUDA.
usage: python3 check_image.py [BUILD_DIR]    (default /opt/mast3r_slam)"""

import json
import sys
from pathlib import Path

import torch  # first: the extensions link against its libraries

build = Path(sys.argv[1] if len(sys.argv) > 1 else "/opt/mast3r_slam")
record = json.loads((build / "build.json").read_text())
tree = build / record["tree"]
sys.path[:0] = [str(tree), str(tree / "thirdparty" / "mast3r"), str(tree / "thirdparty" / "mast3r" / "asmk"),
                str(tree / "thirdparty" / "lietorch")]

import asmk.hamming  # noqa: E402, F401
import lietorch  # noqa: E402
import lietorch_backends  # noqa: E402, F401
import main  # noqa: E402, F401 - MASt3R-SLAM's main.py: its backend and relocalisation
import mast3r_slam_backends  # noqa: E402, F401
from mast3r_slam.lietorch_utils import as_SE3  # noqa: E402
from mast3r_slam.mast3r_utils import load_mast3r, load_retriever  # noqa: E402
from models.curope import cuRoPE2D  # noqa: E402, F401 - croco's kernels (on the path once mast3r is imported)

network = build / record["weights_file"]
model = load_mast3r(path=str(network), device="cpu")
stem = network.name.removesuffix(".pth")
retriever = load_retriever(model, str(network.with_name(stem + "_retrieval_trainingfree.pth")), device="cpu")
assert retriever.centroids.shape[1] == retriever.model.dim, retriever.centroids.shape

torch.manual_seed(0)
half = 0.5**0.5
T_WK = lietorch.Sim3(torch.tensor([[1.0, 2.0, 3.0, 0.0, 0.0, half, half, 2.0]], dtype=torch.float64))
T_WF = lietorch.Sim3(torch.tensor([[0.5, -1.0, 2.0, half, 0.0, 0.0, half, 1.5]], dtype=torch.float64))
back = (T_WK * (T_WK.inv() * T_WF)).data
assert torch.allclose(back, T_WF.data, atol=1e-9), back.tolist()
se3 = as_SE3(T_WF).data[0]
assert torch.allclose(se3, T_WF.data[0, :7]), se3.tolist()
print(
    f"mast3r_slam image: torch {torch.__version__} (CUDA {torch.version.cuda}), extensions for {record['arch']}, "
    f"{sum(p.numel() for p in model.parameters()) / 1e6:.0f} M parameters; weights: {record['weights']}"
)
