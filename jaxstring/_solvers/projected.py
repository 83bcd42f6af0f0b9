"""A solver wrapper that projects the state onto the model's constraint manifold.

The Cartesian tangent of the natural-variable string must keep |t| = 1. Holding it
with Baumgarte terms at the rate of the axial waves adds a stiff, critically damped
(defective) mode that the embedded error estimates of ESDIRK methods handle badly
(docs/numerics.md, "Projection"). Instead, after every accepted or attempted step,
the new state is projected (t -> t/|t|, and the radial part of dt/dt removed) --
the standard projection method for ODEs on manifolds (Hairer, Lubich & Wanner,
*Geometric Numerical Integration*, IV.4). The error estimate and dense output of
the wrapped solver are kept as they are.
"""

import diffrax as dfx


class ProjectedSolver(dfx.AbstractAdaptiveSolver, dfx.AbstractWrappedSolver):
    """Wrap `solver`; project the state at the end of every step.

    The projection is the scene's `args.model.project`: the model travels in `args`
    (never closed over), so its parameters stay differentiable.
    """

    solver: dfx.AbstractSolver

    @property
    def term_structure(self):
        return self.solver.term_structure

    @property
    def interpolation_cls(self):  # pyright: ignore
        return self.solver.interpolation_cls

    @property
    def root_finder(self):
        # diffrax inspects this to copy step-size tolerances into the root finder;
        # jaxstring's root finders carry their own tolerances.
        return getattr(self.solver, "root_finder", None)

    @property
    def term_compatible_contr_kwargs(self):
        return self.solver.term_compatible_contr_kwargs

    def order(self, terms):
        return self.solver.order(terms)

    def strong_order(self, terms):
        return self.solver.strong_order(terms)

    def error_order(self, terms):
        return self.solver.error_order(terms)

    def init(self, terms, t0, t1, y0, args):
        return self.solver.init(terms, t0, t1, y0, args)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        y1, y_error, dense_info, solver_state, result = self.solver.step(
            terms, t0, t1, y0, args, solver_state, made_jump
        )
        return args.model.project(y1), y_error, dense_info, solver_state, result

    def func(self, terms, t0, y0, args):
        return self.solver.func(terms, t0, y0, args)


class ProjectedSolverAD(ProjectedSolver):
    """`ProjectedSolver` for diffrax's ForwardMode and DirectAdjoint, which read
    `solver.scan_kind` (the wrapped solver's, set by the caller before wrapping);
    `ProjectedSolver` does not forward it."""

    @property
    def scan_kind(self):
        return getattr(self.solver, "scan_kind", None)
