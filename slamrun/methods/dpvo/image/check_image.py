"""The image's check, run at build time without a GPU: DPVO's compiled extensions and package import, the network
loads into VONet, and DPV-SLAM's loop-closure module imports and selects loop edges (its numba-compiled
reduce_edges, on the CPU, on a case worked by hand). Nothing touches CUDA (dpvo.dpvo, which builds a CUDA tensor at
import, is not imported).
usage: python3 check_image.py [BUILD_DIR]    (default /opt/dpvo)"""

import json
import sys
from pathlib import Path

import torch  # first: the extensions link against its libraries

build = Path(sys.argv[1] if len(sys.argv) > 1 else "/opt/dpvo")
record = json.loads((build / "build.json").read_text())
sys.path.insert(0, str(build / record["tree"]))

import cuda_ba  # noqa: E402, F401
import cuda_corr  # noqa: E402, F401
import lietorch_backends  # noqa: E402, F401
import numpy as np  # noqa: E402
from dpvo.loop_closure.optim_utils import reduce_edges  # noqa: E402 - numba, pypose, einops, scipy, cuda_ba
from dpvo.net import VONet  # noqa: E402

# three candidate loop edges (i, j) by flow: (1, 45) first, then (0, 40) and (0, 41): none within nms=1 of a kept
# edge's (i, j) in i at the same j, so all three are kept, in order of flow
edges = reduce_edges(np.array([1.0, 2.0, 0.5], np.float32), np.array([0, 0, 1]), np.array([40, 41, 45]), 1000, 1)
assert edges.tolist() == [[1, 45], [0, 40], [0, 41]], edges

net = VONet()
state = torch.load(build / record["weights_file"], map_location="cpu", weights_only=True)
net.load_state_dict({k.replace("module.", ""): v for k, v in state.items() if "update.lmbda" not in k})  # as DPVO
print(
    f"dpvo image: torch {torch.__version__} (CUDA {torch.version.cuda}), extensions for {record['arch']}, "
    f"network: {record['weights']}"
)
