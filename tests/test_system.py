"""The radiosity system: solvers, exact answers (furnace, sphere), energy balance."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import trimesh

import radiosity
from helpers import write_obj
from radiosity.methods.uniform.system import SOLVERS, energy_balance, progressive, solve_system


def random_enclosure(n: int, seed: int = 0):
    """A random closed 'enclosure': F >= 0 with rows summing to 1 and exact reciprocity."""
    rng = np.random.default_rng(seed)
    area = rng.uniform(0.5, 2.0, n)
    G = rng.uniform(0, 1, (n, n))
    G = G + G.T
    np.fill_diagonal(G, 0)
    from radiosity.enclosure import enforce_reciprocity

    F = sp.csr_matrix(G / G.sum(axis=1, keepdims=True))
    return enforce_reciprocity(F, area, closure=True), area


@pytest.mark.parametrize("method", [m for m in SOLVERS])
def test_every_solver_matches_dense_solution(method):
    F, area = random_enclosure(40)
    rng = np.random.default_rng(1)
    rho = rng.uniform(0.1, 0.9, (40, 3))
    e = np.zeros((40, 3))
    e[:5] = rng.uniform(1, 2, (5, 3))
    b, report = solve_system(F, rho, e, area, method=method, rtol=1e-12)
    for c in range(3):
        exact = np.linalg.solve(np.eye(40) - rho[:, c, None] * F.toarray(), e[:, c])
        np.testing.assert_allclose(b[:, c], exact, rtol=1e-8, atol=1e-12)
    assert max(report.residual) < 1e-8
    assert len(report.iterations) == 3


def test_unknown_solver_is_refused_with_the_valid_names():
    F, area = random_enclosure(4)
    with pytest.raises(TypeError, match="gauss-seidel"):
        solve_system(F, np.full((4, 3), 0.5), np.ones((4, 3)), area, method="magic")


def test_furnace_on_random_enclosure():
    """Closed, uniform rho, uniform E: B = E / (1 - rho) exactly."""
    F, area = random_enclosure(30)
    for rho in (0.0, 0.5, 0.9, 0.99):
        b, _ = solve_system(F, np.full((30, 3), rho), np.ones((30, 3)), area, rtol=1e-13)
        np.testing.assert_allclose(b, 1 / (1 - rho), rtol=1e-8)


def test_progressive_refinement_reports_intermediate_results():
    F, area = random_enclosure(25)
    rho = np.full(25, 0.7)
    e = np.zeros(25)
    e[0] = 1.0
    seen = []
    b, shots = progressive(F, area, rho, e, rtol=1e-10, callback=lambda x, it: seen.append(x.sum()))
    assert seen and all(np.diff(seen) >= -1e-15)  # monotone: shooting only adds light
    exact = np.linalg.solve(np.eye(25) - rho[:, None] * F.toarray(), e)
    np.testing.assert_allclose(b, exact, rtol=1e-8)
    assert shots > 0


def test_energy_balance_holds_for_open_scene():
    F, area = random_enclosure(20)
    F = (F * 0.8).tocsr()  # 20% escapes
    rho = np.full((20, 3), 0.5)
    e = np.zeros((20, 3))
    e[3] = 1.0
    b, _ = solve_system(F, rho, e, area, rtol=1e-13)
    bal = {k: np.array(v) for k, v in energy_balance(F, area, rho, e, b).items()}
    np.testing.assert_allclose(bal["emitted"], bal["absorbed"] + bal["escaped"], rtol=1e-10)
    assert (bal["escaped"] > 0).all()


def inward_sphere(tmp_path, subdivisions: int) -> radiosity.Scene:
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions)
    path = write_obj(tmp_path / f"sphere{subdivisions}.obj", {"sphere": [t[::-1] for t in mesh.triangles]})
    return radiosity.load_scene(path)


def test_closed_sphere_matches_exact_answer_and_converges(tmp_path):
    """F_ij = A_j / A for a sphere: B_i = E_i + rho <E> / (1 - rho), approached as the mesh refines."""
    errors = []
    for sub in (1, 2):
        scene = inward_sphere(tmp_path, sub)
        e = (scene.patch_centroid[:, 2] > 0.5).astype(float)
        scene = scene.with_materials(reflectance=0.5, emission=np.repeat(e[:, None], 3, axis=1))
        sol = radiosity.solve(scene, preset="default", cache=False, max_patch_size=10.0)
        mean_e = (scene.patch_area * e).sum() / scene.patch_area.sum()
        expected = e + 0.5 * mean_e / (1 - 0.5)
        errors.append(np.abs(sol.radiosity[:, 0] - expected).max() / expected.max())
    assert errors[1] < errors[0]
    assert errors[1] < 1e-2


def test_materials_change_does_not_change_geometry_hash():
    scene = radiosity.load_scene(radiosity.bundled_scene("unit_cube"))
    recoloured = scene.with_materials(reflectance=0.3)
    assert recoloured.geometry_hash == scene.geometry_hash
    with pytest.raises(radiosity.SceneError):
        scene.with_materials(reflectance=1.0)


def closed_box_near_white(n: int = 24):
    """A random closed enclosure with rho = 0.999 everywhere: B = E / (1 - rho) = 1000."""
    F, area = random_enclosure(n, seed=3)
    return F, area, np.full((n, 3), 0.999), np.ones((n, 3))


@pytest.mark.parametrize("method", ["progressive", "jacobi"])
def test_a_solver_that_stops_at_its_cap_says_so_and_falls_back(method, monkeypatch):
    """Issue 19: progressive stopped at 50 n shots with B = 97 instead of 1000, exit 0."""
    import radiosity.methods.uniform.system as system

    F, area, rho, e = closed_box_near_white()
    if method == "jacobi":  # cap the sweeps far below what rho = 0.999 needs
        original = system._stationary
        monkeypatch.setattr(system, "_stationary",
                            lambda *a, **k: original(*a, **{**k, "maxiter": 50}))
    with pytest.warns(radiosity.RadiosityWarning, match=f"{method} stopped after .* instead"):
        b, report = solve_system(F, rho, e, area, method=method, rtol=1e-10)
    np.testing.assert_allclose(b, 1000.0, rtol=1e-7)
    assert report.fallback == ["gmres"] * 3 or report.fallback == ["direct"] * 3
    assert max(report.residual) <= 1e-8


def test_a_converged_solve_reports_no_fallback():
    F, area, rho, e = closed_box_near_white()
    b, report = solve_system(F, np.full_like(rho, 0.5), e, area, method="progressive", rtol=1e-12)
    np.testing.assert_allclose(b, 2.0, rtol=1e-8)
    assert report.fallback == [None] * 3


def test_a_system_no_solver_can_solve_is_refused(monkeypatch):
    import radiosity.methods.uniform.system as system

    F, area, rho, e = closed_box_near_white()
    monkeypatch.setattr(system, "_relative_residual", lambda A, b, x: 1.0)
    with pytest.raises(radiosity.RadiosityError, match="did not converge"):
        solve_system(F, rho, e, area, method="bicgstab")
