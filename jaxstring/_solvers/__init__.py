"""Time integrators: the registry of named solvers and the project's
own stiff solvers (BDF, Rodas5P, the papers' fixed-step methods, the banded stage
Newton of the Kvaerno methods), written as diffrax solvers.

The submodules are imported where used (`names` alone imports neither diffrax
nor a solver: `jaxstring._lazy`)."""
