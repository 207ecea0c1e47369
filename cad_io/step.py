"""Read a STEP file into a :class:`~cad_io.part.Part`: exact NURBS faces, trim loops, edges.

Every face's surface becomes an exact (rational) B-spline: B-spline faces are taken as they
are; planes, cylinders, cones, spheres, tori, surfaces of revolution and extrusion, offsets
and Bezier faces are converted face by face with OpenCASCADE's ``BRepBuilderAPI_NurbsConvert``
(which also rewrites their pcurves in the new parameters). Periodic B-splines are cut to the
face's parameter range and made non-periodic (knot insertion, exact) with their parameter
values kept, so pcurves, trim loops and mesh (u, v) stay valid. Trim loops sample the
faces' pcurves until the uv polygon is within :data:`LOOP_TOL` mm (measured on the surface)
of the true boundary. Edges carry their adjacent faces and the largest angle between the
faces' outward normals along them.

OCP is imported inside the functions, so importing this module is cheap.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Callable

import numpy as np

from cad_io.part import Edge, Face, NurbsSurface, Part
from zmap.errors import StepImportError

__all__ = ["EDGE_DEFLECTION", "LOOP_TOL", "read_step"]

#: Largest distance (mm, on the surface) between a trim loop's uv polygon and the face's
#: true boundary.
LOOP_TOL = 1e-4
#: Chordal deflection (mm) of the polylines in ``Edge.points``.
EDGE_DEFLECTION = 1e-3
#: Samples along an edge for its dihedral angle.
_DIHEDRAL_SAMPLES = 9

_KIND_NAMES = {
    "GeomAbs_Plane": "plane", "GeomAbs_Cylinder": "cylinder", "GeomAbs_Cone": "cone",
    "GeomAbs_Sphere": "sphere", "GeomAbs_Torus": "torus", "GeomAbs_BezierSurface": "bezier",
    "GeomAbs_BSplineSurface": "bspline", "GeomAbs_SurfaceOfRevolution": "revolution",
    "GeomAbs_SurfaceOfExtrusion": "extrusion", "GeomAbs_OffsetSurface": "offset",
    "GeomAbs_OtherSurface": "other",
}


# --------------------------------------------------------------------------------------
# reading


#: Types of STEP entities whose load or transfer errors can touch the shape: geometry,
#: topology and the representations that hold them. Errors on others (presentation, PMI,
#: properties: AP242 files carry them by the dozen, nist_ctc_02 and trj7 among them) are
#: not counted; syntax errors always are.
_SHAPE_ENTITIES = ("StepGeom_", "StepShape_", "StepRepr_DefinitionalRepresentation",
                   "StepRepr_ShapeRepresentationRelationship", "StepRepr_RepresentationRelationship",
                   "StepRepr_ItemDefinedTransformation", "StepRepr_MappedItem", "StepRepr_RepresentationMap")
_NOT_SHAPE = ("StepShape_DimensionalSize", "StepShape_DimensionalLocation", "StepShape_ShapeDimension",
              "StepShape_DimensionalCharacteristic", "StepShape_ShapeDefinitionRepresentation")
_FACE_ENTITIES = ("StepShape_AdvancedFace", "StepShape_FaceSurface")


class _QuietFd:
    """Point the process's file descriptor ``fd`` (1: stdout) at a temporary file while in
    the block: OpenCASCADE writes its messages (coloured, from C++) straight to stdout,
    which must stay clean for our own output. ``text`` holds what was caught."""

    def __init__(self, fd: int = 1):
        self.fd = fd
        self.text = ""

    def __enter__(self):
        import sys
        import tempfile

        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (AttributeError, ValueError, OSError):
                pass
        self._tmp = tempfile.TemporaryFile()
        try:
            self._saved = os.dup(self.fd)
        except OSError:  # no such descriptor (a daemon, an embedded interpreter)
            self._saved = None
            return self
        os.dup2(self._tmp.fileno(), self.fd)
        return self

    def __exit__(self, *exc):
        if self._saved is not None:
            os.dup2(self._saved, self.fd)
            os.close(self._saved)
        self._tmp.seek(0)
        self.text = self._tmp.read().decode("utf-8", "replace")
        self._tmp.close()
        return False


def _damage(reader, shape) -> dict:
    """What the STEP reader lost: entities that failed to load (syntax errors, broken
    geometry or topology records) or to transfer, and faces of the file missing from the
    shape. Returns counts and the first few messages (entity label, type, OCC's words)."""
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp
    from OCP.TopTools import TopTools_IndexedMapOfShape

    from cad_io.damage import is_harmless

    model = reader.StepModel()
    first: list[str] = []
    notes: list[str] = []
    n_notes = [0]

    def label(ent, number: int) -> str:
        name = ent.DynamicType().Name().split("_", 1)[-1]
        try:
            ident = model.IdentLabel(model.Value(number))
        except Exception:  # noqa: BLE001 (OCCT errors share no base class in OCP)
            ident = 0
        return f"#{ident} {name}" if ident > 0 else f"entity {number} ({name})"

    def scan(checks) -> int:
        n = 0
        checks.Start()
        while checks.More():
            ch = checks.Value()
            if ch.HasFailed():
                ent = ch.Entity()
                name = ent.DynamicType().Name() if ent is not None else ""
                if ent is None or (name.startswith(_SHAPE_ENTITIES) and not name.startswith(_NOT_SHAPE)):
                    where = label(ent, checks.Number()) if ent is not None else "syntax"
                    if ent is not None and is_harmless([ch.CFail(j) for j in range(1, ch.NbFails() + 1)]):
                        # a fault that changes no face: a note, not damage
                        n_notes[0] += 1
                        if len(notes) < 3:
                            notes.append(f"{where}: {' '.join(ch.CFail(1).split())}")
                        checks.Next()
                        continue
                    k = ch.NbFails() if ent is None else 1  # syntax errors: one per bad record
                    n += k
                    if len(first) < 3:
                        first.append(f"{where}: {ch.CFail(1).strip()}")
            checks.Next()
        return n

    load_fails = scan(reader.WS().ModelCheckList())
    transfer_fails = scan(reader.WS().TransferReader().TransientProcess().CheckList(False))
    file_faces = 0
    for i in range(1, model.NbEntities() + 1):
        if model.Value(i).DynamicType().Name() in _FACE_ENTITIES:
            file_faces += 1
    fmap = TopTools_IndexedMapOfShape()
    if shape is not None and not shape.IsNull():
        TopExp.MapShapes_s(shape, TopAbs_FACE, fmap)
    return {"load_fails": load_fails, "transfer_fails": transfer_fails, "file_faces": file_faces,
            "shape_faces": fmap.Extent(), "first": first, "notes": n_notes[0], "first_notes": notes}


def _read_here(path: Path) -> tuple:
    """Read and transfer ``path`` in this process: (shape or None, damage dict, error or "")."""
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.STEPControl import STEPControl_Reader

    reader = STEPControl_Reader()
    status = reader.ReadFile(str(path))
    if status != IFSelect_RetDone:
        return None, {}, f"STEP reader failed ({status.name})"
    reader.TransferRoots()
    if reader.NbShapes() == 0:
        return None, {}, "STEP file has no faces (no shape transferred)"
    shape = reader.OneShape()
    return shape, _damage(reader, shape), ""


def _read_in_child(path: Path) -> tuple:
    """:func:`_read_here` in a forked child, so that a crash of OCC's reader (it segfaults
    on some corrupt files) ends the child and not us. The shape comes back as an OCC
    binary BRep file (``BinTools``: exact, tens of ms for thousands of faces)."""
    import json
    import signal
    import tempfile

    from OCP.BinTools import BinTools
    from OCP.TopoDS import TopoDS_Shape

    with tempfile.TemporaryDirectory(prefix="zmap-step-") as tmp:
        brep = os.path.join(tmp, "shape.bin")
        info = os.path.join(tmp, "info.json")
        pid = os.fork()
        if pid == 0:  # the child: never returns
            code = 1
            try:
                import faulthandler

                faulthandler.disable()  # a crash is the parent's to report (pytest enables it)
                with _QuietFd(1), _QuietFd(2):
                    shape, damage, error = _read_here(path)
                    if shape is not None:
                        BinTools.Write_s(shape, brep)
                with open(info, "w") as fh:
                    json.dump({"damage": damage, "error": error}, fh)
                code = 0
            except BaseException as err:  # noqa: BLE001 (the child must end here, whatever happened)
                try:
                    with open(info, "w") as fh:
                        json.dump({"damage": {}, "error": f"{type(err).__name__}: {err}"}, fh)
                    code = 0
                except BaseException:  # noqa: BLE001
                    pass
            finally:
                os._exit(code)
        while True:
            try:
                _, status = os.waitpid(pid, 0)
                break
            except InterruptedError:
                continue
            except KeyboardInterrupt:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                raise
        if os.WIFSIGNALED(status):
            sig = os.WTERMSIG(status)
            try:
                name = signal.Signals(sig).name
            except ValueError:
                name = f"signal {sig}"
            raise StepImportError(f"{path}: OCC's STEP reader crashed ({name}) on this file: it is "
                                  f"corrupt or uses records the reader cannot handle")
        try:
            with open(info) as fh:
                got = json.load(fh)
        except (OSError, ValueError):
            raise StepImportError(f"{path}: OCC's STEP reader stopped (exit status "
                                  f"{os.WEXITSTATUS(status)}) without a result") from None
        if got["error"]:
            return None, got["damage"], got["error"]
        shape = TopoDS_Shape()
        BinTools.Read_s(shape, brep)
        return shape, got["damage"], ""


def _note_message(damage: dict) -> str:
    """One line on the reader's fails that change no face (:mod:`cad_io.damage`), or ""."""
    n = damage.get("notes", 0) if damage else 0
    if not n:
        return ""
    return (f"{n} {'entity' if n == 1 else 'entities'} with harmless faults ({'; '.join(damage['first_notes'])}): "
            f"no face lost or changed")


def _damage_message(damage: dict) -> str:
    """One line on what the reader lost, or "" when nothing was."""
    if not damage:
        return ""
    bad = damage["load_fails"] + damage["transfer_fails"]
    missing = max(0, damage["file_faces"] - damage["shape_faces"])
    if bad == 0 and missing == 0:
        return ""
    parts = []
    if bad:
        parts.append(f"{bad} entities failed to load or transfer"
                     + (f" ({'; '.join(damage['first'])})" if damage["first"] else ""))
    if missing:
        parts.append(f"{missing} of the file's {damage['file_faces']} faces are missing from the shape")
    return "; ".join(parts) + ": the file is damaged, heights may be missing or wrong"


def _load_shape(path: Path, *, strict: bool = False, isolate: bool = True):
    """The OCP shape of a STEP file and the reader's damage report (a warning line or "").

    StepImportError naming the file where it cannot be read, where OCC's reader crashes
    (the file is read in a child process where ``os.fork`` exists and ``isolate``), or
    where ``strict`` and entities failed to load or transfer (faults that change no face,
    :mod:`cad_io.damage`, are not refused).
    """
    shape, damage = _load_shape_info(path, strict=strict, isolate=isolate)
    return shape, _damage_message(damage)


def _load_shape_info(path: Path, *, strict: bool = False, isolate: bool = True):
    """:func:`_load_shape` with the reader's whole damage dict instead of its line."""
    if not path.exists():
        raise StepImportError(f"{path}: no such file")
    if not path.is_file():
        raise StepImportError(f"{path}: not a file")
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096).lstrip()
    except OSError as err:
        raise StepImportError(f"{path}: cannot read: {err.strerror}") from None
    if not head.startswith(b"ISO-10303-21"):
        raise StepImportError(f"{path}: not a STEP file (expected 'ISO-10303-21;' at the "
                              f"start, got {head[:20]!r})")
    if isolate and hasattr(os, "fork"):
        shape, damage, error = _read_in_child(path)
    else:
        with _QuietFd(1):
            shape, damage, error = _read_here(path)
    if error:
        raise StepImportError(f"{path}: {error}")
    msg = _damage_message(damage)
    if msg and strict:
        raise StepImportError(f"{path}: {msg} (refused: strict)")
    return shape, damage


def _kind(face) -> str:
    from OCP.BRep import BRep_Tool
    from OCP.BRepAdaptor import BRepAdaptor_Surface

    if BRep_Tool.Surface_s(face) is None:
        return "other"
    return _KIND_NAMES.get(BRepAdaptor_Surface(face, False).GetType().name, "other")


def _convert(faces: list, kinds: list[str]):
    """Faces whose surface is a B-spline (as they are) or converted to one, one by one.

    Returns the faces (oriented like ``faces``; None where conversion failed) and the
    reasons of the failures. B-spline faces are kept: their parameters are already those
    of their NURBS, and converting them again (which re-fits their pcurves) is slow.
    """
    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_NurbsConvert
    from OCP.TopoDS import TopoDS

    out: list = [None] * len(faces)
    why: list[str] = [""] * len(faces)
    for i, f in enumerate(faces):
        if BRep_Tool.Surface_s(f) is None:
            why[i] = "no surface (tessellated face)"
        elif kinds[i] == "bspline":
            out[i] = f
        else:
            try:
                nc = BRepBuilderAPI_NurbsConvert(f, True)
                out[i] = TopoDS.Face_s(nc.ModifiedShape(f).Oriented(f.Orientation()))
            except Exception as err:  # noqa: BLE001 (OCCT errors share no base class in OCP)
                why[i] = f"{type(err).__name__}: {err}".strip()
    return out, why


def _nurbs_of(face) -> NurbsSurface:
    """Exact non-periodic NurbsSurface of a converted face (location applied)."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.BRepTools import BRepTools

    ad = BRepAdaptor_Surface(face, False)
    if ad.GetType().name != "GeomAbs_BSplineSurface":
        raise ValueError(f"converted surface is {ad.GetType().name}, not a B-spline")
    b = ad.BSpline()  # a transformed copy when the face has a location
    shift = (0.0, 0.0)
    bounds = BRepTools.UVBounds_s(face)
    b = _periodic_if_needed(b, bounds)
    if b.IsUPeriodic() or b.IsVPeriodic():
        b, shift = _unperiodic(b, *bounds)
    p, q = b.UDegree(), b.VDegree()
    nu, nv = b.NbUPoles(), b.NbVPoles()
    ku = b.UKnotSequence()
    kv = b.VKnotSequence()
    knots_u = np.array([ku.Value(i) for i in range(ku.Lower(), ku.Upper() + 1)])
    knots_v = np.array([kv.Value(i) for i in range(kv.Lower(), kv.Upper() + 1)])
    poles = np.empty((nu, nv, 3))
    weights = np.ones((nu, nv))
    rational = b.IsURational() or b.IsVRational()
    for a in range(nu):
        for c in range(nv):
            pt = b.Pole(a + 1, c + 1)
            poles[a, c] = pt.X(), pt.Y(), pt.Z()
            if rational:
                weights[a, c] = b.Weight(a + 1, c + 1)
    if not rational and b.Weights() is not None:
        W = b.Weights()
        weights = np.array([[W.Value(a + 1, c + 1) for c in range(nv)] for a in range(nu)])
    knots_u -= shift[0]
    knots_v -= shift[1]
    if len(knots_u) != nu + p + 1 or len(knots_v) != nv + q + 1:
        raise ValueError(f"knot sequences of lengths ({len(knots_u)}, {len(knots_v)}) do not "
                         f"fit {nu}x{nv} poles of degrees ({p}, {q})")
    return NurbsSurface(p, q, knots_u, knots_v, poles, weights)


def _periodic_if_needed(b, bounds):
    """``b``, or a periodic copy where the face's (u, v) bounds cross the end of a closed
    direction (NurbsConvert can start a full revolution's B-spline off the face's seam)."""
    u0, u1, v0, v1 = bounds
    a0, a1 = b.UKnot(b.FirstUKnotIndex()), b.UKnot(b.LastUKnotIndex())
    c0, c1 = b.VKnot(b.FirstVKnotIndex()), b.VKnot(b.LastVKnotIndex())
    tu, tv = 1e-9 * max(1.0, a1 - a0), 1e-9 * max(1.0, c1 - c0)
    out_u = not b.IsUPeriodic() and (u0 < a0 - tu or u1 > a1 + tu) and b.IsUClosed()
    out_v = not b.IsVPeriodic() and (v0 < c0 - tv or v1 > c1 + tv) and b.IsVClosed()
    if out_u or out_v:
        b = b.Copy()
        if out_u:
            b.SetUPeriodic()
        if out_v:
            b.SetVPeriodic()
    return b


def _unperiodic(b, u0: float, u1: float, v0: float, v1: float):
    """A non-periodic copy of ``b`` cut to [u0, u1] x [v0, v1] in its periodic directions
    (exact: knot insertion only), and the (u, v) shifts to subtract from its knots so that
    parameters keep their values."""
    b = b.Copy()
    ranges = []
    for periodic, t0, t1, first, last, period in (
            (b.IsUPeriodic(), u0, u1, b.UKnot(b.FirstUKnotIndex()),
             b.UKnot(b.LastUKnotIndex()), b.UPeriod() if b.IsUPeriodic() else 0.0),
            (b.IsVPeriodic(), v0, v1, b.VKnot(b.FirstVKnotIndex()),
             b.VKnot(b.LastVKnotIndex()), b.VPeriod() if b.IsVPeriodic() else 0.0)):
        if periodic:
            if not (t1 - t0 > 1e-9 * period) or t1 - t0 > period:
                t1 = t0 + period
            ranges.append((t0, t1))
        else:
            ranges.append((first, last))
    (a0, a1), (c0, c1) = ranges
    periods = (b.UPeriod() if b.IsUPeriodic() else 0.0, b.VPeriod() if b.IsVPeriodic() else 0.0)
    b.Segment(a0, a1, c0, c1)
    if b.IsUPeriodic():
        b.SetUNotPeriodic()
    if b.IsVPeriodic():
        b.SetVNotPeriodic()
    # Segment may move the range by whole periods: shift the knots back
    shift = []
    for start, got, period in ((a0, b.UKnot(b.FirstUKnotIndex()), periods[0]),
                               (c0, b.VKnot(b.FirstVKnotIndex()), periods[1])):
        shift.append(round((got - start) / period) * period if period > 0 else 0.0)
    return b, (shift[0], shift[1])


# --------------------------------------------------------------------------------------
# trim loops


def _pcurve_samples(c2, t0: float, t1: float, n0: int, packed, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """uv samples of a pcurve on [t0, t1] whose polygon lies within ``tol`` mm of it, and each
    chord's bulge (uv): the pcurve runs ``bulge * s * (1 - s)`` to the chord's left at the
    fraction ``s`` along it (a parabola through the chord's ends and the pcurve's middle).

    The deviation of each uv chord is measured on the surface, between the images of the
    chord's midpoint and of the pcurve's midpoint. A uniform first guess is resampled at
    the count the chordal error (~ h^2) calls for, then bad chords are bisected.
    """
    from cad_io.nurbs import evaluate_packed

    def values(ts):
        return np.array([c2.Value(t).Coord() for t in ts]).reshape(-1, 2)

    def deviation(true, lin):
        both = evaluate_packed(packed, 0, np.r_[true[:, 0], lin[:, 0]],
                               np.r_[true[:, 1], lin[:, 1]])[:, 0]
        return np.linalg.norm(both[: len(true)] - both[len(true):], axis=1)

    def segments(ts, uv):
        tm = 0.5 * (ts[:-1] + ts[1:])
        true = values(tm)
        return tm, true, deviation(true, 0.5 * (uv[:-1] + uv[1:]))

    ts = np.linspace(t0, t1, n0)
    uv = values(ts)
    tm, true, d = segments(ts, uv)
    if d.max() > tol:
        n = int(min(np.ceil((n0 - 1) * np.sqrt(d.max() / tol) * 1.2), 100_000)) + 1
        ts = np.linspace(t0, t1, n)
        uv = values(ts)
        tm, true, d = segments(ts, uv)
    for _ in range(30):
        bad = np.nonzero(d > tol)[0]
        if len(bad) == 0:
            break
        left = 0.5 * (ts[bad] + tm[bad])
        right = 0.5 * (tm[bad] + ts[bad + 1])
        new_true = values(np.r_[left, right])
        new_lin = np.r_[0.5 * (uv[bad] + true[bad]), 0.5 * (true[bad] + uv[bad + 1])]
        new_d = deviation(new_true, new_lin)
        k = len(bad)
        ts = np.insert(ts, bad + 1, tm[bad])
        uv = np.insert(uv, bad + 1, true[bad], axis=0)
        tm[bad], true[bad], d[bad] = left, new_true[:k], new_d[:k]
        tm = np.insert(tm, bad + 1, right)
        true = np.insert(true, bad + 1, new_true[k:], axis=0)
        d = np.insert(d, bad + 1, new_d[k:])
    return uv, _bulges(uv, true)


def _bulges(uv: np.ndarray, mid: np.ndarray) -> np.ndarray:
    """Per chord ``uv[i]``-``uv[i + 1]`` the bulge of the curve through ``mid[i]`` (see
    :func:`_pcurve_samples`); 0 for a chord of no length."""
    d = uv[1:] - uv[:-1]
    w = mid - uv[:-1]
    ll = np.einsum("ij,ij->i", d, d)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.clip(np.einsum("ij,ij->i", w, d) / ll, 0.05, 0.95)
        h = (d[:, 0] * w[:, 1] - d[:, 1] * w[:, 0]) / np.sqrt(ll)
        k = h / (s * (1.0 - s))
    return np.where(ll > 0, np.nan_to_num(k, nan=0.0, posinf=0.0, neginf=0.0), 0.0)


def _wire_loop(wire, face, packed, tol: float) -> tuple[np.ndarray, np.ndarray]:
    from OCP.BRepAdaptor import BRepAdaptor_Curve2d
    from OCP.BRepTools import BRepTools_WireExplorer
    from OCP.TopAbs import TopAbs_REVERSED

    from OCP.BRep import BRep_Tool

    pts: list[np.ndarray] = []
    devs: list[np.ndarray] = []
    ex = BRepTools_WireExplorer(wire, face)
    while ex.More():
        e = ex.Current()
        if BRep_Tool.CurveOnSurface_s(e, face, 0.0, 0.0) is None:
            # a damaged file's edge may lack its pcurve: OCC's adaptor would then crash the process
            raise ValueError("an edge of the face has no curve on its surface")
        c2 = BRepAdaptor_Curve2d(e, face)
        t0, t1 = c2.FirstParameter(), c2.LastParameter()
        n0 = 2 if c2.GetType().name == "GeomAbs_Line" else 9
        uv, dev = _pcurve_samples(c2, t0, t1, n0, packed, tol)
        if e.Orientation() == TopAbs_REVERSED:
            uv, dev = uv[::-1], -dev[::-1]  # the chords turn round: their left is the other side
        pts.append(uv[:-1])
        devs.append(dev)
        ex.Next()
    if not pts:
        return np.zeros((0, 2)), np.zeros(0)
    return np.ascontiguousarray(np.vstack(pts)), np.concatenate(devs)


def _loops(face, packed, tol: float) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The face's trim loops (outer first) and, per loop, each chord's bulge (uv)."""
    from OCP.BRepTools import BRepTools
    from OCP.TopAbs import TopAbs_WIRE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    outer = BRepTools.OuterWire_s(face)
    loops: list[tuple[np.ndarray, np.ndarray]] = []
    holes: list[tuple[np.ndarray, np.ndarray]] = []
    ex = TopExp_Explorer(face, TopAbs_WIRE)
    while ex.More():
        w = TopoDS.Wire_s(ex.Current())
        loop = _wire_loop(w, face, packed, tol)
        if len(loop[0]) >= 2:
            if not outer.IsNull() and w.IsSame(outer):
                loops.insert(0, loop)
            else:
                holes.append(loop)
        ex.Next()
    both = loops + holes
    return [lp for lp, _ in both], [dv for _, dv in both]


def _edge_tolerance(face) -> float:
    """Largest tolerance (mm) of the edges of ``face`` as the file (and OCC's reader) set it."""
    from OCP.BRep import BRep_Tool
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    tol = 0.0
    ex = TopExp_Explorer(face, TopAbs_EDGE)
    while ex.More():
        tol = max(tol, float(BRep_Tool.Tolerance_s(TopoDS.Edge_s(ex.Current()))))
        ex.Next()
    return tol


def _bbox(face) -> tuple[float, ...]:
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib

    box = Bnd_Box()
    try:
        BRepBndLib.AddOptimal_s(face, box, True, False)
    except Exception:  # noqa: BLE001 (OCCT errors share no base class in OCP)
        box = Bnd_Box()
        BRepBndLib.Add_s(face, box, True)
    if box.IsVoid():
        return (np.nan,) * 6
    return tuple(float(x) for x in box.Get())


# --------------------------------------------------------------------------------------
# edges


def _edges(shape, face_index, faces: list, surf_ok: list[bool]) -> list[Edge]:
    from OCP.BRep import BRep_Tool
    from OCP.BRepAdaptor import BRepAdaptor_Curve, BRepAdaptor_Curve2d, BRepAdaptor_Surface
    from OCP.BRepLProp import BRepLProp_SLProps
    from OCP.GCPnts import GCPnts_TangentialDeflection
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_REVERSED
    from OCP.TopExp import TopExp
    from OCP.TopoDS import TopoDS
    from OCP.TopTools import TopTools_IndexedDataMapOfShapeListOfShape

    amap = TopTools_IndexedDataMapOfShapeListOfShape()
    TopExp.MapShapesAndAncestors_s(shape, TopAbs_EDGE, TopAbs_FACE, amap)
    adaptors: dict[int, object] = {}
    edges: list[Edge] = []
    for i in range(1, amap.Extent() + 1):
        e = TopoDS.Edge_s(amap.FindKey(i))
        if BRep_Tool.Degenerated_s(e):
            continue
        adj: list[int] = []
        for f in amap.FindFromIndex(i):
            k = face_index(f)
            if k >= 0 and k not in adj:
                adj.append(k)
        if not adj:
            continue
        seam = len(adj) == 1 and BRep_Tool.IsClosed_s(e, faces[adj[0]])
        if seam:
            adj = [adj[0], adj[0]]
        if BRep_Tool.Curve_s(e, 0.0, 0.0) is None:
            continue  # no 3D curve (a damaged file): OCC's adaptor would crash the process
        c3 = BRepAdaptor_Curve(e)
        t0, t1 = c3.FirstParameter(), c3.LastParameter()
        try:
            td = GCPnts_TangentialDeflection(c3, t0, t1, 0.1, EDGE_DEFLECTION, 2)
            params = np.array([td.Parameter(j) for j in range(1, td.NbPoints() + 1)])
        except Exception:  # noqa: BLE001 (OCCT errors share no base class in OCP)
            params = np.linspace(t0, t1, 17)
        points = np.array([c3.Value(t).Coord() for t in params])
        dihedral = np.nan
        if seam:
            dihedral = 0.0
        elif len(adj) >= 2 and all(surf_ok[k] for k in adj):
            ts = np.linspace(t0, t1, _DIHEDRAL_SAMPLES)
            normals = []
            for k in adj:
                f = faces[k]
                if k not in adaptors:
                    adaptors[k] = BRepAdaptor_Surface(f, False)
                ad = adaptors[k]
                if BRep_Tool.CurveOnSurface_s(e, f, 0.0, 0.0) is None:
                    continue
                c2 = BRepAdaptor_Curve2d(e, f)
                flip = -1.0 if f.Orientation() == TopAbs_REVERSED else 1.0
                nk = np.full((len(ts), 3), np.nan)
                for j, t in enumerate(ts):
                    u, v = c2.Value(t).Coord()
                    props = BRepLProp_SLProps(ad, u, v, 1, 1e-9)
                    if props.IsNormalDefined():
                        nk[j] = np.array(props.Normal().Coord()) * flip
                normals.append(nk)
            best = np.nan
            for a in range(len(normals)):
                for b in range(a + 1, len(normals)):
                    c = np.clip(np.einsum("ij,ij->i", normals[a], normals[b]), -1.0, 1.0)
                    ang = np.arccos(c)
                    if np.any(np.isfinite(ang)):
                        m = float(np.nanmax(ang))
                        best = m if not np.isfinite(best) else max(best, m)
            dihedral = best
        edges.append(Edge(index=len(edges), faces=tuple(adj), points=points,
                          dihedral=dihedral))
    return edges


# --------------------------------------------------------------------------------------
# front door


def _ranges(ids: list[int]) -> str:
    out: list[str] = []
    start = prev = ids[0]
    for i in ids[1:] + [None]:
        if i is not None and i == prev + 1:
            prev = i
            continue
        out.append(f"{start}" if start == prev else f"{start}-{prev}")
        if i is not None:
            start = prev = i
    return ", ".join(out)


def _without_faces(shape, faces: list, drop) -> Any:
    """A compound of the faces of ``shape`` but ``drop`` (the faces keep their shared edges)."""
    from OCP.BRep import BRep_Builder
    from OCP.TopoDS import TopoDS_Compound

    comp = TopoDS_Compound()
    builder = BRep_Builder()
    builder.MakeCompound(comp)
    gone = set(int(i) for i in drop)
    for i, f in enumerate(faces):
        if i not in gone:
            builder.Add(comp, f)
    return comp


def _box_text(box) -> str:
    return ", ".join(f"{a} {box[k]:.4g} .. {box[k + 3]:.4g}" for k, a in enumerate("xyz"))


def read_step(path: str | os.PathLike, *, mesh_deflection: float | None = None, strict: bool = False,
              partial: bool = False, warn: Callable[[str], Any] | None = None) -> Part:
    """Read a STEP file into a :class:`Part` with exact NURBS faces.

    Parameters
    ----------
    path : str or path-like
        A STEP (ISO 10303-21) file; lengths come out in mm.
    mesh_deflection : float, optional, keyword-only
        When given, also triangulate every face (:func:`cad_io.mesh.triangulate`) with this
        linear deflection in mm.
    strict : bool, keyword-only
        Refuse (StepImportError) a damaged file: entities that failed to load or transfer,
        or faces that did not all reach the shape; by default such a file is read and
        ``warnings`` says how many were lost. Faults that change no face (a seam curve
        naming one pcurve twice, a name that is not a quoted string: :mod:`cad_io.damage`)
        are never refused: ``notes`` lists them.
    partial : bool, keyword-only
        Read a damaged file that lost most of its faces (more than :data:`cad_io.damage.MOST_LOST`
        of the file's faces missing from the shape or refused); by default it is refused,
        since a map of what is left is not the part.
    warn : callable, keyword-only
        Called with each warning line as soon as it is known (the reader's damage right
        after the file is read, before the faces are converted); they are in ``warnings`` too.

    Returns
    -------
    Part
        ``faces[i]`` in the order of OCC's face map, each with its exact ``NurbsSurface``
        (None where conversion failed; such faces are listed in ``warnings`` as
        ``"face 17 (kind): conversion failed: ..."``), ``kind``, ``reversed``, trim
        ``loops`` (outer first) in the NURBS's (u, v), ``bbox`` and ``topo``; ``edges``
        with adjacent faces (a seam edge lists its face twice) and dihedral angles (NaN on
        open boundaries); ``shape`` the OCP shape as read (``Face.topo`` is the face, the
        converted one where the surface was converted, whose pcurves the loops sample).

    Raises
    ------
    zmap.errors.StepImportError
        Missing file, not a STEP file, a STEP file the reader rejects or crashes on (the
        file is read in a child process, so a crash of OCC's reader is reported, not
        suffered), one with no faces, a damaged one that lost most of its faces (unless
        ``partial``), or under ``strict`` a damaged one.

    Notes
    -----
    On a damaged file, a face whose extent is absurd against the rest of the part
    (:func:`cad_io.damage.absurd_faces`: OCC gives an unbounded plane a box of 1e100 mm) is
    refused: it is left out of the part and its shape, and a warning names it.

    OCC's reader messages never reach stdout (they are caught in the child).

    Examples
    --------
    >>> part = read_step("part.step")  # doctest: +SKIP
    >>> part.faces[0].surface.domain  # doctest: +SKIP
    (0.0, 1.0, 0.0, 1.0)
    """
    from OCP.BRep import BRep_Tool
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp
    from OCP.TopoDS import TopoDS
    from OCP.TopTools import TopTools_IndexedMapOfShape

    from cad_io.nurbs import MAX_DEGREE, pack

    from cad_io.damage import MOST_LOST, absurd_faces, lost_share

    path = Path(path)
    shape, info = _load_shape_info(path, strict=strict)
    damage = _damage_message(info)
    warnings: list[str] = []

    def tell(line: str) -> None:
        warnings.append(line)
        if warn is not None:
            warn(line)

    fmap = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(shape, TopAbs_FACE, fmap)
    if fmap.Extent() == 0:
        raise StepImportError(f"{path}: STEP file has no faces" + (f"; {damage}" if damage else ""))
    faces = [TopoDS.Face_s(fmap.FindKey(i)) for i in range(1, fmap.Extent() + 1)]
    boxes = [_bbox(f) for f in faces]
    refused = absurd_faces(boxes) if damage else np.zeros(0, dtype=np.int64)
    lost, share = lost_share(info.get("file_faces", 0), len(faces), len(refused))
    if share > MOST_LOST and not partial:
        bad = info.get("load_fails", 0) + info.get("transfer_fails", 0)
        raise StepImportError(
            f"{path}: {lost} of the file's {max(info.get('file_faces', 0), len(faces))} faces are lost "
            f"({100 * share:.0f} %"
            + (f", {len(refused)} refused for an absurd extent" if len(refused) else "")
            + ")" + (f", {bad} entities failed to load or transfer ({'; '.join(info['first'])})" if bad else "")
            + ": the file is damaged and a map of the rest would not be the part; "
              "pass --partial (partial=True) to read what is left")
    if damage:  # told before any face is converted: a damaged face can take long
        tell(damage)
    if len(refused):
        keep = np.setdiff1d(np.arange(len(faces)), refused)
        bulk = np.array([boxes[k] for k in keep], dtype=np.float64).reshape(-1, 6)
        tell(f"{'face' if len(refused) == 1 else 'faces'} {_ranges([int(k) for k in refused])} of the "
             f"{len(faces)} read refused: extent absurd against the part's"
             + (f" ({_box_text((*np.nanmin(bulk[:, :3], axis=0), *np.nanmax(bulk[:, 3:], axis=0)))} mm)"
                if len(keep) else "")
             + f", reaching {_box_text(boxes[int(refused[0])])} mm: the file is damaged")
        shape = _without_faces(shape, faces, refused)
        faces = [faces[k] for k in keep]
        boxes = [boxes[k] for k in keep]
        fmap = TopTools_IndexedMapOfShape()
        TopExp.MapShapes_s(shape, TopAbs_FACE, fmap)
    kinds = [_kind(f) for f in faces]
    conv, why = _convert(faces, kinds)

    out_faces: list[Face] = []
    for i, (f, cf) in enumerate(zip(faces, conv)):
        surface = None
        loops: list[np.ndarray] = []
        errors: list[np.ndarray] = []
        if cf is not None:
            try:
                surface = _nurbs_of(cf)
                if max(surface.degree_u, surface.degree_v) > MAX_DEGREE:
                    why[i] = (f"degrees ({surface.degree_u}, {surface.degree_v}) above "
                              f"{MAX_DEGREE}")
                    surface = None
            except Exception as err:  # noqa: BLE001 (OCCT errors or inconsistent arrays)
                why[i] = f"{type(err).__name__}: {err}".strip()
                surface = None
        topo = cf if cf is not None else f
        if surface is not None:
            try:
                loops, errors = _loops(cf, pack([surface]), LOOP_TOL)
            except Exception as err:  # noqa: BLE001 (OCCT errors on a broken wire)
                why[i] = f"trim loops failed: {type(err).__name__}: {err}".strip()
                surface = None
                loops, errors = [], []
        out_faces.append(Face(index=i, kind=kinds[i], surface=surface,
                              reversed=f.Orientation().name == "TopAbs_REVERSED",
                              loops=loops, bbox=boxes[i], topo=topo, tolerance=_edge_tolerance(f),
                              loop_bulges=errors))

    groups: dict[tuple[str, str], list[int]] = {}
    for fc in out_faces:
        if fc.surface is None:
            groups.setdefault((fc.kind, why[fc.index] or "unknown"), []).append(fc.index)
    for (kind, reason), ids in groups.items():
        word = "face" if len(ids) == 1 else "faces"
        tell(f"{word} {_ranges(ids)} ({kind}): conversion failed: {reason}; facets used")

    def face_index(f) -> int:
        return fmap.FindIndex(f) - 1

    # dihedrals come from OCC's own surfaces: they exist wherever a face is not tessellated
    has_surface = [BRep_Tool.Surface_s(f) is not None for f in faces]
    edges = _edges(shape, face_index, faces, has_surface)
    note = _note_message(info)
    part = Part(faces=out_faces, edges=edges, source=str(path), shape=shape,
                warnings=warnings, notes=[note] if note else [], damaged=bool(damage))
    if mesh_deflection is not None:
        from cad_io.mesh import triangulate

        triangulate(part, mesh_deflection)
    return part
