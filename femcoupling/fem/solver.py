"""The solver side every FEM model shares: :class:`FemSolver`, and :func:`body_kind`, which
keeps a part of :class:`femcoupling.fem.model.FemModel` to the bodies it is for.

``FemSolver`` holds

- the Newton options (``newton_rtol``, ``max_newton``, ``noise_factor``, ``noise_ceiling``)
  that :func:`femcoupling.fem.quadrature.newton_solve` applies;
- the load-step loop (:meth:`FemSolver._load`: :func:`femcoupling.fem.steps.load_path`) and
  the rollback of a failed step (:meth:`FemSolver._rollback`);
- the record of the run: ``history`` (one :class:`~femcoupling.fem.steps.LoadStep` per
  accepted step), ``warnings`` (each also given as a
  :class:`~femcoupling.coupling.status.NoiseWarning`) and :attr:`FemSolver.status`.
"""

from __future__ import annotations

import functools
import warnings as _warnings
from typing import Any, Callable

from femcoupling._checks import FemInputError
from femcoupling.coupling.status import NoiseWarning, worst
from femcoupling.fem.steps import LoadStep, load_path

__all__ = ["FemSolver", "SOIL_ONLY", "body_kind"]

#: what a part of ``FemModel`` for the reinforced soil body says to a model of another body
SOIL_ONLY = ("a model of the reinforced soil body (femcoupling.fem.geometry.ReinforcedSoilBody); "
             "a body of femcoupling.fem.bodies is loaded by step()")


def body_kind(kind: str, what: str):
    """A class decorator: every public method and property of the class (a part of
    ``FemModel``) refuses, by name, a model whose ``_kind`` is not ``kind``; ``what`` says
    which bodies the part is for and what the others use instead."""

    def guard(name: str, f):
        @functools.wraps(f)
        def checked(self, *args, **kwargs):
            if self._kind != kind:
                raise FemInputError(f"{name}: {what} (this model's body: {self.body!r})")
            return f(self, *args, **kwargs)
        return checked

    def decorate(cls):
        for name, v in list(vars(cls).items()):
            if name.startswith("_"):
                continue
            if isinstance(v, property):
                setattr(cls, name, property(guard(name, v.fget),
                                            None if v.fset is None else guard(name, v.fset),
                                            doc=v.__doc__))
            elif callable(v) and not isinstance(v, (staticmethod, classmethod, type)):
                setattr(cls, name, guard(f"{name}()", v))
        return cls

    return decorate


class FemSolver:
    """The solver side of every model; see the module doc."""

    #: whether this process gives the run's warnings as NoiseWarning (a FemModel under MPI:
    #: rank 0 only; every warning is in ``warnings`` on every rank)
    _warns_here = True

    def _solver_options(self, *, newton_rtol: float, max_newton: int, noise_factor: float,
                        noise_ceiling: float) -> None:
        """The Newton options (checked by the subclass) and an empty record of the run."""
        self.newton_rtol, self.max_newton = newton_rtol, max_newton
        self.noise_factor, self.noise_ceiling = float(noise_factor), float(noise_ceiling)
        #: one record per accepted load step, in order
        self.history: list = []
        #: every warning of the run (also given as ``NoiseWarning``), in order
        self.warnings: list[str] = []

    @property
    def status(self) -> str:
        """The run's status so far: the worst of its accepted steps' ("converged" before
        any; :func:`femcoupling.coupling.status.worst`). A step that could not be accepted
        raised ``NewtonFailure``: the run failed."""
        return worst(r.status for r in self.history)

    def _reject_points(self) -> None:
        """The quadrature points' materials back at their accepted state (the soil body's
        materials hold nothing beyond their next trial: nothing to do)."""

    def _rollback(self) -> None:
        """Back to the last accepted step: the points' materials, and u to u_n."""
        self._reject_points()
        self.u.x.array[:] = self.u_n.x.array
        self.u.x.scatter_forward()

    def _load(self, take: Callable[[float], LoadStep], restore: Callable[[float], None], *,
              steps: int, max_cuts: int, where: str,
              accepted: Callable[[Any], None] | None = None) -> list:
        """A load from load factor 0 to 1 in ``steps`` increments by the one load-step loop
        (:func:`femcoupling.fem.steps.load_path`, with this model's rollback and
        ``max_newton``)."""
        return load_path(take, self._rollback, restore, steps=steps, max_cuts=max_cuts,
                         max_newton=self.max_newton, where=where, accepted=accepted)

    def _warn(self, msg: str, stacklevel: int = 2) -> None:
        """Keeps ``msg`` in ``warnings`` and gives it as a NoiseWarning (``stacklevel`` as
        for ``warnings.warn`` called where this is)."""
        self.warnings.append(msg)
        if self._warns_here:
            _warnings.warn(msg, NoiseWarning, stacklevel=stacklevel + 1)
