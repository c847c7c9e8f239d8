"""Geometry of the aortic-arch phantom: centrelines, diameters, ostia (adult anatomy).

The phantom is a set of centreline paths from the access point, each sampled every
`STEP_M` with position, cumulative turning angle and curvature. Sizes are typical adult
values, rounded (the phantom of [endovascular] is a commercial arch model; its drawings are
not published):

- aortic arch: radius of curvature ~35 mm (arch width 70-80 mm, height 35-40 mm;
  Redheuil et al., JACC 2011, 58:1262, "Age-related changes in aortic arch geometry");
- diameters: descending aorta ~24 mm, arch ~27 mm (Hager et al., Z Kardiol 2002,
  91:675, "Diameters of the thoracic aorta throughout life");
- branches in order from the descending side: left subclavian (LSA, ~10 mm), left
  common carotid (LCCA, ~7 mm; Krejza et al., AJR 2006, 186:1261, "Carotid artery
  diameter in men and women"), brachiocephalic trunk (BCT, ~12 mm), their ostia
  12-18 mm apart along the arch's outer curve (Müller et al., Surg Radiol Anat 2011,
  33:885, "Branching pattern of the aortic arch");
- a straight 0.20 m run from the introducer to the arch (the phantom's descending aorta
  and access tubing), and 0.05 m of ascending aorta down to the valve (a dead end).

Coordinates: x to the patient's right... kept simple: the arch lies in the x-z plane
(frontal view), z up, the access at the origin. A branch leaves the arch's outer wall
at an azimuth `phi` about the arch's tangent (0 = superior); the angled guidewire tip
enters it when the tip's rotation points within `half_width` of that azimuth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

STEP_M = 0.001
"""Centreline sampling step."""


@dataclass(frozen=True)
class Branch:
    name: str
    code: int
    """Region code of the branch in the sample stream (see REGIONS)."""
    arch_angle_rad: float
    """Position of the ostium on the arch: 0 where the arch leaves the descending aorta,
    pi where it joins the ascending aorta."""
    phi_rad: float
    """Azimuth of the ostium about the arch's tangent (0 = superior)."""
    half_width_rad: float
    """How far the tip may point off `phi_rad` and still enter (wider for wider vessels)."""
    length_m: float
    diameter_m: float
    lean: tuple[float, float, float]
    """Direction of the branch once entered."""


@dataclass(frozen=True)
class ArchAnatomy:
    descending_length_m: float = 0.20
    arch_radius_m: float = 0.035
    ascending_length_m: float = 0.05
    aorta_diameter_m: float = 0.025
    branches: tuple[Branch, ...] = (
        Branch("left subclavian", 3, 0.30 * math.pi, 1.2, 0.50, 0.08, 0.010, (0.35, 0.3, 1.0)),
        Branch("left common carotid", 4, 0.45 * math.pi, 0.0, 0.40, 0.10, 0.007, (0.1, 0.0, 1.0)),
        Branch("brachiocephalic", 5, 0.62 * math.pi, -1.0, 0.55, 0.04, 0.012, (-0.35, -0.3, 1.0)),
    )
    target: str = "left common carotid"
    target_depth_m: float = 0.03
    """How far past its ostium the tip must be in the target branch for success."""


# geometry columns
G_X, G_Y, G_Z, G_THETA, G_KAPPA, G_REGION, G_BEND = range(7)
GEOMETRY_COLUMNS = 7
"""x, y, z (m), turning angle so far (rad), curvature (1/m), region code, and the
integral of kappa^2 ds so far (1/m; the wire's bending load along the path)."""


def _polyline(points: list[np.ndarray]) -> np.ndarray:
    return np.array(points)


def _resample(points: np.ndarray, step: float) -> np.ndarray:
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    grid = np.arange(0.0, s[-1] + 1e-12, step)
    return np.column_stack([np.interp(grid, s, points[:, k]) for k in range(3)])


def _turning(points: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Cumulative turning angle (rad) and curvature (1/m) along a resampled polyline."""
    tangents = np.gradient(points, step, axis=0)
    tangents /= np.linalg.norm(tangents, axis=1, keepdims=True)
    dots = np.clip(np.sum(tangents[1:] * tangents[:-1], axis=1), -1.0, 1.0)
    dtheta = np.concatenate([[0.0], np.arccos(dots)])
    return np.cumsum(dtheta), dtheta / step


def build_paths(anatomy: ArchAnatomy) -> tuple[np.ndarray, list[dict[str, float]]]:
    """Every path from the access point: (n_paths, n_points, GEOMETRY_COLUMNS) padded with
    the last point, and per path its end, the ostium's arc length and the branch data.

    Path 0 runs up the descending aorta, over the arch and down the ascending aorta to
    the valve; path k >= 1 leaves it at branch k's ostium.
    """
    a = anatomy
    R, step = a.arch_radius_m, STEP_M
    desc = [np.array([0.0, 0.0, z]) for z in np.linspace(0.0, a.descending_length_m, 201)]
    centre = np.array([-R, 0.0, a.descending_length_m])

    def arch_point(alpha: float) -> np.ndarray:
        return centre + R * np.array([math.cos(alpha), 0.0, math.sin(alpha)])

    alphas = np.linspace(0.0, math.pi, 361)
    arch = [arch_point(al) for al in alphas]
    end_arch = arch[-1]
    asc = [end_arch - np.array([0.0, 0.0, d]) for d in np.linspace(0.0, a.ascending_length_m, 51)]
    main = _resample(_polyline(desc + arch[1:] + asc[1:]), step)
    s_arch0 = a.descending_length_m
    s_arch1 = s_arch0 + math.pi * R
    main_region = np.where(
        np.arange(len(main)) * step < s_arch0,
        0,
        np.where(np.arange(len(main)) * step < s_arch1, 1, 2),
    )
    paths = [(main, main_region)]
    meta = [{"end": (len(main) - 1) * step, "ostium": math.inf, "phi": 0.0, "half": 0.0, "code": 2}]
    for b in a.branches:
        s_ost = s_arch0 + b.arch_angle_rad * R
        prefix = main[: round(s_ost / step) + 1]
        lean = np.array(b.lean) / np.linalg.norm(b.lean)
        # a short fillet (the ostium's rounded edge) from the arch tangent into the branch
        tangent = (prefix[-1] - prefix[-2]) / step
        tangent /= np.linalg.norm(tangent)
        fillet_r = 0.004
        pts = [prefix[-1]]
        for u in np.linspace(0.0, 1.0, 21)[1:]:
            direction = (1 - u) * tangent + u * lean
            pts.append(pts[-1] + direction / np.linalg.norm(direction) * fillet_r * 0.1)
        tail = [pts[-1] + lean * d for d in np.linspace(0.0, b.length_m, 101)[1:]]
        branch_pts = _resample(np.array(pts + tail), step)
        path = np.vstack([prefix, branch_pts[1:]])
        region = np.concatenate([main_region[: len(prefix)], np.full(len(branch_pts) - 1, b.code)])
        paths.append((path, region))
        meta.append(
            {
                "end": (len(path) - 1) * step,
                "ostium": s_ost,
                "phi": b.phi_rad,
                "half": b.half_width_rad,
                "code": b.code,
            }
        )
    n = max(len(p) for p, _ in paths)
    geometry = np.zeros((len(paths), n, GEOMETRY_COLUMNS))
    for k, (p, region) in enumerate(paths):
        theta, kappa = _turning(p, step)
        bend = np.cumsum(kappa**2) * step
        rows = np.column_stack([p, theta, kappa, region, bend])
        geometry[k, : len(p)] = rows
        geometry[k, len(p) :] = rows[-1]
    return geometry, meta
