"""An untrained stand-in for dpvo.pth: DPVO's VONet with random weights from a fixed seed, its flow head scaled.

A random network's flow head gives sub-pixel updates, which DPVO's motion probe (median >= 2 px before it starts)
takes for a still camera: it would never initialise. The flow head (update.d, Linear(384, 2)) is scaled so that its
updates are a few pixels and the whole pipeline runs. Plumbing only: accuracy meaningless. Needs the compiled
extensions (imported by dpvo.net), not a GPU. Used by `slamrun native-build dpvo --standin-model` and by the image.
usage: standin_model.py DPVO_TREE OUT.pth SEED FLOW_GAIN
"""

import sys

import torch


def main(tree: str, out: str, seed: int, flow_gain: float) -> None:
    sys.path.insert(0, tree)
    torch.manual_seed(seed)
    from dpvo.net import VONet

    net = VONet()
    with torch.no_grad():
        for p in net.update.d[1].parameters():
            p.mul_(flow_gain)
    torch.save(net.state_dict(), out)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4]))
