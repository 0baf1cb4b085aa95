"""The linear solve of each Newton iteration, on PETSc (petsc4py).

The unknowns are the displacement increments of the step's active nodes, two per node,
numbered by their owners: rank r owns the active nodes of its slab (pmpm's decomposition),
which become the rows [start_r, start_r + 2 n_r) of a PETSc AIJ matrix with block size 2. Each
rank hands PETSc the blocks its own particles assembled (pmpm.core.implicit.kernels), ghost
rows included, with ADD_VALUES: PETSc sums the ghost contributions into their owners when the
matrix is assembled. The Krylov solver and preconditioner come from PETSc's options: the
scene's ``[solver.petsc]`` table and any ``-ksp_*`` / ``-pc_*`` / ``-mat_*`` options on the
command line (``pmpm case.toml -ksp_type cg``), under the prefix ``pmpm_``. The default is a
direct solve (LU by MUMPS on any rank count): robust for the ill-conditioned rows of nodes at
the edge of the material, and exact, so the Newton iterations see only the tangent's error.

petsc4py is imported when the first implicit solver is built (``petsc``): an explicit run
never initialises PETSc.
"""
import atexit
import ctypes
import glob
import logging
import os
import weakref

import numpy as np

from pmpm.core.implicit.kept_factorisation import KeptFactorisation
from pmpm.errors import ConfigError

__all__ = ["LinearSolver", "validate_options", "petsc", "DEFAULT_OPTIONS", "PREFIX", "check_option_names", "command_line_options"]
logger = logging.getLogger(__name__)

#: the options prefix of pmpm's solver objects (a user's -ksp_type reaches them as pmpm_ksp_type)
PREFIX = "pmpm_"
#: a direct solve unless the scene or the command line says otherwise
DEFAULT_OPTIONS = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
#: families of PETSc options a scene may set (the linear solve's objects only)
OPTION_FAMILIES = ("ksp_", "pc_", "mat_", "mg_", "sub_")


def petsc():
    """The petsc4py PETSc module, initialised on first use (with pmpm's MPI communicator
    already set up by mpi4py). Imported here, not at the top, so that an explicit run never
    loads or initialises PETSc. Without petsc4py: ConfigError on solver.integrator (exit 2, one
    line) rather than a traceback."""
    try:
        import petsc4py
    except ImportError:
        raise ConfigError("solver.integrator", "the implicit integrator needs petsc4py, which this Python "
                                               "does not have (setup.sh builds it against Debian's PETSc)") from None
    if not getattr(petsc4py, "_pmpm_initialised", False):
        petsc4py.init(["pmpm"])   # (the program name only: PETSc reads no options from argv)
        petsc4py._pmpm_initialised = True
    from petsc4py import PETSc
    return PETSc


def check_option_names(options, key):
    """Refuse an option name that is not a linear-solver option (``OPTION_FAMILIES``), not a
    plain identifier, or a value that is not a string, number or boolean. PETSc itself then
    refuses the names it does not know (``LinearSolver.check_unused``)."""
    for name, value in options.items():
        bare = name.lstrip("-")
        if not bare.replace("_", "").isalnum() or not bare.startswith(OPTION_FAMILIES):
            raise ConfigError(f"{key}.{name}", f"not a PETSc linear-solver option (names start with "
                                               f"{', '.join(OPTION_FAMILIES)})")
        if not isinstance(value, (str, int, float, bool)) or isinstance(value, str) and not value.replace(
                "_", "").replace(".", "").replace("-", "").replace("+", "").isalnum() and value != "":
            raise ConfigError(f"{key}.{name}", f"must be a plain string, number or boolean (got {value!r})")


def command_line_options(argv):
    """The ``-ksp_*``, ``-pc_*``, ``-mat_*`` options (with their values) in ``argv``, as a dict,
    and the arguments left: ``pmpm case.toml -ksp_type cg -ksp_rtol 1e-10``."""
    out, rest, k = {}, [], 0
    while k < len(argv):
        a = argv[k]
        if a.startswith("-") and a.lstrip("-").startswith(OPTION_FAMILIES) and not a.startswith("--"):
            value = ""
            if k + 1 < len(argv) and not (argv[k + 1].startswith("-") and not _is_number(argv[k + 1])):
                value = argv[k + 1]
                k += 1
            out[a.lstrip("-")] = value
        else:
            rest.append(a)
        k += 1
    return out, rest


def _options_used_function():
    """PetscOptionsUsed of the PETSc library petsc4py loaded (the same process-wide handle)."""
    import petsc4py
    cfg = petsc4py.get_config()
    found = sorted(glob.glob(os.path.join(cfg["PETSC_DIR"], cfg.get("PETSC_ARCH") or "", "lib", "libpetsc*.so*")))
    if not found:
        return None
    fn = ctypes.CDLL(found[0]).PetscOptionsUsed
    fn.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.POINTER(ctypes.c_int)]
    return fn


def _is_number(text):
    try:
        float(text)
        return True
    except ValueError:
        return False


def _option_text(value):
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def validate_options(options):
    """ConfigError naming the first option PETSc does not use: a 2 x 2 system is solved on this
    process alone with the options, then PETSc is asked which it read. Called while the scene
    is checked (implicit scenes only), so a misspelt option stops the run before it writes."""
    from mpi4py import MPI   # (here, not at the top: the command line's parser imports this module)
    probe = LinearSolver(MPI.COMM_SELF, options)
    try:
        block = np.array([[[2.0, 0.0], [0.0, 2.0]]])
        one = np.zeros(1, np.int64)
        probe.set_operator(1, 0, np.zeros(1, np.int64), np.array([0, 1]), np.zeros(1, np.int64), block, one + 1, one)
        probe.solve(np.ones(2))
        probe.check_unused()
    finally:
        probe.destroy()


class LinearSolver:
    """A KSP on ``comm`` whose operator is rebuilt each step from per-rank blocks.

    Parameters
    ----------
    comm : mpi4py communicator
    options : dict
        PETSc options (name without the leading dash -> value) over ``DEFAULT_OPTIONS``.
    krylov : (float, int), optional
        ``newton = "krylov"``: (relative tolerance, iterations) of a flexible GMRES on each
        operator, preconditioned by a kept factorisation of an earlier one (the options'
        solver: pmpm.core.implicit.kept_factorisation), refactored from the current operator
        when the GMRES does not converge within the iterations. None: the options' solver on
        each operator (by default a new LU factorisation of each).
    kept_only : bool
        ``newton = "accelerated"``: each operator is factored when it is set, and the solves
        between two operators apply that factorisation alone, also to a later step's rows
        (``refit``: rows matched by grid node, a Jacobi step on new ones;
        pmpm.core.implicit.kept_factorisation). Newton's accelerated iteration makes up for
        the difference from the current tangent (pmpm.core.implicit.accelerated).
    """

    def __init__(self, comm, options, krylov=None, kept_only=False):
        self.PETSc = petsc()
        self.comm = comm
        self.options = dict(DEFAULT_OPTIONS)
        self.options.update(options)
        if comm.Get_size() == 1 and self.options.get("pc_factor_mat_solver_type") == "mumps" \
                and not self._has_mumps():
            self.options["pc_factor_mat_solver_type"] = "petsc"
        db = self.PETSc.Options()
        for name in list(db.getAll()):   # an earlier scene's options (one process, several runs)
            if name.startswith(PREFIX):
                db.delValue(name)
        for name, value in self.options.items():
            db.setValue(PREFIX + name, _option_text(value))
        self.ksp = None
        self.A = None
        self._sizes = None
        self._pattern = None
        self.iterations = 0
        #: factorisations (direct solves: one for each operator; ``krylov``: of the kept one)
        self.factorisations = 0
        self.krylov = krylov
        self.kept_only = kept_only
        #: ``kept_only``: the diagonal (owned rows) of the kind GridProblem.kept_diagonal computes,
        #: of the operator set next (the kept factorisation's rescaling)
        self.reference_diagonal = None
        self.kept = KeptFactorisation(self.PETSc, comm, PREFIX) if krylov is not None or kept_only else None
        if self.kept is not None:
            # the python preconditioner's objects go before PETSc finalises (petsc4py's own
            # exit handler, registered earlier, runs later): destroyed after it, at garbage
            # collection, they crash the process on its way out
            ref = weakref.ref(self)
            atexit.register(lambda: ref() is not None and ref().destroy())
        self._keys = None
        #: operators whose rows some rank mapped onto the kept factorisation's (changed unknowns)
        self.remapped = 0
        self._refactor_next = False
        self._extra = 0             # GMRES iterations beyond one a solve since the last factorisation
        #: (active, held) node masks of the step whose tangent the operator holds (GridProblem)
        self.unknowns = None

    def _has_mumps(self):
        """Whether the PETSc library was configured with MUMPS (Debian's is)."""
        return bool(self.PETSc.Sys.hasExternalPackage("mumps"))

    def check_unused(self):
        """ConfigError for the first option PETSc did not read (a misspelt name, or one that
        does not apply to the chosen solver): called after the first solve, when every object
        has read its options. PETSc's PetscOptionsUsed through its shared library (petsc4py
        3.18 does not wrap it); skipped, with a warning, where the library is not found."""
        used = _options_used_function()
        if used is None:
            logger.warning("cannot ask PETSc which options it used; misspelt [solver.petsc] names go unnoticed")
            return
        for name, value in self.options.items():
            if name in DEFAULT_OPTIONS and DEFAULT_OPTIONS[name] == value:
                continue
            flag = ctypes.c_int(0)
            used(None, (PREFIX + name).encode(), ctypes.byref(flag))
            if not flag.value:
                raise ConfigError(f"solver.petsc.{name}", "PETSc did not use this option (unknown name, or "
                                                          "it does not apply to the chosen solver)")

    def set_operator(self, n_owned, start, rows, indptr, cols, values, diag_nnz, off_nnz, keys=None):
        """Build this step's matrix: ``n_owned`` nodes owned here (rows 2 start .. 2 (start +
        n_owned)), and the blocks this rank assembled in block-CSR form: block rows ``rows``
        (global node numbers, ghosts included), ``indptr``/``cols`` their column nodes,
        ``values`` (nnz, 2, 2). ``diag_nnz``/``off_nnz``: blocks per owned row in the owned and
        the other columns (preallocation). ``keys``: names of the owned rows that stay the
        same from step to step (``krylov`` only: the kept factorisation's rows are matched by
        them; default their global numbers)."""
        self._build(n_owned, start, rows, indptr, cols, values, diag_nnz, off_nnz)
        if self.kept is None:
            self.factorisations += 1
            return
        if self.kept_only:
            self._keys = np.arange(2 * start, 2 * (start + n_owned)) if keys is None else np.asarray(keys)
            self._factor_kept(self.reference_diagonal)
            return
        self._keys = np.arange(2 * start, 2 * (start + n_owned)) if keys is None else np.asarray(keys)
        d = self.A.getDiagonal()   # (collective: on every rank, whether its rows changed or not)
        self.kept.fit(self._keys, d.array.copy())
        d.destroy()
        if self.kept.ready and self.comm.allreduce(0 if self.kept.identity else 1):
            self.remapped += 1


    def _build(self, n_owned, start, rows, indptr, cols, values, diag_nnz, off_nnz):
        PETSc = self.PETSc
        pattern = (rows.copy(), indptr.copy(), cols.copy())
        same = self.A is not None and self._sizes[0][0] == 2 * n_owned and all(
            a.shape == b.shape and np.array_equal(a, b) for a, b in zip(pattern, self._pattern))
        if self.comm.allreduce(0 if same else 1) == 0:   # every rank, or none
            # the same blocks as the last matrix (the iterations of one step): new values only,
            # so the factorisation reuses its analysis (MUMPS) or its symbolic part (PETSc's LU)
            self.A.zeroEntries()
            self.A.setValuesBlockedIJV(indptr.astype(PETSc.IntType), cols.astype(PETSc.IntType),
                                       values.reshape(-1), addv=PETSc.InsertMode.ADD_VALUES,
                                       rowmap=rows.astype(PETSc.IntType))
            self.A.assemblyBegin()
            self.A.assemblyEnd()
            if self.kept is None:
                self.ksp.setOperators(self.A)
            return
        self._pattern = pattern
        A = PETSc.Mat().create(comm=self.comm)
        A.setSizes(((2 * n_owned, PETSc.DETERMINE), (2 * n_owned, PETSc.DETERMINE)), bsize=2)
        A.setType(PETSc.Mat.Type.AIJ)
        A.setOptionsPrefix(PREFIX)
        A.setFromOptions()
        d = np.repeat(2 * diag_nnz, 2).astype(PETSc.IntType)
        o = np.repeat(2 * off_nnz, 2).astype(PETSc.IntType)
        A.setPreallocationNNZ((d, o))
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        A.setValuesBlockedIJV(indptr.astype(PETSc.IntType), cols.astype(PETSc.IntType),
                              values.reshape(-1), addv=PETSc.InsertMode.ADD_VALUES,
                              rowmap=rows.astype(PETSc.IntType))
        A.assemblyBegin()
        A.assemblyEnd()
        if self.A is not None:
            self.A.destroy()
        self.A = A
        if self.kept_only:   # (no solver of its own: the kept factorisation's)
            self._sizes = A.getSizes()
            return
        if self.kept is not None:
            self._krylov_solver(A)
            return
        resized = self.ksp is not None and self._sizes != A.getSizes()
        # decided together: a rank whose own rows kept their number while a neighbour's changed
        # must destroy the solver too (KSPDestroy is collective; deciding alone deadlocked 3 ranks)
        if self.comm.allreduce(1 if resized else 0) > 0:
            # the active nodes changed: a new solver (a reset KSP keeps sub-solvers, e.g. the
            # multigrid levels, of the old size)
            self.ksp.destroy()
            self.ksp = None
        if self.ksp is None:
            self.ksp = PETSc.KSP().create(comm=self.comm)
            self.ksp.setOptionsPrefix(PREFIX)
        self._sizes = A.getSizes()
        self.ksp.setOperators(A)
        self.ksp.setFromOptions()
        self.x, self.b = A.createVecs()

    def _krylov_solver(self, A):
        """A new operator of the ``krylov`` mode (the new-matrix path, taken on every rank
        together): a flexible GMRES on it with the kept factorisation as its preconditioner
        (a python PC; FGMRES because the options may make the inner solve an iterative one)."""
        PETSc = self.PETSc
        if self.ksp is not None:
            self.ksp.destroy()
        ksp = PETSc.KSP().create(comm=self.comm)
        ksp.setType(PETSc.KSP.Type.FGMRES)
        rtol, its = self.krylov
        ksp.setTolerances(rtol=rtol, atol=0.0, max_it=its)
        ksp.setGMRESRestart(max(its, 1))
        ksp.setOperators(A)
        pc = ksp.getPC()
        pc.setType(PETSc.PC.Type.PYTHON)
        pc.setPythonContext(self.kept)
        self.ksp = ksp
        self._sizes = A.getSizes()
        self.x, self.b = A.createVecs()

    def refit(self, keys, diagonal):
        """``kept_only``: this step's owned rows, named ``keys`` (``diagonal``: their diagonal,
        for the rows the kept factorisation does not have; may be None where the keys are
        its rows), mapped onto the kept factorisation. Rank-local."""
        self._keys = np.asarray(keys)
        self.kept.fit(self._keys, diagonal)

    def solve(self, rhs):
        """The owned part of A^-1 rhs (``rhs``: this rank's owned rows). Raises
        ``ArithmeticError`` when the Krylov solver reports divergence."""
        if self.kept_only:
            self.iterations += 1
            # (a correction that is not finite shows in the next residual's global norm, on
            # every rank: Newton stops there; no rank-local test that would leave the others)
            return self.kept.solve_array(np.asarray(rhs, dtype=float))
        self.b.array[:] = rhs
        if self.kept is not None and (not self.kept.ready or self._refactor_next):
            self._factor_kept()
        self.ksp.solve(self.b, self.x)
        reason = self.ksp.getConvergedReason()
        self.iterations += max(self.ksp.getIterationNumber(), 1)
        if reason < 0 and self.kept is not None:
            # the kept factorisation no longer fits the operator (the same reason on every
            # rank: the decision is collective): factor the current one and solve again
            logger.debug("kept factorisation: %d Krylov iterations without convergence (reason %d), refactored",
                         self.ksp.getIterationNumber(), reason)
            self._factor_kept()
            self.x.set(0.0)
            self.ksp.solve(self.b, self.x)
            reason = self.ksp.getConvergedReason()
            self.iterations += max(self.ksp.getIterationNumber(), 1)
        if reason < 0:
            raise ArithmeticError(f"the linear solver diverged (KSP reason {reason})")
        if self.kept is not None:
            # the back-substitutions beyond one a solve are what the kept factorisation costs over
            # a fresh one; once they add up to the GMRES's budget (about a factorisation's cost
            # when the budget is the ratio of the two: docs/implicit.md), the next solve factors
            # the operator it has. (The counts are the same on every rank: a collective decision.)
            self._extra += self.ksp.getIterationNumber() - 1
            self._refactor_next = self._extra >= self.krylov[1]
        return self.x.array.copy()

    def _factor_kept(self, reference_diagonal=None):
        self._refactor_next = False
        self._extra = 0
        self.kept.factor(self.A, self._keys, reference_diagonal)
        self.factorisations += 1

    def destroy(self):
        if self.kept is not None:
            self.kept.release()
        for obj in (self.ksp, self.A):
            if obj is not None:
                obj.destroy()
        self.ksp = self.A = None
