"""The image's check, run at build time without a GPU: lietorch's and DROID-SLAM's compiled extensions and DROID's
modules import (headless: no matplotlib, scipy, open3d), the network loads into DroidNet as Droid.load_weights does,
and lietorch's SE3 on the CPU keeps the convention slamrun's process relies on (data [tx ty tz qx qy qz qw]; inv() of a
world-to-camera pose is the camera's pose in the world). Nothing touches CUDA.
usage: python3 check_image.py [BUILD_DIR]    (default /opt/droid_slam)"""

import json
import sys
from collections import OrderedDict
from pathlib import Path

import torch  # first: the extensions link against its libraries

build = Path(sys.argv[1] if len(sys.argv) > 1 else "/opt/droid_slam")
record = json.loads((build / "build.json").read_text())
tree = build / record["tree"]
sys.path[:0] = [str(tree / "thirdparty" / "lietorch"), str(tree / "droid_slam"), str(tree)]

import droid_backends  # noqa: E402, F401
import lietorch  # noqa: E402
import lietorch_backends  # noqa: E402, F401
from droid import Droid  # noqa: E402, F401
from droid_net import DroidNet  # noqa: E402

net = DroidNet()
state = torch.load(build / record["weights_file"], map_location="cpu", weights_only=True)
state = OrderedDict((k.replace("module.", ""), v) for k, v in state.items())
for key in ("update.weight.2.weight", "update.weight.2.bias", "update.delta.2.weight", "update.delta.2.bias"):
    state[key] = state[key][:2]  # as Droid.load_weights
net.load_state_dict(state)

# a camera at (1, 2, 3) turned 90 degrees about z: world-to-camera is R^T, -R^T c; lietorch's inverse gives c and R
half = 0.5**0.5
w2c = torch.tensor([[-2.0, 1.0, -3.0, 0.0, 0.0, -half, half]], dtype=torch.float64)
c2w = lietorch.SE3(w2c).inv().data[0]
expected = torch.tensor([1.0, 2.0, 3.0, 0.0, 0.0, half, half], dtype=torch.float64)
assert torch.allclose(c2w, expected, atol=1e-9), f"lietorch SE3 inverse: {c2w.tolist()}, expected {expected.tolist()}"
print(
    f"droid_slam image: torch {torch.__version__} (CUDA {torch.version.cuda}), extensions for {record['arch']}, "
    f"network: {record['weights']}"
)
