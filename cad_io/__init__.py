"""Everything that touches a CAD kernel: STEP reading, NURBS evaluation, z-map sampling."""
