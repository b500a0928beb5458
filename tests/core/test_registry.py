"""Discovery through entry points, with a third-party distribution made on disk."""

import pytest

from asmteach.core import registry
from asmteach.core.errors import UserError
from asmteach.core.interfaces import ROLES, Detector


def test_third_party_plugins_are_discovered_with_distribution(toy_dist):
    infos = {(i.role, i.name): i for i in registry.discover()}
    toy = infos[("detectors", "toy_detector")]
    assert toy.distribution == "toy-asmteach-plugin"
    assert toy.version == "1.2.3"
    assert toy.error is None and issubclass(toy.cls, Detector)
    for role in ROLES:
        assert any(i.role == role and i.distribution == "toy-asmteach-plugin" for i in infos.values())


def test_broken_plugin_is_reported_by_name_and_others_keep_working(toy_dist):
    infos = {i.name: i for i in registry.discover("detectors")}
    assert "toy plugin is broken on purpose" in infos["broken_detector"].error
    plugin = registry.create("detectors", "toy_detector", {"voxel_size": 0.01}, seed=4)
    assert plugin.settings.voxel_size == 0.01 and plugin.seed == 4


def test_builtins_are_registered_like_third_party_ones():
    names = {(i.role, i.name) for i in registry.discover(load=False)}
    for expected in [
        ("teachers", "aruco"),
        ("detectors", "cvfh_icp"),
        ("detectors", "fpfh_ransac"),
        ("correctors", "stable_placements"),
        ("grasp_planners", "antipodal"),
        ("motion_planners", "trrt"),
        ("motion_planners", "rrtconnect"),
        ("robots", "nextage_pybullet"),
        ("robots", "urdf_arm"),
    ]:
        assert expected in names


def test_unknown_name_suggests_closest(toy_dist):
    with pytest.raises(UserError, match="did you mean 'toy_detector'"):
        registry.get_class("detectors", "toy_detectr")


def test_broken_plugin_fails_with_one_line(toy_dist):
    with pytest.raises(UserError, match=r"broken_detector.*failed to import: ImportError"):
        registry.get_class("detectors", "broken_detector")


def test_settings_are_validated_by_the_plugin_model(toy_dist):
    with pytest.raises(UserError, match=r"detectors.toy_detector.settings.voxel_size: Input should be greater than 0"):
        registry.create("detectors", "toy_detector", {"voxel_size": -1})


def test_plugin_rng_follows_seed(toy_dist):
    a = registry.create("detectors", "toy_detector", seed=5).rng(1).random(3)
    b = registry.create("detectors", "toy_detector", seed=5).rng(1).random(3)
    c = registry.create("detectors", "toy_detector", seed=6).rng(1).random(3)
    assert (a == b).all() and not (a == c).all()
