"""Point clouds for the pretext tasks, drawn on the fly from an object library's surface clouds.

The paper pretrained P2V-lite on ShapeNet (point2vec's data; its `p2v` row used point2vec's own
ShapeNet weights) and ROT on ShapeNet too. No dataset can be downloaded here, so both use the
object library's clouds (assets/library_clouds.py, the same reader contact data uses) placed
as contact data places them (contact/generate.ContactDataConfig): each cloud is an object scaled
to radius U(0.04, 0.12) m, turned by a uniform rotation and centred uniformly in x +-0.24,
y +-0.30, z [0.35, 0.65], then 512 of its surface samples with N(0, 4 mm) noise. The clouds are
in the world frame, where a policy's clouds are; the pretrainer normalises them as the policy's
encoder does.

Splits: "train" (the library's train objects), "val" (the same objects in other placements: the
held-out split of the training objects), "unseen" (the library's unseen objects).

The encoder also takes a hand pose (9: position + 6D rotation); the pretext tasks have no
gripper, so each cloud gets a hand pose drawn independently of it from contact data's hand
distribution (the same box, uniform rotation). It carries nothing about the cloud, so the
encoder learns to do its task whatever the hand token says, and the hand's Linear sees the
inputs policies give it rather than one constant.
"""

from __future__ import annotations

from pathlib import Path

import torch

from corn_drake.contact.generate import ContactDataConfig
from corn_drake.assets.library_clouds import load_object_clouds
from corn_drake.contract import DEFAULT_NUM_POINTS
from corn_drake.errors import InputError
from corn_drake.nn.geometry import random_rotations, rot6d

SPLITS = ("train", "val", "unseen")


class LibraryClouds:
    def __init__(self, library: str | Path, num_points: int = DEFAULT_NUM_POINTS,
                 point_noise_std: float = 0.004, placement: ContactDataConfig = ContactDataConfig()):
        objects = load_object_clouds(library)  # InputError naming the library when unusable
        self.num_points, self.point_noise_std = num_points, point_noise_std
        self.low = torch.tensor(placement.low, dtype=torch.float32)
        self.high = torch.tensor(placement.high, dtype=torch.float32)
        self.radius_range = placement.radius
        # Library clouds are random surface samples: any prefix of equal length is a fair one.
        m = min(len(o.points) for o in objects)
        if m < num_points:
            raise InputError(f"object library {library}: clouds of {m} points, the pretext "
                             f"tasks sample {num_points}")
        self.ids: dict[str, list[str]] = {}
        self.clouds: dict[str, torch.Tensor] = {}  # (objects, m, 3), scaled to unit radius
        for split in ("train", "unseen"):
            chosen = [o for o in objects if o.split == split]
            self.ids[split] = [o.id for o in chosen]
            if chosen:
                self.clouds[split] = torch.stack([torch.as_tensor(o.points[:m] / o.radius,
                                                                  dtype=torch.float32)
                                                  for o in chosen])
        if "train" not in self.clouds:
            raise InputError(f"object library {library} has no train objects")
        self.clouds["val"], self.ids["val"] = self.clouds["train"], self.ids["train"]

    def has(self, split: str) -> bool:
        return split in self.clouds

    def objects(self, split: str, n: int, g: torch.Generator) -> torch.Tensor:
        """n object surfaces of `split` (n, m, 3) in their own frame, each scaled to a random
        radius."""
        pool = self.clouds[split]
        which = torch.randint(len(pool), (n,), generator=g)
        lo, hi = self.radius_range
        radius = lo + (hi - lo) * torch.rand(n, generator=g)
        return pool[which] * radius[:, None, None]

    def place(self, surfaces: torch.Tensor, R: torch.Tensor, g: torch.Generator) -> torch.Tensor:
        """Clouds (n, num_points, 3) in the world: num_points random samples of each surface,
        turned by R (n, 3, 3) about the object origin, centred at a random workspace point,
        with point noise."""
        n, m, _ = surfaces.shape
        keep = torch.rand(n, m, generator=g).argsort(dim=1)[:, :self.num_points]
        local = torch.gather(surfaces, 1, keep.unsqueeze(-1).expand(-1, -1, 3))
        return (local @ R.transpose(1, 2) + self.positions(n, g).unsqueeze(1)
                + torch.randn(n, self.num_points, 3, generator=g) * self.point_noise_std)

    def positions(self, n: int, g: torch.Generator) -> torch.Tensor:
        return self.low + (self.high - self.low) * torch.rand(n, 3, generator=g)

    def hands(self, n: int, g: torch.Generator) -> torch.Tensor:
        """n hand states (n, 9: world position + 6D rotation), independent of any cloud."""
        return torch.cat([self.positions(n, g), rot6d(random_rotations(n, g))], dim=-1)
