"""DEM region elements of the reinforced soil body under MPI, run by
tests/test_soil_body_mpi.py as ``mpiexec -n N python tests/mpi_soil_regions.py OUT [dem]``.

A 4 x 3 m elastic body (P1) with two element regions: region a has an element per cell
(``set_cell_elements``), region b one element (``set_region_element``). The elements are
linear stand-ins whose stiffness depends on the key they are given (the serial cell number),
held on rank 0 as a group that answers all its members at once (``trial_many``, as
``femcoupling.materials.dem_elements.PoolRegionMaterials``). A footing pressure of 100 kPa in 2
steps. With ``dem``: region a's cells take periodic DEM elements of 40 grains on a 1-worker Dask
pool instead, under 20 kPa in one step. Rank 0 writes OUT/result.json."""

import json
import sys

import numpy as np


def _stiffness(key: str) -> np.ndarray:
    """A transversely isotropic stiffness (Mandel 6 x 6, Pa), scaled by the key's cell."""
    from femcoupling.materials.continuum import mandel_identity

    cell = int(key.rsplit("/", 1)[1]) if "/" in key else 0
    k, g = 30e6 * (1.0 + 0.05 * (cell % 7)), 12e6
    i = mandel_identity(6)
    c = 3 * k * np.outer(i, i) / 3 + 2 * g * (np.eye(6) - np.outer(i, i) / 3)
    c[2, 2] *= 1.5
    return c


class StandInGroup:
    """Linear elements behind the pool's group interface: ``materials[key]`` a member whose
    ``group`` answers every member at once; counts its calls and commits."""

    class Member:
        strain_measure = "tensor"
        plastic = np.zeros(1)

        def __init__(self, group, key):
            self.group, self.key = group, key

        @property
        def stress_n(self):
            return self.group.committed[self.key]

        def trial(self, de):
            return self.group.trial_many({self.key: de})[self.key]

        def commit(self):
            self.group.commit()

        def state(self):
            return self.group.state()

        def set_state(self, data):
            self.group.set_state(data)

    def __init__(self, keys):
        self.materials = {k: StandInGroup.Member(self, k) for k in keys}
        self.calls = self.commits = 0
        self.committed = {k: np.zeros((3, 3)) for k in keys}  # Pa
        self._trial = dict(self.committed)

    def trial_many(self, increments):
        from femcoupling.materials.continuum import mandel_to_tensor, tensor_to_mandel

        self.calls += 1
        out = {}
        for k, de in increments.items():
            c = _stiffness(k)
            self._trial[k] = self.committed[k] + mandel_to_tensor(c @ tensor_to_mandel(de, 6))
            out[k] = (self._trial[k], c)
        return out

    def commit(self):
        self.commits += 1
        self.committed = dict(self._trial)

    def state(self):
        return dict(self.committed)

    def set_state(self, data):
        self.committed, self._trial = dict(data), dict(data)


class StandIn(StandInGroup):
    """One linear element (``femcoupling.materials.dem_elements.DemRegionMaterial``'s interface: no
    ``group``, evaluated alone)."""

    strain_measure = "tensor"
    plastic = np.zeros(1)

    def __init__(self, key):
        super().__init__([key])
        self.key = key

    @property
    def stress_n(self):
        return self.committed[self.key]

    def trial(self, de):
        return self.trial_many({self.key: de})[self.key]


def main(out: str, dem: bool) -> None:
    from femcoupling.fem.geometry import ElementRegion, ReinforcedSoilBody
    from femcoupling.fem.mpi_points import on_root, world
    from femcoupling.fem.model import FemModel
    from femcoupling.materials.continuum import LinearElastic

    comm = world()
    body = ReinforcedSoilBody(width_m=4.0, height_m=3.0, footing_half_width_m=0.5,
                              regions=(ElementRegion("a", (0.25, 2.7), 0.2),
                                       ElementRegion("b", (0.75, 2.4), 0.2)),
                              mesh_size_m=0.6, fine_size_m=0.1)
    m = FemModel(body, soil=LinearElastic(50e6, 0.3), unit_weight_n_m3=18e3, degree=1,
                  comm=comm)
    m.set_geostatic()
    stresses = m.cell_stresses("a")
    keys = list(stresses)
    res = {"ranks": comm.size, "keys": keys,
           "cell_stresses_pa": [v.tolist() for v in stresses.values()]}
    pool = None
    if dem:
        from femcoupling.materials.dem_elements import PeriodicRegionElement, PoolRegionMaterials

        group = on_root(comm, lambda: PoolRegionMaterials.build(
            stresses, PeriodicRegionElement(n=40, seed=3, tol=0.02, unbalanced=1e-2),
            workers=1, distinct_seeds=True, records=f"{out}/cells.h5"))
        pool = group
        load = dict(pressure_pa=20e3, steps=1)
    else:
        group = on_root(comm, lambda: StandInGroup(keys))
        load = dict(pressure_pa=100e3, steps=2)
    try:
        assert m.set_cell_elements("a", group) == keys
        if not dem:
            m.set_region_element("b", on_root(comm, lambda: StandIn("b")))
        elif comm.rank == 0:  # (the elements as prepared: the same seeds, the same packings)
            res["start_stresses_pa"] = [np.asarray(s).tolist() for s in group.stresses()]
        s0 = m.region_stress("a")
        steps = m.load_footing(**load)
        res.update(
            newton=[r.newton_iterations for r in steps],
            status=[r.status for r in steps],
            settlement_m=m.footing_settlement_m(),
            region_a_pa=(m.region_stress("a") - s0).tolist(),
            region_b_pa=m.region_stress("b").tolist(),
            cell_stresses_after_pa=[v.tolist() for v in m.cell_stresses("a").values()],
            point_stress_pa=m.point_stress([[0.25, 2.7], [0.75, 2.4]]).tolist())
        if comm.rank == 0 and not dem:
            res["group_commits"] = group.commits
        if comm.rank == 0 and dem:
            res["element_stresses_pa"] = [np.asarray(s).tolist() for s in group.stresses()]
    finally:
        if pool is not None:
            pool.close()
    if dem and comm.rank == 0:
        import h5py

        with h5py.File(f"{out}/cells.h5") as f:  # (the records, written by rank 0)
            res["records"] = {"names": [str(n) for n in f.attrs["names"]],
                              "step": f["step"][:].tolist()}
    root_only = ("group_commits", "element_stresses_pa", "records", "start_stresses_pa")
    every = comm.gather({k: v for k, v in res.items() if k not in root_only}, root=0)
    if comm.rank == 0:
        res["same_on_every_rank"] = all(
            r == {k: v for k, v in res.items() if k not in root_only} for r in every)
        with open(f"{out}/result.json", "w") as fh:
            json.dump(res, fh)
        print(f"on {comm.size} rank(s): {len(keys)} cell elements, status "
              f"{' '.join(res['status'])}")


if __name__ == "__main__":
    main(sys.argv[1], len(sys.argv) > 2 and sys.argv[2] == "dem")
