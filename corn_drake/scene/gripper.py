"""The closed Panda hand's collision boxes, read from models/franka_panda/panda.urdf.

One function serves every user of the gripper geometry (contact labels, segmentation,
visualisation), so the boxes the simulator collides with are the boxes the contact dataset
labels against. Pure numpy + XML: no Drake import, so torch-side code can use it cheaply.
"""

from __future__ import annotations

import dataclasses
import functools
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from corn_drake import MODELS_DIR

PANDA_URDF = MODELS_DIR / "franka_panda" / "panda.urdf"
TOOL_FRAME = "panda_tool"
# Links whose collision boxes make up the gripper (palm and the two closed finger pads).
GRIPPER_LINKS = ("panda_hand", "panda_leftfinger", "panda_rightfinger")


@dataclasses.dataclass(frozen=True)
class GripperBox:
    name: str
    half_extents: np.ndarray  # (3,)
    X_TB: np.ndarray  # (4, 4): pose of the box centre in the panda_tool frame


def _origin_to_matrix(origin: ET.Element | None) -> np.ndarray:
    X = np.eye(4)
    if origin is None:
        return X
    xyz = np.array([float(v) for v in origin.get("xyz", "0 0 0").split()])
    r, p, y = (float(v) for v in origin.get("rpy", "0 0 0").split())
    # URDF rpy: fixed-axis roll about x, then pitch about y, then yaw about z: R = Rz Ry Rx.
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    X[:3, :3] = Rz @ Ry @ Rx
    X[:3, 3] = xyz
    return X


def _pose_in_hand(root: ET.Element, link: str) -> np.ndarray:
    """Pose of `link` in panda_hand, following fixed joints up to the hand."""
    X = np.eye(4)
    while link != "panda_hand":
        joint = next((j for j in root.iter("joint") if j.find("child").get("link") == link), None)
        if joint is None or joint.get("type") != "fixed":
            raise ValueError(f"{PANDA_URDF}: {link} is not fixed to panda_hand")
        X = _origin_to_matrix(joint.find("origin")) @ X
        link = joint.find("parent").get("link")
    return X


@functools.lru_cache(maxsize=None)
def _gripper_boxes_cached(urdf_path: str) -> tuple[GripperBox, ...]:
    root = ET.parse(urdf_path).getroot()
    X_HT = _pose_in_hand(root, TOOL_FRAME)
    X_TH = np.linalg.inv(X_HT)
    boxes = []
    for link_el in root.iter("link"):
        name = link_el.get("name")
        if name not in GRIPPER_LINKS:
            continue
        X_HL = _pose_in_hand(root, name)
        for col in link_el.iter("collision"):
            box = col.find("geometry/box")
            if box is None:
                raise ValueError(f"{urdf_path}: gripper collision {col.get('name')} is not a box")
            size = np.array([float(v) for v in box.get("size").split()])
            X_LB = _origin_to_matrix(col.find("origin"))
            boxes.append(GripperBox(col.get("name"), size / 2.0, X_TH @ X_HL @ X_LB))
    if len(boxes) != 3:
        raise ValueError(f"{urdf_path}: expected palm + 2 finger boxes, found {len(boxes)}")
    return tuple(boxes)


def gripper_boxes(urdf_path: str | Path = PANDA_URDF) -> list[GripperBox]:
    """The gripper's collision boxes (palm, left pad, right pad) in the panda_tool frame."""
    return list(_gripper_boxes_cached(str(urdf_path)))
