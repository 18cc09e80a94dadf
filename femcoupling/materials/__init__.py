"""The materials of the FEM models: what a quadrature point, a cell or a region is made of.

- :mod:`femcoupling.materials.continuum`: the continuum laws (``LinearElastic``,
  ``AnisotropicElastic``, ``DruckerPrager`` and its return mapping, ``GeogridLayerMaterial``),
  Mandel algebra, and the laws at quadrature points (``ElasticPoints``,
  ``DruckerPragerPoints``). Pure NumPy.
- :mod:`femcoupling.materials.dem_elements`: DEM elements as materials: one periodic element
  for a region (``DemRegionMaterial``, ``PeriodicRegionElement``), an element per cell on the
  one pool (``PoolRegionMaterials``), the reinforced band element (``ReinforcedBandElement``).

Every one of them implements ``femcoupling.fem.quadrature.QuadratureMaterial`` (trial,
commit, state, set_state). Import the modules directly; this namespace imports nothing.
"""
