"""The solver side every FEM model of the package shares: :class:`FemModel`.

A model is a body (its mesh, boundary conditions and loads: the reinforced soil body of
:class:`femcoupling.fem.soil_model.SoilModel`; the rectangle, box and cylinder of the
hierarchical models in :mod:`femcoupling.coupling.hierarchical` and
:mod:`femcoupling.coupling.hierarchical3d`) with materials at its quadrature points, solved
by one machinery, which this class holds:

- the Newton options (``newton_rtol``, ``max_newton``, ``noise_factor``, ``noise_ceiling``)
  that :func:`femcoupling.fem.quadrature.newton_solve` applies;
- the load-step loop (:meth:`FemModel._load`: :func:`femcoupling.fem.steps.load_path`) and the
  rollback of a failed step (:meth:`FemModel._rollback`);
- the record of the run: ``history`` (one :class:`~femcoupling.fem.steps.LoadStep` per
  accepted step), ``warnings`` (each also given as a
  :class:`~femcoupling.coupling.status.NoiseWarning`) and :attr:`FemModel.status`.

The subclass builds its body and its ``system``
(:class:`femcoupling.fem.quadrature.QuadratureSystem`: ``u`` and ``u_n``) and calls
:meth:`FemModel._solver_options` in its constructor.
"""

from __future__ import annotations

import warnings as _warnings
from typing import Any, Callable

from femcoupling.coupling.status import NoiseWarning, worst
from femcoupling.fem.steps import LoadStep, load_path


class FemModel:
    """See the module doc."""

    #: whether this process gives the run's warnings as NoiseWarning (the hierarchical
    #: models under MPI: rank 0 only; every warning is in ``warnings`` on every rank)
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
