"""What the map answers: the 3-axis verdict, set-ups, per-node directions and the saved result."""

from __future__ import annotations

import os
import tempfile
import time
from dataclasses import dataclass, field

import numpy as np

from .build import VoxelMap
from .directions import count, from_bool
from .tool import Tool

def three_axis(vm: VoxelMap, amap: np.ndarray, *, axis="+z") -> dict:
    """The 3-axis verdict: area reachable along ``axis`` and the rest.

    Returns
    -------
    dict
        ``axis_index``, ``reachable`` (bool (mb,)), ``area_total``, ``area_reachable``,
        ``area_other`` (accessible, but not along the axis), ``area_inaccessible`` (mm^2),
        ``share`` (reachable / total), ``area_uncertain`` and ``uncertain_share`` (the
        uncertain voxels', counted in the others as their conservative directions say).
    """
    ds = vm.directions
    i = ds.index(axis)
    bits = np.asarray(amap)
    reach = ((bits[:, i >> 6] >> np.uint64(i & 63)) & np.uint64(1)).astype(bool)
    anyd = count(bits) > 0
    total = float(vm.area.sum())
    unc = vm.uncertain if vm.uncertain is not None else np.zeros(vm.n_boundary, dtype=bool)
    return {"axis_index": i, "reachable": reach, "area_total": total,
            "area_reachable": float(vm.area[reach].sum()),
            "area_other": float(vm.area[anyd & ~reach].sum()),
            "area_inaccessible": float(vm.area[~anyd].sum()),
            "share": float(vm.area[reach].sum() / total) if total > 0 else float("nan"),
            "area_uncertain": float(vm.area[unc].sum()),
            "uncertain_share": float(vm.area[unc].sum() / total) if total > 0 else float("nan")}


def set_cover(vm: VoxelMap, amap: np.ndarray, *, cone: float | None = None, axis="+z",
              max_setups: int = 64) -> list[dict]:
    """Fewest directions that together reach every accessible voxel (greedy set cover by area).

    Parameters
    ----------
    cone : float, optional
        Only directions within this angle (radians) of ``axis`` (a tilt cone, as 3+2 heads
        allow); voxels reachable only outside it stay uncovered.

    Returns
    -------
    list of dict
        One per set-up in the order chosen: ``direction`` index, ``vector``, ``area`` newly
        covered (mm^2), ``voxels`` (their numbers).
    """
    ds = vm.directions
    cand = np.ones(ds.k, bool) if cone is None else ds.within(
        np.asarray(ds.normals[ds.index(axis)] if isinstance(axis, str) else axis), float(cone))
    from ._access_kernels import greedy_cover

    chosen = np.zeros(max_setups, dtype=np.int64)
    gains = np.zeros(max_setups)
    n = greedy_cover(np.ascontiguousarray(amap, dtype=np.uint64), np.ascontiguousarray(vm.area, dtype=np.float64),
                     cand.astype(np.uint8), int(max_setups), chosen, gains)
    setups = []
    left = count(np.asarray(amap) & from_bool(cand)[0]) > 0
    for s_ in range(n):
        j = int(chosen[s_])
        got = left & ((np.asarray(amap)[:, j >> 6] >> np.uint64(j & 63)) & np.uint64(1)).astype(bool)
        setups.append({"direction": j, "vector": ds.normals[j].tolist(), "area": float(gains[s_]),
                       "voxels": np.flatnonzero(got)})
        left &= ~got
    return setups


def node_directions(vm: VoxelMap, amap: np.ndarray, x, y) -> tuple[np.ndarray, np.ndarray]:
    """Per z-map node (x, y): the top-most boundary voxel in its column and its directions.

    Returns
    -------
    voxel : ndarray of shape broadcast(x, y).shape, int64
        Boundary voxel number, -1 where the column holds none.
    n : ndarray of the same shape, int64
        Number of accessible directions there (0 where none or no voxel).
    """
    x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    i = np.floor((x - vm.origin[0]) / vm.d).astype(np.int64)
    j = np.floor((y - vm.origin[1]) / vm.d).astype(np.int64)
    nx, ny, nz = vm.state.shape
    ok = (i >= 0) & (i < nx) & (j >= 0) & (j < ny)
    col = vm.index[np.clip(i, 0, nx - 1), np.clip(j, 0, ny - 1), :]  # (..., nz)
    has = col >= 0
    top = nz - 1 - np.argmax(has[..., ::-1], axis=-1)
    vox = np.take_along_axis(col, top[..., None], axis=-1)[..., 0].astype(np.int64)
    vox[~(ok & has.any(axis=-1))] = -1
    cnt = np.where(vox >= 0, count(np.asarray(amap))[np.maximum(vox, 0)], 0)
    return vox, cnt


@dataclass
class AccessResult:
    """Everything ``zmap access`` computes, saved as one ``.npz``."""

    vm: VoxelMap
    vg: np.ndarray
    amap: np.ndarray
    tool: Tool
    verdict: dict
    setups: list
    seconds: dict
    source: str = ""
    #: optional per z-map node arrays (``node_voxel``, ``node_count``) and their grid
    nodes: dict = field(default_factory=dict)
    #: ``V'_g`` of each piece of ``vm.pieces`` (a face in a voxel where several meet), or None
    vg_pieces: np.ndarray | None = None
    #: ``V'_g`` of each half-voxel piece of ``vm.fine`` (:func:`global_visibility` with
    #: ``refine=True``), or None
    vg_fine: np.ndarray | None = None
    #: ``A'`` of each piece of ``vm.pieces`` (:func:`accessibility` with ``pieces``), or None
    amap_pieces: np.ndarray | None = None
    #: the casting's refinement figures (``"refine"``, :func:`global_visibility`'s ``stats``)
    #: and the tool test's (``"tool"``: pairs clear, blocked and scanned)
    stats: dict = field(default_factory=dict)

    def summary(self) -> str:
        """A markdown table of the verdict and the set-ups."""
        v = self.verdict
        tot = v["area_total"]
        lines = ["| figure | value |", "|---|---:|",
                 f"| surface area | {tot:,.1f} mm^2 |",
                 f"| reachable from +z (3-axis) | {v['area_reachable']:,.1f} mm^2 ({100 * v['share']:.1f} %) |",
                 f"| reachable only from other directions | {v['area_other']:,.1f} mm^2 "
                 f"({100 * v['area_other'] / tot if tot else 0:.1f} %) |",
                 f"| inaccessible with this tool | {v['area_inaccessible']:,.1f} mm^2 "
                 f"({100 * v['area_inaccessible'] / tot if tot else 0:.1f} %) |",
                 f"| set-ups found | {len(self.setups)} |"]
        if "area_uncertain" in v:
            lines.insert(6, f"| uncertain (walls or gaps thinner than the voxel) | {v['area_uncertain']:,.1f} mm^2 "
                            f"({100 * v['uncertain_share']:.2f} %) |")
        acc = v["area_reachable"] + v["area_other"]
        run = 0.0
        for need in (0.9, 0.99):
            n = 0
            run = 0.0
            for s in self.setups:
                run += s["area"]
                n += 1
                if run >= need * acc:
                    break
            lines.append(f"| set-ups for {100 * need:.0f} % of the accessible area | {n} |")
        out = "\n".join(lines) + "\n\n| set-up | direction (x, y, z) | tilt from +z (deg) | area (mm^2) |\n|---:|---|---:|---:|\n"
        for i, s in enumerate(self.setups[:10]):
            x, y, z = s["vector"]
            out += (f"| {i + 1} | ({x:+.3f}, {y:+.3f}, {z:+.3f}) | {np.degrees(np.arccos(np.clip(z, -1, 1))):.1f} "
                    f"| {s['area']:,.1f} |\n")
        if len(self.setups) > 10:
            out += f"| ... | {len(self.setups) - 10} more | | {sum(s['area'] for s in self.setups[10:]):,.1f} |\n"
        from .solid import describe

        return "\n".join(describe(self.vm)) + "\n\n" + out

    def save(self, path) -> None:
        """Write atomically (temporary name, then rename)."""
        import json

        path = os.fspath(path)
        vm = self.vm
        setup_of = np.full(vm.n_boundary, -1, dtype=np.int32)
        for s, su in enumerate(self.setups):
            setup_of[su["voxels"]] = s
        header = {"format": "zmap.access", "version": 1, "d": vm.d, "q": vm.q, "step": vm.step,
                  "tool": vars(self.tool), "verdict": {k: v for k, v in self.verdict.items() if k != "reachable"},
                  "setups": [{k: v for k, v in s.items() if k != "voxels"} for s in self.setups],
                  "seconds": self.seconds, "flipped": vm.flipped, "solid": vm.solid, "solid_note": vm.solid_note,
                  "floor": vm.floor, "uncertain": vm.uncertain_info}
        arrays = dict(origin=vm.origin, ijk=vm.ijk, state=vm.state, vl=vm.vl, light=vm.light, vg=self.vg,
                      amap=self.amap, curvature=vm.curvature, surface=vm.surface, point=vm.point,
                      normal=vm.normal, area=vm.area, setup=setup_of,
                      n_access=count(self.amap).astype(np.int32),
                      directions=vm.directions.normals,
                      uncertain=vm.uncertain if vm.uncertain is not None else np.zeros(vm.n_boundary, dtype=bool),
                      header=np.frombuffer(json.dumps(header).encode(), dtype=np.uint8))
        if self.vg_pieces is not None and vm.pieces is not None and vm.pieces.face is not None:
            arrays.update(piece_voxel=vm.pieces.voxel, piece_face=vm.pieces.face, piece_vg=self.vg_pieces)
            if self.amap_pieces is not None:
                arrays.update(piece_amap=self.amap_pieces)
        if self.vg_fine is not None and vm.fine is not None:
            arrays.update(fine_voxel=vm.fine.voxel.astype(np.int32), fine_octant=vm.fine.octant.astype(np.uint8),
                          fine_face=vm.fine.face.astype(np.int32), fine_vg=self.vg_fine)
        for key, val in self.nodes.items():
            if isinstance(val, np.ndarray):
                arrays[key] = val
            else:
                header[key] = val
        arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
        folder = os.path.dirname(os.path.abspath(path))
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=".tmp-", suffix=".npz")
        os.close(fd)
        try:
            np.savez_compressed(tmp, **arrays)
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise


def _timer():
    t0 = time.perf_counter()
    return lambda: time.perf_counter() - t0
