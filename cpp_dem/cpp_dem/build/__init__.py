"""What goes into a scene: packings and particle-size distributions (`packing`, `psd`), clumps
and clump templates from sphere lists or surface meshes (`clumps`, `clump_mesh`), and
geogrids: beam-linked nodes with cylinders and PFacets (`geogrid`) or woven grids of bonded
spheres (`woven`)."""
