"""The image's check, run at build time without a GPU: DPVO's compiled extensions and package import, and the
network loads into VONet. Nothing touches CUDA (dpvo.dpvo, which builds a CUDA tensor at import, is not imported).
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
from dpvo.net import VONet  # noqa: E402

net = VONet()
state = torch.load(build / record["weights_file"], map_location="cpu", weights_only=True)
net.load_state_dict({k.replace("module.", ""): v for k, v in state.items() if "update.lmbda" not in k})  # as DPVO
print(
    f"dpvo image: torch {torch.__version__} (CUDA {torch.version.cuda}), extensions for {record['arch']}, "
    f"network: {record['weights']}"
)
