"""Anatomy from images and templates, built on the finite-element engine.

* :mod:`~harpx.anatomy.segmentation`: hexahedral meshes and bodies from label volumes
  (:func:`~harpx.anatomy.segmentation.mesh_from_labels`).
* :mod:`~harpx.anatomy.ventricle`: the prolate-spheroidal left-ventricle template with
  fibres, AHA regions and named boundaries (:func:`~harpx.anatomy.ventricle.ventricle`).
* :mod:`~harpx.anatomy.ventricle_fit`: that template fitted to a segmentation (the names of
  :mod:`~harpx.anatomy.ventricle_template`, the placed template and its fit to contour
  points; :mod:`~harpx.anatomy.contours`, contour points of a mask; and
  :mod:`~harpx.anatomy.mask_fit`, the fit to a mask with its refusals and flags, which
  reads the mask as a stack of short-axis slices with :mod:`~harpx.anatomy.mask_slices`).
* :mod:`~harpx.anatomy.tongue_mesh`: the tongue with its muscles and fibre fields.

Units: mm.
"""
