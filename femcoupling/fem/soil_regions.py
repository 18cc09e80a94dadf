"""The regions of :class:`femcoupling.fem.model.FemModel` with a material of their own: an
elastic or anisotropic material, one DEM element for a region (its mean strain in, its
stress and tangent out), or an element per cell. A part of ``FemModel`` for the soil body: the methods use its
mesh, spaces and state."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from cpp_dem import fixedorder

from femcoupling._checks import FemInputError
from femcoupling.fem import geometry as geo
from femcoupling.fem.mpi_points import PointPartition, bcast_from_root, check_on_root
from femcoupling.fem.quadrature import NewtonFailure, check_material
from femcoupling.fem.solver import SOIL_ONLY, body_kind
from femcoupling.materials.continuum import (LinearElastic, mandel_to_tensor, stiffness_block,
                                             tensor_to_mandel)


class RegionPoints:
    """The quadrature points of one element region (or cell) whose stress a DEM element gives
    (a ``femcoupling.fem.quadrature.QuadratureMaterial`` on those points): ``element`` (a
    ``femcoupling.materials.dem_elements.DemRegionMaterial``, or a member of a
    ``PoolRegionMaterials``, whose ``group`` evaluates, commits and saves its members at once) gets
    the points' volume-mean strain increment (``weights``, summing to 1); each point takes its
    committed stress (``stress_pa``) plus the element's stress increment, plus the element's tangent
    times the point's deviation from that mean (so the region's mean stress is the element's, and
    the pointwise tangent is the consistent Jacobian: with the mean alone every point would depend
    on every other one, and Newton converged linearly, 15 % per iteration); ``key``: the
    model's name of the element (a group's member key). The points never
    yield (``plastic`` is 0). ``commit``, ``state`` and ``set_state`` are those of the points'
    stress; the model commits and saves the element (or its group) once. The points take
    Mandel strain increments (``strain_measure``); the element, the region's mean as a
    tensor (its ``strain_measure`` is "tensor"), and it answers with its total stress: its
    increment is that less its committed stress (``stress_n``)."""

    strain_measure = "mandel"

    def __init__(self, element: Any, weights: np.ndarray, stress_pa: np.ndarray,
                 ncomp: int, key: str = "") -> None:
        self.element, self.weights, self.ncomp, self.key = element, weights, ncomp, key
        self.stress_n = np.array(stress_pa, float)
        self.stress = self.stress_n.copy()
        self.plastic = np.zeros(len(self.stress_n))

    def mean(self, increment: np.ndarray) -> np.ndarray:
        """The points' volume-mean strain increment (ncomp,)."""
        return fixedorder.weighted_rows(self.weights, increment)

    def _answer(self, increment: np.ndarray, mean: np.ndarray, answer: tuple):
        ds, c = answer
        c = stiffness_block(c, self.ncomp)
        self.stress = (self.stress_n + tensor_to_mandel(ds, self.ncomp)
                       + fixedorder.rows_matmul(increment - mean, c.T))
        return self.stress, np.broadcast_to(c, (len(self.stress),) + c.shape)

    @staticmethod
    def _increment(element: Any, answer: tuple) -> tuple:
        """The element's (stress increment, tangent) from its answer (total stress,
        tangent): the total less its committed stress."""
        total, c = answer
        return np.asarray(total, float) - element.stress_n, c

    def trial(self, increment: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The points' stress and tangent for their strain increments ((n, ncomp))."""
        mean = self.mean(increment)
        el = self.element
        return self._answer(increment, mean,
                            self._increment(el, el.trial(mandel_to_tensor(mean))))

    @staticmethod
    def _evaluate(sets: list, means: list) -> dict:
        """The elements' answers (stress increment, tangent) for the mean strain increments
        ``means`` of ``sets``, by set index: the members of one group (``trial_many``) at
        once."""
        answers: dict = {}
        units: dict = {}
        for k, (_, m) in enumerate(sets):
            unit = getattr(m.element, "group", None)
            if unit is None:
                answers[k] = RegionPoints._increment(
                    m.element, m.element.trial(mandel_to_tensor(means[k])))
            else:
                units.setdefault(id(unit), (unit, []))[1].append(k)
        for unit, ks in units.values():
            got = unit.trial_many({sets[k][1].key: mandel_to_tensor(means[k]) for k in ks})
            answers.update({k: RegionPoints._increment(sets[k][1].element,
                                                       got[sets[k][1].key]) for k in ks})
        return answers

    @staticmethod
    def trial_all(sets: list, deps: np.ndarray, sig: np.ndarray, tan: np.ndarray,
                  comm: Any = None) -> None:
        """The trial of every ``(indices, RegionPoints)`` of ``sets`` for the model's
        increments ``deps``, written into ``sig`` and ``tan`` (in place): the members of one
        group (``trial_many``) are evaluated at once.

        Under MPI (``comm`` of more than one rank) every rank holds a set for every element,
        in the same order, with its own points (the weights of its owned points; none on a
        rank without them): the means are summed over the ranks, the elements (on rank 0)
        answer, and their answers (or the ``NewtonFailure`` of one) reach every rank."""
        means = [m.mean(deps[idx]) for idx, m in sets]
        if comm is None or comm.size == 1:
            answers = RegionPoints._evaluate(sets, means)
        else:
            total = comm.allreduce(np.array(means).reshape(len(sets), -1))
            means = list(total)
            answers, err = None, None
            if comm.rank == 0:
                try:
                    answers = RegionPoints._evaluate(sets, means)
                except NewtonFailure as e:
                    err = str(e)
            answers, err = bcast_from_root(comm, (answers, err))
            if err is not None:
                raise NewtonFailure(err)
        for k, (idx, m) in enumerate(sets):
            sig[idx], tan[idx] = m._answer(deps[idx], means[k], answers[k])

    def commit(self) -> None:
        self.stress_n = self.stress.copy()

    def state(self) -> np.ndarray:
        return self.stress_n.copy()

    def set_state(self, data: np.ndarray) -> None:
        self.stress_n = np.array(data, float)
        self.stress = self.stress_n.copy()


@body_kind("soil", SOIL_ONLY)
class RegionMaterials:
    """See the module doc."""

    def set_region_material(self, name: str, material: LinearElastic) -> None:
        """Give the element region ``name`` a new material (two-way coupling)."""
        self.body.region_tag(name)
        if not isinstance(material, LinearElastic):
            raise FemInputError(f"material={material!r}: must be a LinearElastic")
        self.region_materials[name] = material
        self._set_point_materials()

    def set_region_element(self, name: str, element: Any) -> None:
        """The element region ``name`` takes its stress and tangent from a DEM element at
        every Newton iterate (the hierarchical mode on this body, one element for the
        region's cells): ``element`` (``femcoupling.materials.dem_elements.DemRegionMaterial``) gets
        the region's volume-mean strain increment since the start of the load step (3 x 3) and
        returns its stress increment (3 x 3, Pa) and tangent (6 x 6 Mandel, Pa), which every
        point of the region takes; a converged step commits it. The members of one
        ``femcoupling.materials.dem_elements.PoolRegionMaterials`` (several regions' elements on
        Dask workers) are evaluated at once, in parallel. Under MPI the element lives on rank 0
        (``element=None`` on the others: ``femcoupling.fem.mpi_points.on_root``); the region's
        mean is taken over all ranks. Collective."""
        tag = self.body.region_tag(name)
        self._add_element(name, element, np.repeat(self.cell_tag_of == tag, self.nq))

    # ---- the cells in the serial model's numbering (the same keys on any number of ranks)

    def _serial_cells(self) -> np.ndarray:
        """(n_cells,) each local cell's number in the serial model's mesh (its cell there at
        the same place; the serial mesh is built again on rank 0 under MPI). Serial: the
        local numbering. Raises RuntimeError if the ranks' cells are not the serial mesh's."""
        got = getattr(self, "_serial_cell_ids", None)
        if got is not None:
            return got
        if self.comm.size == 1:
            self._serial_cell_ids = np.arange(self.n_cells)
            return self._serial_cell_ids
        from scipy.spatial import cKDTree

        serial = None
        if self.comm.rank == 0:
            fx = self._fx
            mb = geo.build_mesh(self.body, comm=fx.MPI.COMM_SELF)
            g, n = mb.mesh.geometry, mb.mesh.topology.index_map(self.tdim).size_local
            serial = g.x[g.dofmaps[0][:n]].mean(axis=1)
        serial = self.comm.bcast(serial, root=0)
        centres = self._cell_centres()
        size = max(self.body.width_m, self.body.height_m)
        # the owned cells: each serial cell exactly once; the ghosts: at a serial cell's place
        self._cell_partition = PointPartition(self.comm, centres[: self.n_owned], serial, size,
                                              what="cells")
        dist, ghosts = cKDTree(serial).query(centres[self.n_owned:])
        if self.comm.allreduce(int(float(np.max(dist, initial=0.0)) > 1e-9 * size)):
            raise RuntimeError("the ranks' ghost cells are not the serial mesh's: a cell "
                               f"centre farther than {1e-9 * size:.3g} m from the nearest")
        self._serial_cell_ids = np.concatenate([self._cell_partition.ids,
                                                np.asarray(ghosts, np.int64)])
        return self._serial_cell_ids

    def _serial_cell_data(self, *arrays: np.ndarray) -> list:
        """Per-cell arrays (leading axis: the local cells) in the serial numbering, every
        serial cell once (from its owner), on every rank. Serial: the arrays themselves."""
        if self.comm.size == 1:
            return [np.asarray(a) for a in arrays]
        self._serial_cells()
        return [self._cell_partition.gather(np.asarray(a)[: self.n_owned]) for a in arrays]

    def cell_stresses(self, name: str) -> dict:
        """The converged stress of each cell of element region ``name``, by the key
        ``set_cell_elements`` gives that cell's element (``"<name>/<cell>"``): 3 x 3, Pa,
        tension positive (the cell's volume mean; where each cell's element takes over)."""
        tag = self.body.region_tag(name)
        tags, cms = self._serial_cell_data(self.cell_tag_of, self.cell_mean_stress())
        return {f"{name}/{c}": mandel_to_tensor(cms[c]) for c in np.flatnonzero(tags == tag)}

    def band_cells(self, name: str) -> dict:
        """The cells of the geogrid layers' bands inside element region ``name`` (their
        centres in its square, or cube), by the key ``set_cell_elements(band=True)`` gives
        their elements, ``"<name>-<layer name>/<cell>"`` -> the layer's index. (The bands'
        cells are not the region's: a layer's tag comes first.)"""
        reg = self.body.region(name)
        lo = np.asarray(reg.center_m, float) - reg.size_m / 2
        hi = lo + reg.size_m
        tags, centres = self._serial_cell_data(self.cell_tag_of, self._cell_centres())
        centres = centres[:, : len(lo)]
        inside = np.all((centres >= lo - 1e-12) & (centres <= hi + 1e-12), axis=1)
        out = {}
        for i, layer in enumerate(self.body.layers):
            label = layer.name or f"layer{i}"
            for c in np.flatnonzero(inside & (tags == geo.LAYER_TAG0 + i)):
                out[f"{name}-{label}/{c}"] = i
        return out

    def band_cell_states(self, name: str, reach_m: float) -> dict:
        """Where a reinforced RVE of each cell of :meth:`band_cells` (``name``) starts
        (``femcoupling.materials.dem_elements.ReinforcedBandElement``): key -> (the grains'
        pressure, Pa, compression positive: the volume mean of -tr(sigma)/3 over the region's soil
        cells whose centres are within ``reach_m`` (m) of the band cell's; the band's tension
        along x, N/m: the layer's thickness times the cell's sigma_xx)."""
        if not (isinstance(reach_m, (int, float)) and np.isfinite(reach_m) and reach_m > 0):
            raise FemInputError(f"reach_m={reach_m!r}: must be > 0 (m)")
        tags, cms, centres, volume = self._serial_cell_data(
            self.cell_tag_of, self.cell_mean_stress(), self._cell_centres(), self.cell_volume)
        centres = centres[:, : self.tdim]
        soil = np.flatnonzero(tags == self.body.region_tag(name))
        pressure = -cms[:, :3].sum(axis=1) / 3.0
        out = {}
        for key, i in self.band_cells(name).items():
            c = int(key.rsplit("/", 1)[1])
            near = soil[np.linalg.norm(centres[soil] - centres[c], axis=1) <= reach_m]
            if not near.size:
                raise FemInputError(f"reach_m={reach_m!r}: no soil cell of region {name!r} "
                                    f"within it of band cell {c}; give a larger reach")
            w = volume[near]
            out[key] = (fixedorder.dot(w, pressure[near]) / math.fsum(w),
                        float(self.body.layers[i].thickness_m * cms[c, 0]))
        return out

    def set_cell_elements(self, name: str, group: Any, *, band: bool = False) -> list:
        """Every cell of element region ``name`` takes its stress and tangent from its own
        DEM element (the hierarchical mode at the cells' scale; with P1 cells, one
        quadrature point each, an element per quadrature point). ``group`` holds one element
        per cell under the keys of :meth:`cell_stresses` (``femcoupling.materials.dem_elements.
        PoolRegionMaterials.build(m.cell_stresses(name), runner, workers=)``: all of them
        evaluated at once on Dask workers at every Newton iterate); each cell is then what
        :meth:`set_region_element` makes of a region: its element gets the cell's mean strain
        increment, and the cell's points take its answer. ``band``: the geogrid bands' cells
        inside the region too (:meth:`band_cells`; their elements reinforced RVEs,
        ``PoolRegionMaterials.build(band=)``). Returns the keys.

        Under MPI the keys are the serial model's (``<cell>`` numbers the serial mesh's cell
        at the same place), so each cell gets the same element, and seed, on any number of
        ranks; ``group`` lives on rank 0 (None on the others). Collective."""
        keys = list(self.cell_stresses(name)) + (list(self.band_cells(name)) if band else [])
        on_root = self.comm.size == 1 or self.comm.rank == 0
        if self.comm.size > 1:
            check_on_root(self.comm, group)
        members = getattr(group, "materials", None)
        missing = [k for k in keys if members is None or k not in members] if on_root else []
        if self.comm.size > 1:
            missing = self.comm.bcast(missing, root=0)
        if missing:
            raise FemInputError(f"group={group!r}: needs an element (in its .materials) for "
                                f"every cell of region {name!r}"
                                + (" and of its bands" if band else "")
                                + f"; missing {missing[:5]}"
                                + (" ..." if len(missing) > 5 else ""))
        serial = self._serial_cells()
        for k in keys:
            on = serial == int(k.rsplit("/", 1)[1])
            self._add_element(k, members[k] if on_root else None, np.repeat(on, self.nq),
                              _checked=True)
        self._set_point_materials()
        return keys

    def _add_element(self, key: str, element: Any, sel: np.ndarray, *,
                     _checked: bool = False) -> None:
        """``element`` answers for the quadrature points ``sel`` (their volume mean strain:
        the weights of the owned points, summed to 1 over the ranks; a ghost point takes the
        answer with a weight of 0). ``_checked``: the caller checked the element's rank and
        sets the points' materials once for all its elements."""
        if self.comm.size > 1 and not _checked:
            check_on_root(self.comm, element)
        if element is not None or self.comm.size == 1:
            check_material(element, "element", "tensor")
        self.region_elements[key] = element
        self._region_form = None  # (the regions' cells changed)
        w = (self.cell_volume[:, None] * self.qweights[None, :]).reshape(-1)[sel]
        if self.comm.size == 1:
            total = w.sum()
        else:
            owned = np.repeat(np.arange(self.n_cells) < self.n_owned, self.nq)[sel]
            w = np.where(owned, w, 0.0)
            total = self.comm.allreduce(float(w.sum()))
        if not total > 0:
            raise FemInputError(f"region element {key!r}: its cells have no volume")
        self._element_points[key] = (sel, w / total)  # its points and volume weights
        if not _checked:
            self._set_point_materials()  # (its points leave their tag's material)

    def _element_units(self) -> list:
        """(unit, region names): each region element once, except the members of one group
        (``femcoupling.materials.dem_elements.PoolRegionMaterials``: an element's ``group``), which
        the group evaluates, commits and saves at once. Under MPI, the elements on rank 0 (none on
        the others)."""
        if self.comm.size > 1 and self.comm.rank != 0:
            return []
        units: dict = {}
        for name, el in self.region_elements.items():
            unit = getattr(el, "group", el)
            units.setdefault(id(unit), (unit, []))[1].append(name)
        return list(units.values())
