"""Contact pairs on a closed mesh: surface samples and the opposite contact by ray casting.

All coordinates are in the part frame, metres. A *contact pair* is a point
``p0`` on the surface with outward normal ``n0`` and the point ``p1`` where a
ray from ``p0`` along ``-n0`` leaves the part again (outward normal ``n1``);
the segment ``p0 -> p1`` lies inside the material, so a parallel jaw closing
along it squeezes solid part. Ray casting uses Open3D's ``RaycastingScene``
(Embree), which answers about a million rays in tens of milliseconds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
import trimesh

__all__ = ["ContactPairs", "Raycaster", "SurfaceSamples", "find_opposite_contacts", "sample_surface"]

# Rays start this far inside the surface, so they do not hit their own face.
_START_INSET = 1e-6


class Raycaster:
    """First-hit ray queries against one mesh (part frame, metres)."""

    def __init__(self, mesh: trimesh.Trimesh) -> None:
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(
            o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
            o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)),
        )

    def cast(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cast rays; returns ``(t, normals, face_ids)``.

        ``origins``, ``directions``: ``(n, 3)``; directions must be unit length
        so ``t`` is a distance in metres (``inf`` where nothing is hit).
        ``normals`` are the hit triangles' normals, ``(n, 3)``; ``face_ids`` are
        ``-1`` for misses.
        """
        rays = np.concatenate([origins, directions], axis=1).astype(np.float32)
        if len(rays) == 0:
            return np.zeros(0), np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
        hit = self.scene.cast_rays(o3d.core.Tensor(rays))
        t = hit["t_hit"].numpy().astype(float)
        normals = hit["primitive_normals"].numpy().astype(float)
        ids = hit["primitive_ids"].numpy().astype(np.int64)
        miss = ~np.isfinite(t)
        ids[miss] = -1
        return t, normals, ids

    def inside(self, points: np.ndarray) -> np.ndarray:
        """``(n,)`` bool: the points lie inside the closed mesh (ray parity, majority of 3 rays)."""
        if len(points) == 0:
            return np.zeros(0, dtype=bool)
        q = o3d.core.Tensor(np.asarray(points, dtype=np.float32))
        return self.scene.compute_occupancy(q, nsamples=3).numpy() > 0.5

    def closest(self, points: np.ndarray) -> np.ndarray:
        """Closest surface points to ``(n, 3)`` query points."""
        q = o3d.core.Tensor(np.asarray(points, dtype=np.float32))
        return self.scene.compute_closest_points(q)["points"].numpy().astype(float)


@dataclass
class SurfaceSamples:
    """Points on the surface with outward unit normals; ``from_facet`` marks facet centres."""

    points: np.ndarray
    normals: np.ndarray
    face_ids: np.ndarray
    from_facet: np.ndarray


@dataclass
class ContactPairs:
    """Candidate contact pairs (part frame, metres): ``width = |p1 - p0|``."""

    p0: np.ndarray
    n0: np.ndarray
    p1: np.ndarray
    n1: np.ndarray
    width: np.ndarray
    from_facet: np.ndarray

    def __len__(self) -> int:
        return len(self.width)

    def subset(self, mask: np.ndarray) -> ContactPairs:
        """The pairs where ``mask`` (bool or index array) selects."""
        return ContactPairs(
            self.p0[mask], self.n0[mask], self.p1[mask], self.n1[mask], self.width[mask], self.from_facet[mask]
        )


def sample_surface(
    mesh: trimesh.Trimesh,
    count: int,
    rng: np.random.Generator,
    *,
    facet_centres: bool = True,
    raycaster: Raycaster | None = None,
) -> SurfaceSamples:
    """Area-weighted surface samples plus the centres of planar facets.

    Parameters
    ----------
    mesh : closed triangle mesh, part frame, metres.
    count : number of area-weighted samples.
    rng : source of every random choice.
    facet_centres : also add one point per planar facet (a group of coplanar
        adjacent faces): the facet's area-weighted centroid, kept only when it
        lies on the facet (a centroid of an L-shaped face may not).
    """
    areas = np.asarray(mesh.area_faces, dtype=float)
    total = float(areas.sum())
    prob = areas / total
    face_ids = rng.choice(len(areas), size=count, p=prob)
    tri = np.asarray(mesh.triangles)[face_ids]
    # Uniform barycentric coordinates (reflect the unit square into the triangle).
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1.0
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    pts = tri[:, 0] + u[:, None] * (tri[:, 1] - tri[:, 0]) + v[:, None] * (tri[:, 2] - tri[:, 0])
    normals = np.asarray(mesh.face_normals)[face_ids]
    from_facet = np.zeros(count, dtype=bool)
    if facet_centres and len(mesh.facets):
        c_pts, c_nrm, c_ids = _facet_centres(mesh, raycaster or Raycaster(mesh))
        pts = np.concatenate([pts, c_pts])
        normals = np.concatenate([normals, c_nrm])
        face_ids = np.concatenate([face_ids, c_ids])
        from_facet = np.concatenate([from_facet, np.ones(len(c_ids), dtype=bool)])
    return SurfaceSamples(pts, normals, face_ids, from_facet)


def _facet_centres(mesh: trimesh.Trimesh, raycaster: Raycaster) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    centres, normals, ids = [], [], []
    areas = mesh.area_faces
    tri_centres = mesh.triangles_center
    for facet, normal in zip(mesh.facets, mesh.facets_normal, strict=True):
        w = areas[facet]
        c = (tri_centres[facet] * w[:, None]).sum(0) / w.sum()
        centres.append(c)
        normals.append(normal)
        ids.append(facet[int(np.argmax(w))])
    c = np.asarray(centres)
    on_surface = np.linalg.norm(raycaster.closest(c) - c, axis=1) < 1e-6
    return c[on_surface], np.asarray(normals)[on_surface], np.asarray(ids)[on_surface]


def find_opposite_contacts(
    samples: SurfaceSamples, raycaster: Raycaster, *, across: bool = True, max_crossings: int = 8
) -> tuple[ContactPairs, np.ndarray]:
    """Cast from each sample through the part along ``-normal``; the exit point is ``p1``.

    Returns the pairs whose ray left the part through a face facing away from
    the ray origin (a proper exit), and the ``(n,)`` array of all through-part
    distances to that first exit (``inf`` where the ray found no exit: open
    meshes, flipped normals), the wall thickness at each sample.

    With ``across``, a ray that enters the part again after its first exit (a
    tube's bore, a wheel's spoke window) is followed to its last exit, up to
    ``max_crossings`` more crossings, and that pair is added too: a jaw closing
    from outside meets the part's outermost surfaces, so a tube is grasped
    across its diameter, not only across its wall (which would put a finger in
    the bore).
    """
    d = -samples.normals
    origins = samples.points + _START_INSET * d
    t, n1, _ = raycaster.cast(origins, d)
    exits = np.isfinite(t) & (np.einsum("ij,ij->i", n1, d) > 0.0)
    width = np.where(exits, t + _START_INSET, np.inf)
    p1 = origins + t[:, None] * d
    pairs = ContactPairs(samples.points, samples.normals, p1, n1, width, samples.from_facet).subset(exits)
    if not across:
        return pairs, width
    last_p, last_n = p1.copy(), n1.copy()
    far = np.zeros(len(d), dtype=bool)
    active = np.flatnonzero(exits)
    for _ in range(max_crossings):
        if len(active) == 0:
            break
        # From the last exit: the next entry, if any, then its exit.
        o = last_p[active] + _START_INSET * d[active]
        t_in, n_in, _ = raycaster.cast(o, d[active])
        entry = np.isfinite(t_in) & (np.einsum("ij,ij->i", n_in, d[active]) < 0.0)
        active, o, t_in = active[entry], o[entry], t_in[entry]
        if len(active) == 0:
            break
        q = o + (t_in + _START_INSET)[:, None] * d[active]
        t_out, n_out, _ = raycaster.cast(q, d[active])
        ok = np.isfinite(t_out) & (np.einsum("ij,ij->i", n_out, d[active]) > 0.0)
        active, q, t_out, n_out = active[ok], q[ok], t_out[ok], n_out[ok]
        last_p[active] = q + t_out[:, None] * d[active]
        last_n[active] = n_out
        far[active] = True
    if np.any(far):
        w = np.linalg.norm(last_p[far] - samples.points[far], axis=1)
        extra = ContactPairs(
            samples.points[far], samples.normals[far], last_p[far], last_n[far], w, samples.from_facet[far]
        )
        pairs = ContactPairs(
            *(
                np.concatenate([getattr(pairs, f), getattr(extra, f)])
                for f in ("p0", "n0", "p1", "n1", "width", "from_facet")
            )
        )
    return pairs, width
