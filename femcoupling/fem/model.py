"""The FEM model of the package: :class:`FemModel`, one class for every body, with materials
at its quadrature points (docs/fem.md, docs/coupling_hierarchical.md).

The body chooses the mesh, the boundary conditions and how the model is loaded:

- the reinforced soil body (:class:`femcoupling.fem.geometry.ReinforcedSoilBody`, plane
  strain or 3D, with geogrid layers and element regions): continuum materials at its points
  (``soil=``, ``layers=``, ``region_materials=``; DEM elements for a region or each of its
  cells), loaded by its stages (``set_geostatic``, ``apply_prestress``, ``load_footing``,
  ``load_footing_to_pressure``); the part :class:`femcoupling.fem.soil_body.SoilPart` and its
  roles (:mod:`~femcoupling.fem.soil_loading`, :mod:`~femcoupling.fem.soil_regions`,
  :mod:`~femcoupling.fem.soil_measures`);
- a body of :mod:`femcoupling.fem.bodies` (``Rectangle``: plane strain with smooth, rough or
  footing platens; ``Box``; ``Cylinder``) with a DEM element at every quadrature point
  (``elements=``), loaded by :meth:`FemModel.step`: the hierarchical mode, below; the part
  :class:`femcoupling.fem.element_body.ElementPart`.

A method of one kind of body called on a model of the other is refused by name
(``FemInputError``). Every model shares the solver side
(:class:`femcoupling.fem.solver.FemSolver`): the Newton options, the one load-step loop, the
rollback, ``history``, ``warnings`` and ``status``; and the one Newton
(:func:`femcoupling.fem.quadrature.newton_solve`).

**The hierarchical mode.** A body of :mod:`femcoupling.fem.bodies` with a DEM element at every
quadrature point (``elements``: an ``ElementPool``
with one element per point; point k is cell k // nq, point k % nq): the hierarchical mode. The
elements are the points' material
(:class:`femcoupling.materials.element_pool.ElementPoolMaterial`, whose strain measure is the
displacement gradient). In a load step (:meth:`FemModel.step`) Newton iterates:

1. the displacement-gradient increment since the start of the step, grad(u) - grad(u_n), at
   every quadrature point (shear and rotation included; in plane strain the FEM's (x, y) is
   the element's (x, z), and its out-of-plane y is held);
2. every element is restored to the start of the step (a rejected iterate leaves no trace)
   and takes that increment; it returns its stress and its network tangent;
3. the residual and the Jacobian are assembled from them (Voigt with engineering shear),
   and the displacements are corrected.

An accepted step is saved (every element's state kept as bytes). Each step ends in a status
(:mod:`femcoupling.coupling.status`): ``converged`` (the residual within ``newton_rtol``) or
``stopped_at_scatter`` (``convergence="noise"``: Newton stalled above ``newton_rtol`` with
the residual within ``noise_factor`` times the elements' measured noise and within the
``noise_ceiling``, 10 x ``newton_rtol`` by default). A step whose residual is within the
noise but above the ceiling is cut, as a step Newton fails (``NewtonFailure``; a step that
still fails after its cuts raises it: the run has ``failed``). The residual is relative to
the internal force scale (the largest element stress times the body's ``scale_length``: the
square root of the area in 2D, the volume to the power 2/3 in 3D) and also given in stress
units (``LoadStep.residual_pa``, Pa). Newton and its rules are
:func:`femcoupling.fem.quadrature.newton_solve`, the soil body's
(:class:`femcoupling.fem.model.FemModel`) too.

Stresses are tension positive, Pa. The FEM is serial, or, with ``comm`` (an mpi4py
communicator, ``mpiexec -n N``), split over its ranks with the elements' pool on rank 0
(``elements=None`` on the others; :mod:`femcoupling.fem.mpi_points`): element k is the same
place on any number of ranks. Records (``out=DIR``):
:class:`femcoupling.coupling.records.ElementRecords`.
"""

from __future__ import annotations

import inspect

from femcoupling._checks import FemInputError, _max_newton, _newton_rtol
from femcoupling.fem import geometry as geo
from femcoupling.fem.element_body import ElementPart
from femcoupling.fem.soil_body import SoilPart
from femcoupling.fem.soil_loading import LoadingStages
from femcoupling.fem.soil_measures import SoilMeasures
from femcoupling.fem.soil_regions import RegionMaterials
from femcoupling.fem.solver import FemSolver

__all__ = ["FemModel", "FemSolver", "split_options"]

#: the keyword arguments of each kind of body (``FemModel``'s others are refused with it)
_SOIL_ARGS = ("soil", "layers", "region_materials", "unit_weight_n_m3", "degree", "max_cuts")
_ELEMENT_ARGS = ("elements", "tangent", "strain_kw", "convergence", "relaxation",
                 "noise_factor", "noise_ceiling", "nonlocal_length", "nonlocal_weight",
                 "verbose", "out", "overwrite")
_BODY_HOOKS = ("mesh", "bcs", "loads", "target", "apply", "scale_length")


def split_options(body_type, options: dict) -> tuple[dict, dict]:
    """``options`` split into the keyword arguments of ``body_type`` (a body class of
    :mod:`femcoupling.fem.bodies`) and the rest (:class:`FemModel`'s): for a caller that takes
    both in one ``**kw``."""
    names = set(inspect.signature(body_type).parameters)
    return ({k: v for k, v in options.items() if k in names},
            {k: v for k, v in options.items() if k not in names})


def _check_comm(comm) -> None:
    """``comm``: None or an mpi4py communicator (anything with its ``rank`` and ``size``),
    else FemInputError."""
    if comm is not None and not all(hasattr(comm, a) for a in ("rank", "size")):
        raise FemInputError(f"comm={comm!r}: an mpi4py communicator (e.g. MPI.COMM_WORLD), "
                            "or None")


class FemModel(SoilPart, RegionMaterials, LoadingStages, SoilMeasures, ElementPart, FemSolver):
    """A body with materials at its quadrature points, solved in dolfinx; see the module doc.
    Collective on ``comm``.

    Args:
        body: a ``femcoupling.fem.geometry.ReinforcedSoilBody``, or a body of
            :mod:`femcoupling.fem.bodies` (``Rectangle``, ``Box``, ``Cylinder``).
        newton_rtol: Newton's tolerance (the soil body: |R| <= newton_rtol |F_int| over the
            free dofs, default 1e-8; the bodies with elements: relative to the internal force
            scale, default 1e-3), -, in (0, 1e-2].
        max_newton: iterations before a step is cut, a whole number >= 1 (default 25; with
            elements 10).
        comm: mpi4py communicator (the soil body: default COMM_WORLD; with elements: None,
            serial).

    The reinforced soil body's:
        soil: the soil's material (``LinearElastic``, ``AnisotropicElastic``,
            ``DruckerPrager``).
        layers: one ``GeogridLayerMaterial`` per geogrid layer of ``body``.
        region_materials: optional material per element-region name (default: ``soil``).
        unit_weight_n_m3: soil unit weight gamma, N/m^3, >= 0 (0: weightless).
        degree: displacement degree (1 or 2; default 2).
        max_cuts: step halvings before ``NewtonFailure``, a whole number in [0, 20]
            (default 6).

    A body of :mod:`femcoupling.fem.bodies`'s:
        elements: an ``ElementPool`` with one element per quadrature point (under MPI on
            rank 0, None on the others).
        tangent: the elements' tangent in the Jacobian
            (:data:`femcoupling.materials.element_pool.TANGENTS`; "secant" in plane strain
            only; default "network").
        strain_kw: keyword arguments of every element's ``apply_strain``.
        convergence: "noise" (default: ``newton_rtol``, or, when Newton stalls above it,
            within the elements' measured noise) or "tolerance" (``newton_rtol`` only).
        relaxation: of Newton's corrections: "aitken" (default), "none" or a factor in (0, 1].
        noise_factor: a stalled step is accepted within this many times the elements'
            measured noise (default 2) ...
        noise_ceiling: ... and only up to this residual (relative, like ``newton_rtol``;
            default 10 x ``newton_rtol``), above which the step is cut.
        nonlocal_length: the elements strained by a mean of the strain around them over this
            length, m (:mod:`femcoupling.fem.nonlocal_strain`: a shear band's width set by
            it, not by the mesh); None (default): each by its own point's.
        nonlocal_weight: the averaged strain's share, in (0, 1] (default 1).
        verbose: a line per Newton iteration (rank 0).
        out: the records' folder (None: none); ``overwrite``: replace an earlier run's.
    """

    def __init__(self, body, *, newton_rtol: float | None = None,
                 max_newton: int | None = None, comm=None, **options) -> None:
        given = {k: v for k, v in (("newton_rtol", newton_rtol), ("max_newton", max_newton))
                 if v is not None}
        if newton_rtol is not None:
            _newton_rtol(newton_rtol)
        if max_newton is not None:
            _max_newton(max_newton)
        _check_comm(comm)
        if isinstance(body, geo.ReinforcedSoilBody):
            self._kind = "soil"
            self.body = body
            self._refuse(options, _SOIL_ARGS, "the reinforced soil body")
            self._build_soil(body, comm=comm, **given, **options)
        elif all(callable(getattr(body, h, None)) for h in _BODY_HOOKS):
            self._kind = "elements"
            self.body = body
            self._refuse(options, _ELEMENT_ARGS, f"a {type(body).__name__}")
            if "elements" not in options:
                raise FemInputError(f"elements: missing; a {type(body).__name__}'s points are "
                                    "DEM elements: an ElementPool with one per point")
            self._build_elements(body, comm=comm, **given, **options)
        else:
            raise FemInputError(f"body={body!r}: a femcoupling.fem.geometry.ReinforcedSoilBody "
                                "or a body of femcoupling.fem.bodies (Rectangle, Box, "
                                "Cylinder)")

    @staticmethod
    def _refuse(options: dict, allowed: tuple, body: str) -> None:
        """A keyword argument of the other kind of body, or none at all, is refused by name."""
        for k in options:
            if k not in allowed:
                other = ("a body of femcoupling.fem.bodies'" if k in _ELEMENT_ARGS else
                         "the reinforced soil body's" if k in _SOIL_ARGS else None)
                raise FemInputError(
                    f"{k}: not an argument of FemModel on {body}"
                    + (f" (it is {other})" if other else "")
                    + f"; its own: newton_rtol, max_newton, comm, {', '.join(allowed)}")

    def __repr__(self) -> str:
        if self._kind == "elements":
            return f"FemModel({self.body!r}, {self.n_points} elements)"
        return f"FemModel({self.body!r})"

    @property
    def _warns_here(self) -> bool:
        """With elements under MPI, rank 0 gives the warnings (every rank keeps them)."""
        return self._root if self._kind == "elements" else True

    def _reject_points(self) -> None:
        """The points' materials back at their accepted state (``FemSolver._rollback``): the
        elements (the soil body's materials hold nothing beyond their next trial)."""
        if self._kind == "elements":
            self.material.reject()

    def footing_pressure_pa(self) -> float:
        """The footing's mean pressure, Pa, compression positive: the soil body's (the reaction
        in displacement control, the applied pressure in load control) or a ``Rectangle``'s
        with ``platens="footing"`` (the reaction at its vertical displacement dofs over its
        half width); both sum the reaction by ``QuadratureSystem.reaction``."""
        if self._kind == "elements":
            return self.body.footing_pressure_pa(self)
        return SoilMeasures.footing_pressure_pa(self)

    def footing_settlement_m(self) -> float:
        """The footing's settlement, m, positive down: the soil body's mean footing
        displacement, or a ``Rectangle``'s (``platens="footing"``) imposed one."""
        if self._kind == "elements":
            return self.body.footing_settlement_m(self)
        return SoilMeasures.footing_settlement_m(self)
