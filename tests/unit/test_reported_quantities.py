"""Every quantity a run reports (energies, frame fields, tracked histories) against a formula
of the other reported quantities, written here independently of pmpm's code.

One run through ``pmpm.run`` of a yielding cantilever strip (bilinear_vonmises, plane stress,
small rotations), off the origin and loaded off every symmetry: clamped at its left end, gravity
with a horizontal part, a sideways and downward force at the tip, mass-proportional damping.
Frames and energy rows are sampled at the same times, so each frame can be checked against its
energy row:

* ``kinetic`` = 1/2 sum m |v|^2; ``strain_energy`` = sum vol 1/2 sigma . S sigma with S the 3-D
  isotropic compliance (plane stress: szz = 0); ``plastic_work`` = sum vol * plastic_work;
* ``external_work`` = sum m g . (x - x0) + sum F m / M_set . (x - x0) over the force's particles
  (a set force is shared in proportion to mass; the clamp does no work): the telescoping sums
  of the work increments, exact to round-off;
* ``total`` = kinetic + internal_work + damping_work, and the balance total = external_work
  (the run starts at rest) within the issue's 2 % of the largest energy in play;
* the fields: m = density * (h / ppc)^2 * thickness, x0 the particle lattice, stress = D (strain
  - eps_p) with D the plane-stress stiffness (the stress update adds D de - D d_eps_p to the
  stress and de, d_eps_p to the strains each step: the identity holds to round-off without
  rotations), the von Mises function of sigma - back_stress at most sigma_y (bilinear return
  mapping), eps_p_eq >= sqrt(2/3) |eps_p| (a sum of increments is at least the norm of their
  sum, the tensor's zz = -(xx + yy), shear half of the engineering gxy);
* each track's ux, uy, vx, vy, sxx, syy, sxy: the frame fields of the particle it follows.
"""
import math

import numpy as np
import pytest

import pmpm

E, NU, RHO, SY, ALPHA = 2e6, 0.3, 10.0, 4e3, 0.05
H, PPC = 0.05, 2
G_VEC = np.array([1.5, -9.81])
F_TIP = np.array([-6.0, -30.0])
TIP_BOX = ([1.85, -0.55], [2.0, -0.4])
FIELDS = ["x", "x0", "v", "m", "vol", "stress", "strain", "eps_p", "eps_p_eq", "plastic_work", "back_stress", "F"]


@pytest.fixture(scope="module")
def res():
    return pmpm.run({
        "particles_per_cell": PPC, "formulation": "plane_stress",
        "grid": {"origin": [0.35, -0.9], "cell_size": H, "cells": [36, 14]},
        "materials": {"steel": {"type": "bilinear_vonmises", "E": E, "nu": NU, "density": RHO,
                                "yield_stress": SY, "hardening": ALPHA}},
        "bodies": [{"shape": "rectangle", "material": "steel", "lower": [0.4, -0.7], "upper": [2.0, -0.4]}],
        "boundary": [{"name": "clamp", "type": "fixed", "lower": [0.35, -0.9], "upper": [0.45, -0.2]}],
        "loads": {"gravity": list(G_VEC), "damping": 5.0,
                  "forces": [{"name": "tip", "lower": TIP_BOX[0], "upper": TIP_BOX[1], "force": list(F_TIP)}]},
        "solver": {"end_time": 0.06, "cfl": 0.5},
        "output": {"interval": 0.01, "history_interval": 0.01, "fields": FIELDS,
                   "track": [{"name": "tip", "point": [1.97, -0.43]}, {"name": "root", "point": [0.52, -0.68]}]},
    }, dataframes=False)


def _frame_rows(res):
    """(frame index, energy row index) pairs at equal times."""
    et = np.asarray(res.energies["time"])
    pairs = []
    for i, t in enumerate(res.frame_times):
        k = int(np.argmin(np.abs(et - t)))
        if abs(et[k] - t) < 1e-12:
            pairs.append((i, k))
    assert len(pairs) >= 6
    return pairs


def _compliance():
    """3-D isotropic compliance on (xx, yy, xy, zz) with the TENSOR shear stress: e = S s,
    energy 1/2 s . e summed over the 9 components (the xy pair counted twice)."""
    S = np.zeros((4, 4))
    for a in (0, 1, 3):
        for b in (0, 1, 3):
            S[a, b] = 1 / E if a == b else -NU / E
    S[2, 2] = 2 * (1 + NU) / E  # 2 e_xy = s_xy / G, counted twice: s_xy (2 e_xy)
    return S


def test_energies_are_the_sums_of_the_frame_fields(res):
    S = _compliance()
    f, e = res.frames, res.energies
    for i, k in _frame_rows(res):
        m, v, vol, s = f["m"][i], f["v"][i], f["vol"][i], f["stress"][i]
        kinetic = 0.5 * np.sum(m * np.sum(v * v, axis=1))
        strain = 0.5 * np.sum(vol * np.einsum("pa,ab,pb->p", s, S, s))
        plastic = np.sum(vol * f["plastic_work"][i])
        scale = max(e["external_work"][k], 1e-30)
        # round-off of sums over 768 particles
        assert e["kinetic"][k] == pytest.approx(kinetic, rel=1e-12, abs=1e-12 * scale)
        assert e["strain_energy"][k] == pytest.approx(strain, rel=1e-12, abs=1e-12 * scale)
        assert e["plastic_work"][k] == pytest.approx(plastic, rel=1e-12, abs=1e-12 * scale)
        assert e["total"][k] == pytest.approx(e["kinetic"][k] + e["internal_work"][k] + e["damping_work"][k],
                                              rel=1e-14)
    assert e["plastic_work"][-1] > 0.01 * e["external_work"][-1]  # it yielded: the terms are in play
    assert e["damping_work"][-1] > 0.01 * e["external_work"][-1]


def test_external_work_is_the_work_of_gravity_and_the_tip_force(res):
    f, e = res.frames, res.energies
    tip = np.all((f["x0"][0] >= TIP_BOX[0]) & (f["x0"][0] <= TIP_BOX[1]), axis=1)
    assert tip.sum() == 3 * 3 * PPC * PPC  # the box holds 3 x 3 cells of particles
    for i, k in _frame_rows(res):
        u = f["x"][i] - f["x0"][i]
        m = f["m"][i]
        gravity = np.sum(m * (u @ G_VEC))
        force = np.sum(m[tip] / m[tip].sum() * (u[tip] @ F_TIP))
        want = gravity + force
        # telescoping sums of per-step increments: round-off of ~1200 steps
        assert e["external_work"][k] == pytest.approx(want, rel=1e-10, abs=1e-12)


def test_energy_balance_two_sided(res):
    """total = kinetic + internal work + damping work equals the external work (no initial
    kinetic energy), within the issue's 2 % of the largest energy in play, both ways."""
    e = res.energies
    largest = max(np.max(np.abs(e["external_work"])), np.max(e["total"]))
    gap = np.asarray(e["total"]) - np.asarray(e["external_work"])
    assert np.abs(gap).max() <= 0.02 * largest


def test_internal_work_is_strain_energy_plus_plastic_work(res):
    """The bilinear update makes (elastic energy + plastic work) of a point grow by exactly
    mean(sigma) . de per increment (its docstring), and the internal work adds vol mean(sigma)
    . de (trapezoid): they differ only by the volume changes times the energy densities,
    sum dV (e + w), at most max |vol / vol0 - 1| of the energy for a volume that changes
    monotonically (a factor 2 for the oscillation of a damped run)."""
    e, f = res.energies, res.frames
    dilation = max(np.abs(f["vol"][i] / (f["m"][i] / RHO) - 1).max() for i in range(len(res.frame_times)))
    for i, k in _frame_rows(res):
        held = e["strain_energy"][k] + e["plastic_work"][k]
        assert abs(e["internal_work"][k] - held) <= 2 * dilation * max(held, 1e-30) + 1e-15


def test_fields_and_their_derived_state(res):
    f = res.frames
    n = f["m"].shape[1]
    # mass and the initial lattice
    np.testing.assert_allclose(f["m"][0], RHO * (H / PPC) ** 2, rtol=1e-14)
    a = H / PPC
    lattice = np.array([(0.4 + (i + 0.5) * a, -0.7 + (j + 0.5) * a)
                        for i in range(round(1.6 / a)) for j in range(round(0.3 / a))])
    got = f["x0"][0][np.lexsort((f["x0"][0][:, 1], f["x0"][0][:, 0]))]
    want = lattice[np.lexsort((lattice[:, 1], lattice[:, 0]))]
    assert len(got) == n == len(want)
    np.testing.assert_allclose(got, want, atol=1e-12)
    for i in range(1, len(res.frame_times)):
        np.testing.assert_array_equal(f["x0"][i], f["x0"][0])
    # stress = D (strain - eps_p), plane stress, engineering shear
    c = E / (1 - NU ** 2)
    D = c * np.array([[1, NU, 0], [NU, 1, 0], [0, 0, (1 - NU) / 2]])
    sig_max = np.abs(f["stress"]).max()
    for i in range(len(res.frame_times)):
        elastic = f["strain"][i] - f["eps_p"][i]
        np.testing.assert_allclose(f["stress"][i][:, :3], elastic @ D.T, rtol=0, atol=1e-9 * sig_max)
        np.testing.assert_array_equal(f["stress"][i][:, 3], 0.0)
        # the return mapping keeps sigma - eta on or inside the yield surface
        xi = f["stress"][i] - f["back_stress"][i]
        phi = np.sqrt(xi[:, 0] ** 2 - xi[:, 0] * xi[:, 1] + xi[:, 1] ** 2 + 3 * xi[:, 2] ** 2)
        assert phi.max() <= SY * (1 + 1e-9)
        # eps_p_eq >= sqrt(2/3) |eps_p| (zz = -(xx + yy), tensor shear gxy / 2)
        ep = f["eps_p"][i]
        norm = np.sqrt(ep[:, 0] ** 2 + ep[:, 1] ** 2 + (ep[:, 0] + ep[:, 1]) ** 2 + 2 * (0.5 * ep[:, 2]) ** 2)
        assert np.all(f["eps_p_eq"][i] >= math.sqrt(2 / 3) * norm * (1 - 1e-9))
        # the volume is the initial one (m / density, unit thickness) times the in-plane det F
        F = f["F"][i]
        np.testing.assert_allclose(f["vol"][i], f["m"][i] / RHO * (F[:, 0] * F[:, 3] - F[:, 1] * F[:, 2]),
                                   rtol=1e-12)
        # small strain: F - I is the displacement gradient, whose symmetric part the strain
        # accumulates; they differ by the second-order terms, about |F - I|^2 / 2 (a rotation
        # by theta: cos(theta) - 1 = -theta^2 / 2), bounded here by 2 |F - I|^2
        eps = f["strain"][i]
        gap = np.abs(np.column_stack([F[:, 0] - 1, F[:, 3] - 1, F[:, 1] + F[:, 2]]) - eps).max()
        assert gap <= 2 * np.abs(np.column_stack([F[:, 0] - 1, F[:, 3] - 1, F[:, 1], F[:, 2]])).max() ** 2 + 1e-15
    last = len(res.frame_times) - 1
    assert f["eps_p_eq"][last].max() > SY / E  # yielded: the identities above see plastic strain
    assert np.abs(f["back_stress"][last]).max() > 0.01 * SY


def test_histories_follow_their_particles(res):
    f = res.frames
    for name, pid in res.track_ids.items():
        h = res.histories[name]
        ht = np.asarray(h["time"])
        for i, t in enumerate(res.frame_times):
            k = int(np.argmin(np.abs(ht - t)))
            if abs(ht[k] - t) > 1e-12:
                continue
            u = f["x"][i][pid] - f["x0"][i][pid]
            row = [h[c][k] for c in ("ux", "uy", "vx", "vy", "x", "y", "sxx", "syy", "sxy")]
            want = [*u, *f["v"][i][pid], *f["x"][i][pid], *f["stress"][i][pid][:3]]
            np.testing.assert_allclose(row, want, rtol=1e-14, atol=1e-300)
    assert abs(res.histories["tip"]["uy"][-1]) > 1e-3  # the tip moved


def test_named_components_are_the_columns_they_name(res):
    """res.frame(i) names every component (docs/output.md): each named column is that
    component of the frame field (stress sxx syy sxy szz, strain exx eyy gxy, ...)."""
    names = {"x": ("x", "y"), "v": ("vx", "vy"), "stress": ("sxx", "syy", "sxy", "szz"),
             "strain": ("exx", "eyy", "gxy"), "eps_p": ("epxx", "epyy", "gpxy"),
             "back_stress": ("back_xx", "back_yy", "back_xy", "back_zz")}
    i = len(res.frame_times) - 1
    table = res.frame(i)
    for field, cols in names.items():
        for k, col in enumerate(cols):
            np.testing.assert_array_equal(np.asarray(table[col]), res.frames[field][i][:, k], err_msg=col)
