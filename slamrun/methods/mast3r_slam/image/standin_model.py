"""Untrained stand-ins for MASt3R-SLAM's three checkpoint files, from a fixed seed, with the published ones'
architecture and format: the MASt3R network (AsymmetricMASt3R, ViT-Large encoder, ViT-Base decoder, catmlp+dpt heads,
24-dim descriptors: 689 M parameters, its checkpoint {'model': state_dict, 'args': Namespace(model=<constructor>)} as
mast3r's load_model reads it), the retrieval head beside it (RetrievalModel's projector on the frozen backbone, its
checkpoint's args as mast3r/retrieval/processor.py reads them) and the retrieval codebook (asmk's Codebook state: unit
random centroids). Plumbing only: every output is meaningless, and tracking may lose the camera at once. Runs on the
CPU; needs the patched tree (no compiled extension). Used by `slamrun native-build mast3r_slam --standin-model` and by
the image. Prints what it made.
usage: standin_model.py MAST3R_SLAM_TREE OUT.pth SEED
"""

import argparse
import pickle
import sys
from pathlib import Path

import numpy as np
import torch

# the published checkpoint's constructor (its args.model), which load_model edits (PatchEmbedDust3R, landscape_only)
MODEL = (
    "AsymmetricMASt3R(enc_depth=24, dec_depth=12, enc_embed_dim=1024, dec_embed_dim=768, enc_num_heads=16, "
    "dec_num_heads=12, pos_embed='RoPE100', patch_embed_cls='ManyAR_PatchEmbed', img_size=(512, 512), "
    "head_type='catmlp+dpt', output_mode='pts3d+desc24', depth_mode=('exp', -inf, inf), conf_mode=('exp', 1, inf), "
    "two_confs=True, desc_conf_mode=('exp', 0, inf))"
)
RETRIEVAL_SUFFIX = "_retrieval_trainingfree.pth"
CODEBOOK_SUFFIX = "_retrieval_codebook.pkl"
NFEAT = 300  # local features a keyframe adds to the retrieval database
CLUSTERS = 65536  # the codebook's size (processor.py's default, '64k')
PROJECTOR = "1024"  # the retrieval projector's hidden dims (its args.hdims)


def main(tree: str, out: str, seed: int) -> None:
    sys.path[:0] = [tree, f"{tree}/thirdparty/mast3r", f"{tree}/thirdparty/mast3r/asmk"]
    import mast3r.utils.path_to_dust3r  # noqa: F401
    from mast3r.model import AsymmetricMASt3R  # noqa: F401 - named by MODEL
    from mast3r.retrieval.model import RetrievalModel

    inf = float("inf")  # noqa: F841 - named by MODEL
    torch.manual_seed(seed)
    built = MODEL.replace("ManyAR_PatchEmbed", "PatchEmbedDust3R")[:-1] + ", landscape_only=False)"
    net = eval(built)  # as mast3r's load_model builds it
    params = sum(p.numel() for p in net.parameters())
    torch.save({"model": net.state_dict(), "args": argparse.Namespace(model=MODEL)}, out)

    stem = Path(out).with_suffix("")
    args = argparse.Namespace(
        pretrained=Path(out).name, freeze_backbone=1, prewhiten=None, hdims=PROJECTOR, residual=False, postwhiten=None,
        featweights="l2norm", nfeat=NFEAT, imsize=512, nclusters=CLUSTERS,
    )  # fmt: skip
    head = RetrievalModel(
        net, freeze_backbone=1, prewhiten=None, hdims=[int(PROJECTOR)], residual=False, postwhiten=None, nfeat=NFEAT
    )
    torch.save({"model": head.state_dict(), "args": args}, f"{stem}{RETRIEVAL_SUFFIX}")

    rng = np.random.default_rng(seed)
    centroids = rng.standard_normal((CLUSTERS, int(PROJECTOR)), dtype=np.float32)
    centroids /= np.linalg.norm(centroids, axis=1, keepdims=True)
    state = {"type": "Codebook", "params": {"size": CLUSTERS}, "state": {"centroids": centroids}}
    with open(f"{stem}{CODEBOOK_SUFFIX}", "wb") as f:
        pickle.dump(state, f, protocol=4)
    print(f"{params / 1e6:.0f} M parameters; retrieval head {PROJECTOR}-dim, {NFEAT} features; codebook {CLUSTERS}")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]))
