"""The FEM side: geometry, meshes and the models solved in dolfinx.

- :mod:`femcoupling.fem.geometry`: the reinforced soil body (2D or 3D) in gmsh, its tagged
  layers and element regions; :mod:`femcoupling.fem.gmsh_mesh`: gmsh on one rank, the mesh
  distributed by dolfinx;
- :mod:`femcoupling.fem.model`: ``FemModel``, the one model: a body with materials at its
  quadrature points. Its parts: :mod:`~femcoupling.fem.soil_body` for the reinforced soil
  body (spaces, material state, Newton), with its roles :mod:`~femcoupling.fem.soil_loading`
  (the load stages), :mod:`~femcoupling.fem.soil_regions` (regions with a material of their
  own) and :mod:`~femcoupling.fem.soil_measures` (what it gives out);
  :mod:`~femcoupling.fem.element_body` for a body of :mod:`~femcoupling.fem.bodies`
  (``Rectangle``, ``Box``, ``Cylinder``) with a DEM element at every quadrature point (the
  hierarchical mode); :mod:`~femcoupling.fem.solver` (``FemSolver``), what every model is on
  its solver side: the Newton options, the load-step loop, the rollback of a failed step,
  the run's history, warnings and status;
- :mod:`femcoupling.fem.steps`: what a load step of every model ends in: its record
  (``LoadStep``, the same Newton fields in every model) or ``NewtonFailure`` (the one failure
  type), and the one load-step loop (``load_path``);
- :mod:`femcoupling.fem.quadrature`: the material interface at quadrature points, the spaces
  and forms, and the one Newton with its acceptance rules;
- :mod:`femcoupling.fem.nonlocal_strain`: the elements strained by a mean of the strain
  around them (a length for a softening body of DEM elements);
- :mod:`femcoupling.fem.mpi_points`: quadrature points split over MPI ranks, their materials
  on rank 0;
- :mod:`femcoupling.fem.elastic_block`: the toolchain check (a linear-elastic block against
  its closed form).

dolfinx, PETSc and MPI come from :mod:`femcoupling._dolfinx` on first use. Import the
modules directly; this namespace imports nothing.
"""
