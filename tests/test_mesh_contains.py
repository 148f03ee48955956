"""The solid-mesh inside test: compiled winding numbers against numpy and trimesh."""

from __future__ import annotations

import numpy as np


def test_compiled_winding_numbers_match_numpy_and_trimesh() -> None:
    """``mesh_contains`` (compiled) against the numpy reference of the same formula, and
    inside/outside against trimesh's ray tests, an independent method, on a torus (a mesh
    with a hole, so the bounding box or the hull would be wrong)."""
    import trimesh

    from pointplan.geometry.collision import mesh_contains, mesh_winding_reference
    from pointplan.geometry.shapes import Mesh

    torus = trimesh.creation.torus(0.05, 0.02, major_sections=48, minor_sections=24)
    mesh = Mesh(np.asarray(torus.vertices), np.asarray(torus.faces))
    rng = np.random.default_rng(0)
    points = rng.uniform([-0.08, -0.08, -0.03], [0.08, 0.08, 0.03], (3000, 3))
    from pointplan.geometry._kernels import winding_numbers_compiled

    np.testing.assert_allclose(
        winding_numbers_compiled(points, mesh.vertices[mesh.faces]), mesh_winding_reference(mesh, points), atol=1e-9
    )
    inside = mesh_contains(mesh, points)
    assert 0.1 < inside.mean() < 0.5  # both classes are well represented
    assert np.array_equal(inside, torus.contains(points))
    assert mesh_contains(mesh, np.zeros((0, 3))).shape == (0,)
