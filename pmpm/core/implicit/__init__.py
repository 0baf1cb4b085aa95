"""The implicit integrator (docs/implicit.md): Newmark's rule with Newton iterations on the grid,
the materials' tangents as the stiffness, PETSc for the linear solve.

    options        the scene keys ([solver] integrator, analysis; [solver.implicit]; [solver.petsc])
                   and what is refused that is no part of the solver (the parts: scheme.check_parts)
    kernels        numba kernels: step deformation, internal force, tangent blocks, Newmark update
    reference      their NumPy twins (tests)
    dofs           the step's unknowns: mass rule, global numbering over the slabs, block CSR
    edges          edge nodes slaved to their inward neighbours (edge_mass_ratio): folds, expansion
    newmark        the time integration rule
    newton         Newton's method with a line search
    problem        one step's residual and tangent on a rank's window
    linear_solver  the PETSc adapter (petsc4py, loaded by implicit runs only)
    scheme         the step as phases, registered as the scheme ``newmark``
"""
