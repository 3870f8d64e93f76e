"""Coarse-graining clumps as rigid bodies: centroids, body frames, mass counted once, spin
without kinetic stress, and contact branches through the bodies' centroids."""
from __future__ import annotations

import math

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from postprocess.cg_kernels import gaussian
from postprocess.clump_bodies import body_centres, body_frame, centroid_weights
from siloflow.clumps import union_centroid
from postprocess.cg_grids import CartesianGrid
from postprocess.coarse_grain import CoarseGraining
from postprocess.dumps import Frame

WHEAT = np.array([[-0.001, 0.0, 0.0], [0.0, 0.0, 0.0], [0.001, 0.0, 0.0]]), np.full(3, 0.002)


def cap(R, h):
    """Volume and centroid distance from the sphere's centre of a cap of height h."""
    return math.pi * h * h * (3 * R - h) / 3.0, 3.0 * (2 * R - h) ** 2 / (4.0 * (3 * R - h))


def test_union_centroid_of_two_unequal_spheres_is_the_closed_form():
    r1, r2, d = 0.002, 0.0013, 0.0021
    a = (d * d + r1 * r1 - r2 * r2) / (2 * d)                  # the plane of the intersection circle
    v1, v2 = 4 / 3 * math.pi * r1 ** 3, 4 / 3 * math.pi * r2 ** 3
    (c1v, c1x), (c2v, c2x) = cap(r1, r1 - a), cap(r2, r2 - (d - a))
    volume = v1 + v2 - c1v - c2v
    x = (v2 * d - c1v * c1x - c2v * (d - c2x)) / volume
    rot = np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))[0]
    shift = np.array([0.01, -0.02, 0.03])
    centers = np.array([[0, 0, 0], [d, 0, 0]]) @ rot.T + shift
    got = union_centroid(centers, np.array([r1, r2]))
    np.testing.assert_allclose(got, np.array([x, 0, 0]) @ rot.T + shift, atol=1e-10 * r1)
    w = centroid_weights(centers, np.array([r1, r2]))
    assert w.sum() == pytest.approx(1.0) and w @ centers == pytest.approx(np.array([x, 0, 0]) @ rot.T + shift,
                                                                         abs=1e-10 * r1)


def test_union_centroid_of_six_random_spheres_agrees_with_monte_carlo():
    rng = np.random.default_rng(3)
    centers, radii = rng.normal(scale=0.001, size=(6, 3)), rng.uniform(0.001, 0.002, 6)
    pts = rng.uniform((centers - radii[:, None]).min(0), (centers + radii[:, None]).max(0), (2_000_000, 3))
    inside = np.zeros(len(pts), bool)
    for c, r in zip(centers, radii):
        inside |= ((pts - c) ** 2).sum(1) <= r * r
    sigma = pts[inside].std(0) / math.sqrt(inside.sum())
    assert np.all(np.abs(union_centroid(centers, radii) - pts[inside].mean(0)) < 4 * sigma)


def clump_frame(n_bodies=40, n_dust=15, seed=0, spin=1.0, drift=(0.0, 0.0, 0.0)):
    """Wheat grains at random places and orientations moving as rigid bodies (velocity V + w x
    (x - X)), and dust balls; LIGGGHTS style: every sphere of a clump carries the clump's mass."""
    rng = np.random.default_rng(seed)
    rows = []
    aid = 1
    for b in range(n_bodies):
        rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        X = rng.uniform(-0.02, 0.02, 3) + [0, 0, 0.05]
        V = np.asarray(drift) + 0.1 * rng.normal(size=3)
        om = spin * rng.normal(size=3) * 50.0
        for c, r in zip(*WHEAT):
            x = X + rot @ c
            v = V + np.cross(om, x - X)
            rows.append((aid, 1, b + 1, *x, *v, r, 5.8e-5))
            aid += 1
    for k in range(n_dust):
        x = rng.uniform(-0.02, 0.02, 3) + [0, 0, 0.05]
        rows.append((aid, 2, -1, *x, *(np.asarray(drift) + 0.1 * rng.normal(size=3)), 0.00025, 5.2e-8))
        aid += 1
    data = pd.DataFrame(rows, columns=["id", "type", "mol", "x", "y", "z", "vx", "vy", "vz", "radius", "mass"])
    return Frame(0, np.array([[-0.05, 0.05], [-0.05, 0.05], [0.0, 0.1]]), data, source="constructed")


def test_body_frame_puts_each_clump_at_its_centroid_with_its_velocity_and_mass_once():
    frame = clump_frame(spin=1.0)
    bodies = body_frame(frame)
    assert bodies.n == 40 + 15
    grains = bodies.data[bodies.data.type == 1]
    pos, vel = frame.positions(), frame.velocities()
    for _, row in grains.iterrows():
        member = frame.data.mol.to_numpy() == row.mol
        # wheat is symmetric: the centroid is the middle sphere, moving with the body's V
        np.testing.assert_allclose(row[["x", "y", "z"]].to_numpy(float), pos[member][1], atol=1e-12)
        np.testing.assert_allclose(row[["vx", "vy", "vz"]].to_numpy(float), vel[member][1], atol=1e-10)
    assert bodies.data.mass.sum() == pytest.approx(40 * 5.8e-5 + 15 * 5.2e-8)


def test_clump_mass_of_either_dump_convention_gives_the_same_bodies():
    """LIGGGHTS gives every sphere the clump's mass ("body"); rigid bodies of LAMMPS give each
    sphere its share ("sum"): both conventions give the same body masses."""
    frame = clump_frame(spin=1.0)
    shared = frame.data.copy()
    in_clump = shared.mol > 0
    shared.loc[in_clump, "mass"] = shared.loc[in_clump, "mass"] * np.array([0.2, 0.5, 0.3] * 40)
    a = body_frame(frame, clump_mass="body").data.sort_values("id")
    b = body_frame(replace(frame, data=shared), clump_mass="sum").data.sort_values("id")
    np.testing.assert_allclose(a.mass.to_numpy(), b.mass.to_numpy(), rtol=1e-14)
    with pytest.raises(ValueError, match="clump_mass"):
        body_frame(frame, clump_mass="sphere")


def test_clump_mass_is_counted_once_and_spin_makes_no_kinetic_stress():
    # every body translating with one velocity and spinning: no velocity fluctuation
    still = clump_frame(spin=1.0, drift=(0.0, 0.0, -0.3))
    X, _ = body_centres(still)
    body = still.data.mol.to_numpy()
    rng = np.random.default_rng(5)
    for b in np.unique(body[body > 0]):
        m = body == b
        om = 80.0 * rng.normal(size=3)
        still.data.loc[m, ["vx", "vy", "vz"]] = [0.0, 0.0, -0.3] + np.cross(om, still.positions()[m] - X[m])
    still.data.loc[body < 0, ["vx", "vy", "vz"]] = [0.0, 0.0, -0.3]
    grid = CartesianGrid([-0.04, -0.04, 0.0], [0.04, 0.04, 0.1], (32, 32, 40))
    cg = CoarseGraining(grid, gaussian(0.003)).run([still])
    f = cg.fields()
    total = 40 * 5.8e-5 + 15 * 5.2e-8
    assert f["rho"].sum() * grid.cell_volume == pytest.approx(total, rel=0.005)
    assert f["momentum"][..., 2].sum() * grid.cell_volume == pytest.approx(-0.3 * total, rel=0.005)
    scale = f["rho"].max() * 0.3 ** 2
    assert np.abs(f["kinetic_stress"]).max() < 1e-9 * scale
    # the spheres as separate particles would have seen the spin as fluctuation
    loose = Frame(0, still.box, still.data.drop(columns="mol"), source="no bodies")
    loose.data["mass"] = np.where(loose.data.type == 1, 5.8e-5 / 3, 5.2e-8)
    assert np.abs(CoarseGraining(grid, gaussian(0.003)).run([loose]).fields()["kinetic_stress"]).max() > 1e-3 * scale


def test_clump_contact_branches_run_through_the_centroids():
    """The volume integral of the contact stress is sum f (X_i - X_j) (X the bodies' centroids),
    not f (x_i - x_j) of the touching spheres; wall contacts run from the wall point to X_i."""
    frame = clump_frame(n_bodies=2, n_dust=0, seed=3)
    X, _ = body_centres(frame)
    pos, rad = frame.positions(), frame.radii()
    # sphere 0 of body 1 touching sphere 5 of body 2 (placed by hand: a small overlap)
    n = np.array([0.6, 0.0, 0.8])
    shifted = frame.data.copy()
    body2 = shifted.mol.to_numpy() == 2
    target = pos[0] + n * (rad[0] + rad[5] - 1e-5)
    shifted.loc[body2, ["x", "y", "z"]] = pos[body2] + (target - pos[5])
    frame = Frame(0, frame.box, shifted, source="constructed")
    pos = frame.positions()
    X, _ = body_centres(frame)
    f1 = np.array([-0.3, 0.1, -0.5])                           # force on sphere 0 from sphere 5
    pair = pd.DataFrame([[*pos[0], *pos[5], 1, 6, 0, *f1]],
                        columns=["x1", "y1", "z1", "x2", "y2", "z2", "id1", "id2", "periodic", "fx", "fy", "fz"])
    wall_point = pos[2] + np.array([0.0, 0.0, -rad[2]])
    fw = np.array([0.0, 0.0, 0.7])
    wall = pd.DataFrame([[*wall_point, *pos[2], 3, *fw]], columns=["xw", "yw", "zw", "x1", "y1", "z1", "id1",
                                                                   "fx", "fy", "fz"])
    contacts = Frame(0, frame.box, pair, kind="entries", source="pairs")
    walls = Frame(0, frame.box, wall, kind="entries", source="walls")
    grid = CartesianGrid([-0.05, -0.05, -0.01], [0.05, 0.05, 0.11], (50, 50, 60))
    cg = CoarseGraining(grid, gaussian(0.003), n_s=8).run([frame], [contacts], [walls])
    integral = cg.fields()["contact_stress"].reshape(-1, 9).sum(0) * grid.cell_volume
    expect = np.outer(f1, X[0] - X[5]) + np.outer(fw, X[2] - wall_point)
    np.testing.assert_allclose(integral, expect.ravel(), atol=5e-3 * np.abs(expect).max())
    spheres = np.outer(f1, pos[0] - pos[5]) + np.outer(fw, pos[2] - wall_point)
    assert np.abs(integral - spheres.ravel()).max() > 0.05 * np.abs(expect).max()


def test_solid_fraction_counts_volumes_when_species_differ_in_density():
    """Scaled (heavy) dust among clumps: the solid fraction is each species' partial density over
    its own particle density, so its integral is the solid volume (clumps' unions, dust spheres),
    not the mass over the grains' density."""
    from siloflow.clumps import union_volume
    frame = clump_frame(seed=2)
    dust = frame.data.type == 2
    frame.data.loc[dust, "mass"] = 8.0e5 * 4 / 3 * math.pi * 0.00025 ** 3         # dust x400
    grain_volume = union_volume(*WHEAT)
    frame.data.loc[~dust, "mass"] = 1000.0 * grain_volume
    grid = CartesianGrid([-0.04, -0.04, 0.0], [0.04, 0.04, 0.1], (32, 32, 40))
    cg = CoarseGraining(grid, gaussian(0.003), particle_density=1000.0, species="type").run([frame])
    f = cg.fields()
    solid = 40 * grain_volume + 15 * 4 / 3 * math.pi * 0.00025 ** 3
    assert f["solid_fraction"].sum() * grid.cell_volume == pytest.approx(solid, rel=0.005)
    np.testing.assert_allclose(cg.class_density, [1000.0, 8.0e5], rtol=1e-9)
    # rho / rho_p would have counted the dust's mass as grain volume
    assert f["rho"].sum() * grid.cell_volume / 1000.0 > 1.2 * solid


def test_clumps_of_one_shape_and_two_sizes_get_their_own_volumes():
    from siloflow.clumps import union_volume
    frame = clump_frame(n_bodies=4, n_dust=0, seed=4)
    big = frame.data.mol.to_numpy() >= 3                      # bodies 3 and 4 scaled x2 about their middle
    pos = frame.positions()
    for b in (3, 4):
        m = frame.data.mol.to_numpy() == b
        mid = pos[m][1]
        frame.data.loc[m, ["x", "y", "z"]] = mid + 2.0 * (pos[m] - mid)
        frame.data.loc[m, "radius"] = 0.004
    bodies = body_frame(frame).data.set_index("mol")
    assert bodies.loc[1, "volume"] == pytest.approx(union_volume(*WHEAT), rel=1e-9)
    assert bodies.loc[3, "volume"] == pytest.approx(8 * union_volume(*WHEAT), rel=1e-9)
    assert big.sum() == 6
