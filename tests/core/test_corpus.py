"""The part corpus: closed, seeded, every family, CAD-style STL export."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from asmteach.core.corpus import FAMILIES, corpus_part, part_corpus, write_cad_stl


@pytest.fixture(scope="module")
def corpus():
    return part_corpus(seed=0)


def test_corpus_has_every_family_and_at_least_40_closed_parts(corpus):
    assert len(corpus) >= 40
    assert {p.family for p in corpus} == set(FAMILIES)
    assert len({p.name for p in corpus}) == len(corpus)
    for p in corpus:
        assert p.mesh.is_watertight and p.mesh.is_volume, p.name
        assert p.mesh.volume > 0, p.name
        assert 0.004 < float(np.max(p.mesh.extents)) < 0.15, p.name


def test_seed_draws_the_sizes_and_a_part_is_the_same_alone_or_in_the_corpus(corpus):
    again = corpus_part("tube_1", seed=0)
    first = next(p for p in corpus if p.name == "tube_1")
    assert np.array_equal(again.mesh.vertices, first.mesh.vertices)
    other = corpus_part("tube_1", seed=1)
    assert not np.allclose(other.mesh.extents, first.mesh.extents)


def test_holes_and_windows_are_cut(corpus):
    by = {p.name: p for p in corpus}
    wheel = by["wheel_0"].mesh
    # hub bore and spoke windows: genus > 0 and much less volume than the disc
    assert wheel.euler_number < 2
    disc = np.pi * (wheel.extents[0] / 2) ** 2 * wheel.extents[2]
    assert wheel.volume < 0.8 * disc
    assert by["tube_0"].mesh.euler_number == 0


def test_unknown_part_names_the_families():
    with pytest.raises(ValueError, match="families"):
        corpus_part("sprocket_0")


def test_cad_stl_is_in_millimetres_with_open_edges(tmp_path, corpus):
    part = corpus[0]
    path = write_cad_stl(part.mesh, tmp_path / "p.stl", open_faces=3, seed=4)
    loaded = trimesh.load(path, force="mesh")
    assert np.allclose(loaded.extents, part.mesh.extents * 1000, rtol=1e-4)
    assert not loaded.is_watertight
    assert len(loaded.faces) == len(part.mesh.faces) - 3
