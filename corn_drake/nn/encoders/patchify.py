"""Point-cloud patches in plain PyTorch: farthest-point centres, sorted kNN groups.

No CUDA extension (pytorch3d, torch-cluster) installs here, so FPS and kNN are written for
batched CPU tensors: FPS keeps the coordinates as three (B, N) planes and updates the running
minimum distance in place (the fastest pure-torch variant measured here); kNN is cdist + topk,
whose sorted output orders each patch's points by distance to its centre, the order the MLP
tokenizer relies on. FPS starts at index 0, so both are deterministic, and for a fixed cloud moved
rigidly the indices never change: compute them once (patch_indices) and only gather.
"""

from __future__ import annotations

import torch


def farthest_point_sample(points: torch.Tensor, num_centers: int) -> torch.Tensor:
    """Indices (B, G) of `num_centers` farthest points, starting from point 0."""
    B, N, _ = points.shape
    planes = points.permute(2, 0, 1)  # (3, B, N): contiguous per-coordinate rows
    dist = torch.full((B, N), float("inf"), dtype=points.dtype, device=points.device)
    idx = torch.zeros(B, num_centers, dtype=torch.long, device=points.device)
    far = torch.zeros(B, 1, dtype=torch.long, device=points.device)
    d = torch.empty_like(dist)
    for i in range(num_centers):
        idx[:, i] = far[:, 0]
        center = torch.gather(planes, 2, far.expand(3, B, 1))  # (3, B, 1)
        torch.sub(planes[0], center[0], out=d)
        d.mul_(d)
        d.addcmul_(planes[1] - center[1], planes[1] - center[1])
        d.addcmul_(planes[2] - center[2], planes[2] - center[2])
        torch.minimum(dist, d, out=dist)
        far = dist.argmax(dim=1, keepdim=True)
    return idx


def knn_indices(points: torch.Tensor, centers: torch.Tensor, k: int) -> torch.Tensor:
    """(B, G, k) indices of each centre's k nearest points, nearest first."""
    return torch.cdist(centers, points).topk(k, dim=-1, largest=False, sorted=True).indices


def patch_indices(points: torch.Tensor, num_patches: int = 16, patch_size: int = 32):
    """(centre indices (B, G), patch indices (B, G, k)) for a batch of clouds (B, N, 3)."""
    if points.ndim != 3 or points.shape[-1] != 3:
        raise ValueError(f"points must be (B, N, 3), got {tuple(points.shape)}")
    if points.shape[1] < max(patch_size, num_patches):
        # Fewer points than centres would make FPS repeat point 0 (every distance is then 0).
        raise ValueError(f"clouds need at least {max(patch_size, num_patches)} points "
                         f"({num_patches} patches of {patch_size}), got {points.shape[1]}")
    center_idx = farthest_point_sample(points, num_patches)
    centers = gather_points(points, center_idx)
    return center_idx, knn_indices(points, centers, patch_size)


def gather_points(points: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """points (B, N, C) gathered at idx (B, ...) -> (B, ..., C)."""
    B = points.shape[0]
    flat = idx.reshape(B, -1)
    out = torch.gather(points, 1, flat.unsqueeze(-1).expand(-1, -1, points.shape[-1]))
    return out.reshape(*idx.shape, points.shape[-1])


def group(points: torch.Tensor, center_idx: torch.Tensor, knn_idx: torch.Tensor):
    """(centres (B, G, 3), patches centred on them (B, G, k, 3))."""
    centers = gather_points(points, center_idx)
    patches = gather_points(points, knn_idx) - centers.unsqueeze(2)
    return centers, patches
