"""torch_scatter's scatter_sum, scatter_mean and scatter_softmax, as DPVO and DROID-SLAM call them, on PyTorch's own
scatter operations.

Copied into DPVO's tree as dpvo/_scatter.py by slamrun/methods/dpvo/image/patches.py, and into DROID-SLAM's as droid_slam/_scatter.py
by slamrun/methods/droid_slam/image/patches.py (torch_scatter is a compiled package that PyPI serves as source only). Same signatures
and results as rusty1s/pytorch_scatter's torch_scatter/scatter.py and composite/softmax.py: the index is broadcast
along `dim` the same way, a group's maximum comes from `scatter_reduce(..., "amax", include_self=False)` instead of
the compiled scatter_max; scatter_sum and scatter_mean are pytorch_scatter's own pure-Python code paths.
"""

from __future__ import annotations

import torch


def broadcast(index: torch.Tensor, other: torch.Tensor, dim: int) -> torch.Tensor:
    """`index` (1-D along `dim`, or of `other`'s leading shape) expanded to `other`'s shape."""
    if dim < 0:
        dim = other.dim() + dim
    if index.dim() == 1:
        for _ in range(dim):
            index = index.unsqueeze(0)
    for _ in range(index.dim(), other.dim()):
        index = index.unsqueeze(-1)
    return index.expand(other.size())


def _out_size(src: torch.Tensor, index: torch.Tensor, dim: int, dim_size: int | None) -> list[int]:
    size = list(src.size())
    if dim_size is not None:
        size[dim] = dim_size
    elif index.numel() == 0:
        size[dim] = 0
    else:
        size[dim] = int(index.max()) + 1
    return size


def scatter_sum(
    src: torch.Tensor,
    index: torch.Tensor,
    dim: int = -1,
    out: torch.Tensor | None = None,
    dim_size: int | None = None,
) -> torch.Tensor:
    """out[..., index[i], ...] += src[..., i, ...] along `dim`."""
    index = broadcast(index, src, dim)
    if out is None:
        out = torch.zeros(_out_size(src, index, dim, dim_size), dtype=src.dtype, device=src.device)
    return out.scatter_add_(dim, index, src)


def scatter_mean(
    src: torch.Tensor,
    index: torch.Tensor,
    dim: int = -1,
    out: torch.Tensor | None = None,
    dim_size: int | None = None,
) -> torch.Tensor:
    """The mean of `src` within each group of equal index along `dim` (an empty group: 0, or `out`'s value / 1)."""
    out = scatter_sum(src, index, dim, out, dim_size)
    dim_size = out.size(dim)
    index_dim = dim + src.dim() if dim < 0 else dim
    if index.dim() <= index_dim:
        index_dim = index.dim() - 1
    count = scatter_sum(torch.ones(index.size(), dtype=src.dtype, device=src.device), index, index_dim, None, dim_size)
    count[count < 1] = 1
    count = broadcast(count, out, dim)
    if out.is_floating_point():
        return out.true_divide_(count)
    return out.div_(count, rounding_mode="floor")


def scatter_softmax(src: torch.Tensor, index: torch.Tensor, dim: int = -1, dim_size: int | None = None) -> torch.Tensor:
    """The softmax of `src` within each group of equal index along `dim`."""
    if not torch.is_floating_point(src):
        raise ValueError("`scatter_softmax` can only be computed over tensors with floating point data types.")
    index = broadcast(index, src, dim)
    size = _out_size(src, index, dim, dim_size)
    group_max = torch.zeros(size, dtype=src.dtype, device=src.device)
    group_max = group_max.scatter_reduce(dim, index, src, "amax", include_self=False)
    recentered = (src - group_max.gather(dim, index)).exp_()
    sums = scatter_sum(recentered, index, dim, dim_size=size[dim])
    return recentered.div(sums.gather(dim, index))
