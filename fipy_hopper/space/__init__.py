"""The 3D Eulerian model of a circular silo (or a rectangular bin): the same physics as the
sections (:mod:`fipy_hopper.model`) on a fixed Cartesian grid, run by the shared loop
(:class:`fipy_hopper.simulation.Simulation`) for a configuration with ``[hopper] dimensions = 3``
(``fipy-hopper run``, ``fipy_hopper.run``).

Coordinates ``(x, y, z)`` in m, ``z`` up, the outlet plane ``z = 0``, the silo's axis the
line ``x = y = 0``; an off-centre outlet lies on ``+x``.  Arrays of cells are ``(nz, ny, nx)``
(C order: FiPy's ``Grid3D`` numbering ``i + nx j + nx ny k``), of nodes ``(nz + 1, ny + 1,
nx + 1)``; SI units throughout.

Modules:

* ``config``: :class:`SpaceConfig`, the 3D run's settings (the sections' dataclasses and the
  outlet offset and mirror planes);
* ``boundary``: :class:`SiloBoundary`, the silo in 3D as data (signed distance, normals,
  contact entries) from the sections' wall profile revolved about the axis; ``silo_boundary``
  the silo of a configuration, circular or rectangular;
* ``rectangular``: :class:`RectangularSilo`, a rectangular plan (``plan = "rectangular"``) as
  data: its plane faces, exact distance, contact entries per face;
* ``grid``: :class:`SpaceGrid`, the FiPy ``Grid3D`` with cut-cell open fractions, face
  apertures and node distances/normals (:func:`build_grid`);
* ``momentum``: trilinear hexahedra with one-point quadrature, hourglass control, strain
  rate, spin, Jaumann rotation and the open divergence (numpy reference and compiled);
* ``transport``: the bounded van Leer transport on the 3D index grid (compiled), held to the
  numpy reference and to FiPy's ``VanLeerConvectionTerm`` on ``Grid3D``;
* ``contact``: the wall and plate constraints as data and the numpy reference of the contact;
* ``stepping``: the compiled material steps (forces, node update, contact, stress update,
  faces);
* ``model``: :class:`SpaceModel`, the model (initial state, steps, transport, masses; the
  model protocol of :mod:`fipy_hopper.protocol`);
* ``wall``: the wall's patches (height bins times sectors around the circumference, or
  across a rectangular plan's faces), the wall loads from the wall's
  reaction and the stresses, the vertical balance (:class:`SpaceWallLoads`) and the loop's
  view of them (:class:`PatchLoads`);
* ``flow``: the wall slip per sector, the flow-mode measures, the plane through the axis and
  the outlet, the flow channel;
* ``estimate``: the grid, memory and time of a run from its settings alone;
* ``output``, ``pictures``: the hexahedral snapshots; the 3D pictures.

What exists and what is tested: ``docs/three_d.md``.
"""
