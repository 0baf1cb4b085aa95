"""Communication depends on the slab boundary, not on the particle count (issue: scaling).

Two blocks on the same grid, one with 2 and one with 3 particles per cell per direction (2.25x
the particles): the halo bytes each rank sends per step are the same, because a halo carries
grid columns, and their size is the ghost width times the column height times the fields.
"""
import pytest
from mpi4py import MPI

from pmpm.benchmarks.block import block_scene
from pmpm.build import build_solver

comm = MPI.COMM_WORLD


@pytest.mark.skipif(comm.size < 2, reason="needs mpirun -n 2 or more")
def test_halo_bytes_do_not_grow_with_particles():
    sent = []
    for ppc, n in ((2, 20000), (3, 45000)):
        s = build_solver(block_scene(n, ppc=ppc), comm)
        s.step()
        s.decomp.reset_counters()
        for _ in range(5):
            s.step()
        sent.append((s.grid.cells, s.decomp.bytes_sent["halo"], s.particles.n))
    (cells_a, halo_a, n_a), (cells_b, halo_b, n_b) = sent
    assert cells_a == cells_b
    assert comm.allreduce(n_b) > 2 * comm.allreduce(n_a)
    assert halo_a == halo_b
    # 5 MUSL steps, each with two exchanges (after P2G: 5 fields; after the re-map: 2), each
    # summed to the owner and copied back, ghost-width columns per neighbour, float64
    neighbours = (s.decomp.lower != MPI.PROC_NULL) + (s.decomp.upper != MPI.PROC_NULL)
    column = s.grid.nodes[1 - s.axis]
    assert halo_a == 5 * neighbours * 2 * s.decomp.ghost * column * (5 + 2) * 8
