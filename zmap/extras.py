"""The light core and its optional extras: which extra installs which module.

``pip install zmap`` gives the core: z-maps, Bezier heights, precision models, G-code, the
cutting simulation and its history, the drop-cutter, verification against a z-map or a
precision model, and the map pictures (numpy, scipy, numba, matplotlib). The extras add:

* ``cad``: STEP parts (cadquery's OCP kernel) and geomdl NURBS, so ``zmap convert``,
  ``refine``, ``report``, ``access`` and a STEP design anywhere;
* ``view``: 3D pictures and meshes (pyvista) and the web viewer (trame);
* ``tiled``: tiled z-maps in zarr stores and work on Dask;
* ``all``: every one of them (``make demo`` and ``make test`` install it).

Examples
--------
>>> extra_for("OCP.TopoDS"), extra_for("zarr"), extra_for("numpy") is None
('cad', 'tiled', True)
"""

from __future__ import annotations

__all__ = ["EXTRAS", "extra_for", "missing_extra_message"]

#: extra -> the top-level modules it installs that the code imports
EXTRAS = {
    "cad": ("cadquery", "OCP", "geomdl"),
    "view": ("pyvista", "vtk", "vtkmodules", "trame", "trame_vtk", "trame_vuetify", "trame_pyvista"),
    "tiled": ("dask", "distributed", "zarr"),
}


def extra_for(module: str) -> str | None:
    """The extra that installs ``module`` (a dotted name), or None for the core's and others'."""
    top = module.split(".")[0]
    return next((extra for extra, modules in EXTRAS.items() if top in modules), None)


def missing_extra_message(exc: BaseException, what: str) -> str | None:
    """One line saying which extra ``what`` needs, for a ModuleNotFoundError of an extra's
    module (None for any other error).

    Examples
    --------
    >>> missing_extra_message(ModuleNotFoundError("No module named 'zarr'", name="zarr"), "zmap info")
    "zmap info needs zarr, which the 'tiled' extra installs: pip install 'zmap[tiled]'"
    """
    name = getattr(exc, "name", None)
    if not isinstance(exc, ModuleNotFoundError) or not name:
        return None
    extra = extra_for(name)
    if extra is None:
        return None
    return f"{what} needs {name.split('.')[0]}, which the '{extra}' extra installs: pip install 'zmap[{extra}]'"
