"""The size rule of an ingested mesh (`corn-drake objects --source MESHDIR`), said on screen for
every mesh and recorded in its manifest entry ("scale"): its size as the file gives it, the unit
read from it (ingest.detect_unit), and the scale the library applied. By default every mesh is
rescaled to a radius drawn from the library's range (process.ProcessConfig.radius, the authors'
5-10 cm); `--keep-size` keeps its real size where that fits keep_size_radius, and refuses a mesh
that does not, saying why.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import trimesh

from corn_drake.assets.ingest import TABLETOP_ACROSS, Rejected, detect_unit
from corn_drake.assets.processing.process import ProcessConfig


@dataclasses.dataclass
class SizeRule:
    extents: tuple[float, float, float]  # the bounding box's sides, in the file's numbers
    unit: str  # the unit read (metres, millimetres, centimetres)
    metres_per_unit: float
    how: str  # how the unit was read
    radius_m: float  # its real radius in that unit (m, largest distance from the centre of mass)
    keep_size: bool

    def record(self, final_radius: float) -> dict:
        """The manifest entry's "scale" (the scale factor from the file's numbers to the
        library's metres)."""
        return {"size_in_file": [round(e, 6) for e in self.extents], "unit": self.unit,
                "unit_from": self.how, "real_radius_m": round(self.radius_m, 6),
                "radius_m": round(final_radius, 6), "kept_size": self.keep_size,
                "scale": final_radius / self.radius_m * self.metres_per_unit}

    def warning(self) -> str | None:
        """The manifest warning of a mesh not in metres or of no tabletop size, else None."""
        across = max(self.extents) * self.metres_per_unit
        lo, hi = TABLETOP_ACROSS
        if self.unit == "metres" and lo <= across <= hi:
            return None
        what = ("kept at that size" if self.keep_size
                else "rescaled to the library's radius range")
        return (f"size {max(self.extents):.4g} across in the file: read as {self.unit} "
                f"({across:.3g} m, {self.how}); {what}")

    def line(self, object_id: str, source: str, final_radius: float, cfg: ProcessConfig) -> str:
        """The rule as one line on screen."""
        sides = " x ".join(f"{e:.4g}" for e in self.extents)
        real = self.radius_m
        head = (f"{object_id} ({source}): {sides} in the file, read as {self.unit} ({self.how}): "
                f"real radius {_cm(real)}")
        if self.keep_size:
            return f"{head}; kept at its real size (--keep-size)"
        lo, hi = cfg.radius
        return (f"{head}; rescaled x{final_radius / real:.3g} to radius {_cm(final_radius)} (the "
                f"library's {_cm(lo, False)}-{_cm(hi)} range; --keep-size keeps real sizes "
                f"of {_cm(cfg.keep_size_radius[0], False)}-{_cm(cfg.keep_size_radius[1])})")


def _cm(metres: float, unit: bool = True) -> str:
    return f"{metres * 100:.3g}" + (" cm" if unit else "")


def size_rule(mesh: trimesh.Trimesh, suffix: str, cfg: ProcessConfig
              ) -> tuple[trimesh.Trimesh, SizeRule]:
    """(the mesh to process, its size rule): with cfg.keep_size the mesh in metres, or Rejected
    naming its real size and the range it misses; without it the mesh as loaded (the library
    rescales it whatever its unit)."""
    extents = np.ptp(mesh.vertices, axis=0)
    unit, per_unit, how = detect_unit(float(extents.max()), suffix, cfg.unit)
    radius = float(np.linalg.norm(mesh.vertices - mesh.center_mass, axis=1).max())
    rule = SizeRule(tuple(float(e) for e in extents), unit, per_unit, how, radius * per_unit,
                    cfg.keep_size)
    if not cfg.keep_size:
        return mesh, rule
    lo, hi = cfg.keep_size_radius
    if not lo <= rule.radius_m <= hi:
        why = (f"smaller than the gripper's {_cm(lo)} finger pads and the table's contact "
               "resolution" if rule.radius_m < lo else
               f"larger than the paper's largest objects ({_cm(2 * hi)} across), which already "
               "cover most of the 0.4 x 0.5 m table")
        raise Rejected(f"--keep-size: its real radius {_cm(rule.radius_m)} (read as {unit}, "
                       f"{how}) is outside {_cm(lo, False)}-{_cm(hi)}: {why}; leave --keep-size "
                       "out to rescale it, or scale the file")
    mesh = mesh.copy()
    mesh.apply_scale(per_unit)
    return mesh, rule
