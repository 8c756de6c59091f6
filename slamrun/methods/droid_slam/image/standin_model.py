"""An untrained stand-in for droid.pth: DROID-SLAM's DroidNet with random weights from a fixed seed, its flow head
scaled.

A random network's flow head (update.delta, its last Conv2d(128, 2)) gives sub-pixel updates, which DROID's motion
filter (mean flow above filter_thresh, 2.4 px, before a frame is kept) takes for a still camera: no keyframe would
ever be added and the system would never initialise. The head is scaled so that its mean flow on random inputs of the
update operator's shapes (drawn from the same seed) is FLOW_PX pixels, and the whole pipeline runs. Plumbing only:
accuracy meaningless. Runs on the CPU; needs the compiled extensions (droid_net imports them), not a GPU. Used by
`slamrun native-build droid_slam --standin-model` and by the image. Prints the gain it applied.
usage: standin_model.py DROID_TREE OUT.pth SEED FLOW_PX
"""

import sys

import torch


def main(tree: str, out: str, seed: int, flow_px: float) -> None:
    sys.path[:0] = [f"{tree}/thirdparty/lietorch", f"{tree}/droid_slam", tree]
    torch.manual_seed(seed)
    from droid_net import DroidNet

    net = DroidNet().eval()
    head = net.update.delta[2]  # Conv2d(128, 2, 3): the flow update, in pixels at 1/8 resolution
    ht, wd = 24, 32
    probe = torch.Generator().manual_seed(seed)
    hidden = torch.randn(1, 1, 128, ht, wd, generator=probe).tanh()
    context = torch.randn(1, 1, 128, ht, wd, generator=probe).relu()
    corr = torch.randn(1, 1, 4 * 7 * 7, ht, wd, generator=probe)
    with torch.no_grad():
        _, delta, _ = net.update(hidden, context, corr)
        gain = flow_px / delta.norm(dim=-1).mean().item()
        head.weight.mul_(gain)
        head.bias.mul_(gain)
    torch.save(net.state_dict(), out)
    print(f"flow head x{gain:.3f}")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4]))
