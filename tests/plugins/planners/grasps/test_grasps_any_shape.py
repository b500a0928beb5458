"""Grasps on round, curved and thin parts (the soft-pad contact model), and the reasons when there are none.

Fixtures are made in code with trimesh (metres) and the test hand of ``conftest.py`` (20 x 30 mm pads,
85 mm stroke). The contact model is checked against closed forms (a soft pad on a sphere touches a disc,
on a cylinder a strip), the planned grasps of a wheel, a tube and a free-form blob in PyBullet.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from asmteach.core.errors import UserError
from asmteach.core.interfaces import PartModel
from asmteach.core.models import HandSpec, PartSpec
from asmteach.core.parts import mesh_hash
from asmteach.plugins.planners.grasps.contact import load_ratio, pad_contacts, pad_strip
from asmteach.plugins.planners.grasps.hold_check import HoldSimulator
from asmteach.plugins.planners.grasps.planner import AntipodalGraspPlanner
from asmteach.plugins.planners.grasps.sampling import Raycaster


def _part(mesh: trimesh.Trimesh, name: str, density: float = 700.0) -> PartModel:
    return PartModel(
        spec=PartSpec(name=name, mesh=f"{name}.stl"),
        mesh=mesh,
        mass=float(density * mesh.volume),
        center_of_mass=np.asarray(mesh.center_mass, dtype=float),
        source_hash=mesh_hash(mesh),
    )


def _wheel() -> trimesh.Trimesh:
    """A 60 mm disc, 10 mm thick, with a 10 mm bore and four 14 mm spoke windows."""
    cuts = [trimesh.creation.cylinder(radius=0.005, height=0.03, sections=24)]
    for k in range(4):
        a = k * np.pi / 2 + np.pi / 4
        w = trimesh.creation.cylinder(radius=0.007, height=0.03, sections=24)
        w.apply_translation([0.017 * np.cos(a), 0.017 * np.sin(a), 0.0])
        cuts.append(w)
    disc = trimesh.creation.cylinder(radius=0.030, height=0.010, sections=48)
    return disc.difference(trimesh.boolean.union(cuts))


def _tube() -> trimesh.Trimesh:
    """A 24 mm tube, 2.5 mm wall, 90 mm long."""
    outer = trimesh.creation.cylinder(radius=0.012, height=0.090, sections=48)
    inner = trimesh.creation.cylinder(radius=0.0095, height=0.100, sections=48)
    return outer.difference(inner)


def _blob() -> trimesh.Trimesh:
    """A free-form convex blob: an ellipsoid 44 x 36 x 30 mm, no planar face anywhere."""
    m = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    m.apply_scale([0.022, 0.018, 0.015])
    return m


def _planner(**settings) -> AntipodalGraspPlanner:
    return AntipodalGraspPlanner({"cache": False, **settings}, seed=0)


def _spread(n: int, k: int) -> list[int]:
    return sorted({int(i) for i in np.linspace(0, n - 1, k)})


# ------------------------------------------------------------------ the contact model, against closed forms
def _one_candidate(mesh: trimesh.Trimesh, p0, p1, x, hand: HandSpec, grid=(21, 31), compliance=0.0015):
    y = np.asarray(p1, float) - np.asarray(p0, float)
    y /= np.linalg.norm(y)
    x = np.asarray(x, float)
    R = np.stack([x, y, np.cross(x, y)], axis=1)[None]
    strip = pad_strip(hand, *grid, inset=0.0, set_backs=False)
    return pad_contacts(
        Raycaster(mesh),
        strip,
        np.array([p0], float),
        np.array([p1], float),
        R,
        np.zeros(1, int),
        compliance,
        compliance + 0.002,
        spacing=0.0005,
    )


def test_soft_pad_on_sphere_touches_a_disc(hand) -> None:
    """Radius 20 mm, compliance 1.5 mm: a disc of radius a = sqrt(2 r c - c^2) = 7.6 mm under each pad,
    pressed about like a paraboloid (Winkler foam), whose torsion radius is 8 a / 15."""
    r, c = 0.020, 0.0015
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=r)
    pc = _one_candidate(sphere, [0, -r, 0], [0, r, 0], [1, 0, 0], hand, compliance=c)
    a = np.sqrt(2 * r * c - c * c)
    assert not pc.protrusion[0, 0]
    # share of the pad's 21 x 31 sample points inside the disc
    gx, gz = np.meshgrid(np.linspace(-0.010, 0.010, 21), np.linspace(-0.015, 0.015, 31))
    assert pc.share[0, 0] == pytest.approx(np.mean(np.hypot(gx, gz) <= a), rel=0.05)
    np.testing.assert_allclose(pc.torsion_radius[0, 0], 8 * a / 15, rtol=0.08)


def test_soft_pad_on_cylinder_touches_a_strip(hand) -> None:
    """A 15 mm radius cylinder along the pad's long side: a strip 2 sqrt(2 r c - c^2) = 13.1 mm wide, the pad
    long; across it, the same strip the pad's width long (the pad's ends, 15 mm off the contact, graze the
    cylinder's silhouette: no contact there, and no protrusion)."""
    r, c = 0.015, 0.0015
    cyl = trimesh.creation.cylinder(radius=r, height=0.1, sections=256)
    # cylinder axis z, grasp axis y, pad long side (TCP z) along the cylinder axis
    pc = _one_candidate(cyl, [0, -r, 0], [0, r, 0], [1, 0, 0], hand, compliance=c)
    width = 2 * np.sqrt(2 * r * c - c * c)
    assert not pc.protrusion[0, 0]
    assert pc.share[0, 0] == pytest.approx(width / 0.020, rel=0.08)
    # across the cylinder instead (pad long side around it): the strip is 20 mm long, the pad's width
    pc = _one_candidate(cyl, [0, -r, 0], [0, r, 0], [0, 0, 1], hand, compliance=c)
    assert not pc.protrusion[0, 0]
    assert pc.share[0, 0] == pytest.approx(width / 0.030, rel=0.08)


def test_protrusion_under_the_pad_is_refused(hand) -> None:
    """A block with a 3 mm rib beside the contact: more than the 1.5 mm compliance in front of the pad."""
    base = trimesh.creation.box([0.04, 0.04, 0.04])
    rib = trimesh.creation.box([0.004, 0.003, 0.04])
    rib.apply_translation([0.008, -0.0215, 0.0])
    part = trimesh.boolean.union([base, rib])
    pc = _one_candidate(part, [0, -0.02, 0], [0, 0.02, 0], [1, 0, 0], hand, grid=(9, 13))
    assert pc.protrusion[0, 0]
    shallow = trimesh.creation.box([0.004, 0.001, 0.04])  # 1 mm proud: within the compliance
    shallow.apply_translation([0.008, -0.0205, 0.0])
    pc = _one_candidate(
        trimesh.boolean.union([base, shallow]), [0, -0.02, 0], [0, 0.02, 0], [1, 0, 0], hand, grid=(9, 13)
    )
    assert not pc.protrusion[0, 0]


def test_load_ratio_soft_finger() -> None:
    """Weight only (centre of mass on the axis): m g / (2 mu F); a point contact cannot bear a moment."""
    assert load_ratio(1.0, 40.0, 0.3, np.array(0.0), np.array([0.0, 0.0])) == pytest.approx(9.81 / 24.0)
    assert np.isinf(load_ratio(0.1, 40.0, 0.3, np.array(0.01), np.array([0.0, 0.0])))
    both = load_ratio(0.1, 40.0, 0.3, np.array(0.02), np.array([0.004, 0.004]))
    assert both == pytest.approx(np.hypot(0.981 / 24.0, 0.981 * 0.02 / (12.0 * 0.008)))


# ------------------------------------------------------------------ planned grasps that hold
@pytest.mark.slow
@pytest.mark.parametrize(("make", "name", "trials"), [(_wheel, "wheel", 4), (_tube, "tube", 4), (_blob, "blob", 4)])
def test_round_parts_get_grasps_that_hold(make, name, trials, hand) -> None:
    part = _part(make(), name)
    planner = _planner()
    grasps = planner.plan(part, hand)
    assert len(grasps) >= 30, planner.last_stats
    with HoldSimulator(hand, part, friction=0.5) as sim:
        results = [sim.check(grasps[i]) for i in _spread(len(grasps), trials)]
    # The best grasp holds, and so do all but at most one of the spread down to the worst-ranked (over the
    # corpus 93-100 % of the tried grasps hold per part; the misses are low-ranked grasps that hold the part
    # near a fingertip edge, where the simulator's rigid 1 mm pads lose it).
    assert results[0].held, results[0]
    assert sum(r.held for r in results) >= trials - 1, results
    if name == "tube":
        # grasped across its diameter (the bore under no finger), never across the 2.5 mm wall alone
        assert all(g.width > 0.02 for g in grasps)
        # and the old rule (half of each pad on the surface) would have found none: contacts are lines
        assert planner.last_stats["contact_share_median"] < 0.5


# ------------------------------------------------------------------ reasons for no grasp
def test_too_wide_names_its_width_and_the_stroke(hand) -> None:
    with pytest.raises(UserError, match=r"too wide.*smallest width is 90\.0 mm.*opens 85\.0 mm"):
        _planner().plan(_part(trimesh.creation.box([0.12, 0.10, 0.09]), "crate"), hand)


def test_cone_has_no_opposing_surfaces(hand) -> None:
    """A 30 deg cone: its side faces tilt 30 deg off any jaw axis across them, beyond the 16.7 deg cone of
    mu = 0.3, and its base faces only the side; a parallel jaw squeezes it out."""
    cone = trimesh.creation.cone(radius=0.020, height=0.020 / np.tan(np.radians(30.0)), sections=64)
    with pytest.raises(UserError, match=r"no opposing surfaces.*friction cone \(16\.7 deg for mu=0\.3\)"):
        _planner().plan(_part(cone, "cone"), hand)


def test_too_small_part(hand) -> None:
    with pytest.raises(UserError, match=r"too small: at most 1\.\d\d mm across.*under the 2\.00 mm"):
        _planner().plan(_part(trimesh.creation.icosphere(subdivisions=2, radius=0.00075), "bead"), hand)


def test_too_heavy_part(hand) -> None:
    """A 40 mm cube of 2 kg: 2 x 0.3 x 40 N of friction bears 24 N, under 1.5 x 19.6 N."""
    cube = trimesh.creation.box([0.04, 0.04, 0.04])
    with pytest.raises(UserError, match=r"too heavy for the hand: 2 kg"):
        _planner().plan(_part(cube, "anvil", density=2.0 / cube.volume), hand)
    # with the check off (hold_safety 0) it is planned
    assert _planner(hold_safety=0.0, max_grasps=20).plan(_part(cube, "anvil", density=2.0 / cube.volume), hand)
