"""The direction set of paper 002: a q-frequency icosahedron, k = 20 q^2 tessels, as bitsets.

Each face of the icosahedron is split into q^2 triangles by lines parallel to its edges (the
"alternate method"); their corners, pushed onto the unit sphere, are the tessels' vertices.
The set ``N`` holds one unit normal per tessel (perpendicular to the flat triangle through its
three vertices, pointing out), so ``k = 20 q^2``. A set of directions is a k-bit bitset stored
in ``ceil(k / 64)`` uint64 words; bit ``i`` stands for ``normals[i]``.

Precomputed, as in the paper: ``H(v) = {n in N : n . v > 0}`` for every vertex, and per tessel
``t = (v1, v2, v3)`` its visibility hemisphere ``H_V(t) = H(v1) & H(v2) & H(v3)`` and light
hemisphere ``H_L(t) = H(v1) | H(v2) | H(v3)``. :meth:`DirectionSet.lookup` finds the tessel
whose patch holds a direction in O(1): the nearest of the 20 face centres, then the flat
barycentric coordinates of the direction's hit with that face's plane. The icosahedron is
turned so that a face centre points along +z: when 3 does not divide q, +z and -z are
directions of the set.

Examples
--------
>>> ds = DirectionSet(2)
>>> ds.k, ds.words
(80, 2)
>>> int(ds.lookup([0.0, 0.0, 1.0])) == int(ds.nearest([0.0, 0.0, 1.0]))
True
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = ["DirectionSet", "direction_set", "to_bool", "from_bool", "count", "words_for"]


def words_for(k: int) -> int:
    """Number of uint64 words of a k-bit bitset."""
    return (int(k) + 63) // 64


def _icosahedron() -> tuple[np.ndarray, np.ndarray]:
    """Unit vertices (12, 3) and faces (20, 3) wound outward."""
    p = (1.0 + 5.0 ** 0.5) / 2.0
    v = np.array([[-1, p, 0], [1, p, 0], [-1, -p, 0], [1, -p, 0],
                  [0, -1, p], [0, 1, p], [0, -1, -p], [0, 1, -p],
                  [p, 0, -1], [p, 0, 1], [-p, 0, -1], [-p, 0, 1]], dtype=np.float64)
    v /= np.linalg.norm(v, axis=1)[:, None]
    # turn face 0's centre onto +z (and so face 0's opposite onto -z): when 3 does not divide
    # q, +z and -z are then exact directions of the set (centres of the middle sub-triangles)
    c = v[[0, 11, 5]].sum(axis=0)
    c /= np.linalg.norm(c)
    axis = np.cross(c, [0.0, 0.0, 1.0])
    s, co = np.linalg.norm(axis), c[2]
    axis /= s
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    R = np.eye(3) + s * K + (1 - co) * K @ K
    v = v @ R.T
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
                  [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
                  [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
                  [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]], dtype=np.int64)
    return v, f


class DirectionSet:
    """The q-frequency icosahedral direction set with its hemisphere bitsets.

    Parameters
    ----------
    q : int
        Frequency, >= 1; ``k = 20 q^2`` directions.

    Attributes
    ----------
    q, k, words : int
        Frequency, number of directions, uint64 words per bitset.
    normals : ndarray of shape (k, 3), float64
        Unit direction of each tessel (bit i of a bitset).
    vertices : ndarray of shape (k, 3, 3), float64
        Unit vertices of each tessel (on the sphere).
    hv, hl : ndarray of shape (k, words), uint64
        ``H_V(t)`` and ``H_L(t)`` of each tessel.
    face : ndarray of shape (k,), int64
        Icosahedron face (0..19) of each tessel.
    area : ndarray of shape (k,), float64
        Solid angle of each tessel's spherical triangle (sr); sums to 4 pi.
    """

    def __init__(self, q: int) -> None:
        if isinstance(q, bool) or not isinstance(q, (int, np.integer)):
            raise ValueError(f"q must be an integer >= 1, got {q!r}")
        if q < 1:
            raise ValueError(f"q must be an integer >= 1, got {q!r}")
        if q > 64:
            raise ValueError(f"q must be at most 64 (k = 81,920 directions), got {q!r}")
        self.q = int(q)
        self.k = 20 * self.q * self.q
        self.words = words_for(self.k)
        self._build()

    def _build(self) -> None:
        q = self.q
        iv, ifc = _icosahedron()
        tri_uv = []  # (i, j) barycentric lattice corners of each sub-triangle, in kernel order
        for i in range(q):
            for j in range(q - i):
                tri_uv.append(((i, j), (i + 1, j), (i, j + 1)))
        for i in range(q - 1):
            for j in range(q - 1 - i):
                tri_uv.append(((i + 1, j), (i + 1, j + 1), (i, j + 1)))
        tri_uv = np.array(tri_uv, dtype=np.float64) / q  # (q^2, 3, 2): (b, c) weights of B, C
        verts = np.empty((20, q * q, 3, 3))
        centres = np.empty((20, 3))
        frames = np.empty((20, 3, 3))
        for f in range(20):
            A, B, C = iv[ifc[f]]
            pts = A + tri_uv[..., 0, None] * (B - A) + tri_uv[..., 1, None] * (C - A)
            verts[f] = pts / np.linalg.norm(pts, axis=-1)[..., None]
            c = A + B + C
            centres[f] = c / np.linalg.norm(c)
            frames[f] = (A, B - A, C - A)
        self.vertices = verts.reshape(self.k, 3, 3)
        v = self.vertices
        nrm = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        nrm /= np.linalg.norm(nrm, axis=1)[:, None]
        nrm *= np.sign(np.einsum("ij,ij->i", nrm, v.sum(axis=1)))[:, None]
        self.normals = np.ascontiguousarray(nrm)
        self.face = np.repeat(np.arange(20), q * q)
        self._centres = centres
        self._frames = frames
        # solid angles (Van Oosterom and Strackee)
        a, b, c = v[:, 0], v[:, 1], v[:, 2]
        num = np.abs(np.einsum("ij,ij->i", a, np.cross(b, c)))
        den = 1 + np.einsum("ij,ij->i", a, b) + np.einsum("ij,ij->i", b, c) + np.einsum("ij,ij->i", c, a)
        self.area = 2 * np.arctan2(num, den)
        # hemispheres: H(v) for the three vertices of each tessel, as boolean (k, 3, k)
        dots = np.einsum("tjx,nx->tjn", v, self.normals) > 0.0
        self.hv = from_bool(dots.all(axis=1))
        self.hl = from_bool(dots.any(axis=1))

    def hemisphere(self, v) -> np.ndarray:
        """``H(v) = {n in N : n . v > 0}`` of the direction(s) ``v``.

        Parameters
        ----------
        v : array_like of shape (..., 3)

        Returns
        -------
        ndarray of shape (..., words), uint64

        Examples
        --------
        >>> ds = DirectionSet(1)
        >>> int(count(ds.hemisphere([0.0, 0.0, 1.0])))
        10
        """
        v = np.asarray(v, dtype=np.float64)
        shape = v.shape[:-1]
        mask = v.reshape(-1, 3) @ self.normals.T > 0.0
        return from_bool(mask).reshape(shape + (self.words,))

    def lookup(self, n) -> np.ndarray:
        """Index of the tessel whose spherical patch holds each direction, in O(1).

        Parameters
        ----------
        n : array_like of shape (..., 3)
            Directions, any non-zero length.

        Returns
        -------
        ndarray of shape (...,), int64
            In ``0 .. k - 1``; -1 where ``n`` is zero or not finite.

        Examples
        --------
        >>> ds = DirectionSet(4)
        >>> i = ds.lookup([[0.3, -0.2, 0.9]])
        >>> bool(ds.normals[i[0]] @ np.array([0.3, -0.2, 0.9]) > 0.9)
        True
        """
        from ._direction_kernels import lookup_kernel

        n = np.asarray(n, dtype=np.float64)
        if n.shape[-1:] != (3,):
            raise ValueError(f"directions must have shape (..., 3), got {n.shape}")
        shape = n.shape[:-1]
        flat = np.ascontiguousarray(n.reshape(-1, 3))
        out = np.empty(len(flat), dtype=np.int64)
        lookup_kernel(flat, self._centres, self._frames, self.q, out)
        bad = ~(np.isfinite(flat).all(axis=1) & (np.abs(flat).sum(axis=1) > 0))
        out[bad] = -1
        return out.reshape(shape)

    def nearest(self, n) -> np.ndarray:
        """Index of the normal nearest each direction (brute force over all k; for tests)."""
        n = np.asarray(n, dtype=np.float64)
        return np.argmax(n.reshape(-1, 3) @ self.normals.T, axis=1).reshape(n.shape[:-1])

    def contains(self, t, n) -> np.ndarray:
        """True where direction ``n`` lies in tessel ``t``'s spherical patch (brute force)."""
        v = self.vertices[np.asarray(t)]
        n = np.asarray(n, dtype=np.float64)
        tol = -1e-12
        s0 = np.einsum("...x,...x->...", np.cross(v[..., 0, :], v[..., 1, :]), n)
        s1 = np.einsum("...x,...x->...", np.cross(v[..., 1, :], v[..., 2, :]), n)
        s2 = np.einsum("...x,...x->...", np.cross(v[..., 2, :], v[..., 0, :]), n)
        return (s0 >= tol) & (s1 >= tol) & (s2 >= tol)

    def index(self, direction) -> int:
        """The tessel index of one direction given as a vector or as '+z', '-x', ..."""
        axes = {"+x": (1, 0, 0), "-x": (-1, 0, 0), "+y": (0, 1, 0), "-y": (0, -1, 0),
                "+z": (0, 0, 1), "-z": (0, 0, -1)}
        if isinstance(direction, str):
            if direction not in axes:
                raise ValueError(f"direction {direction!r} is not one of {', '.join(axes)}")
            direction = axes[direction]
        return int(self.lookup(np.asarray(direction, dtype=np.float64)[None])[0])

    def within(self, axis, angle: float) -> np.ndarray:
        """Boolean (k,): the normals within ``angle`` radians of ``axis`` (a tilt cone)."""
        a = np.asarray(axis, dtype=np.float64)
        a = a / np.linalg.norm(a)
        return self.normals @ a >= np.cos(angle) - 1e-12

    def __repr__(self) -> str:
        return f"DirectionSet(q={self.q}, k={self.k})"


@lru_cache(maxsize=8)
def direction_set(q: int) -> DirectionSet:
    """A cached :class:`DirectionSet` of frequency ``q``."""
    return DirectionSet(q)


def from_bool(mask) -> np.ndarray:
    """Bitsets (rows, words) uint64 from a boolean (rows, k) array (bit i = column i).

    Examples
    --------
    >>> from_bool(np.array([[True, False, True]])).tolist()
    [[5]]
    """
    from ._direction_kernels import bool_to_bits

    mask = np.ascontiguousarray(np.asarray(mask, dtype=np.bool_))
    if mask.ndim == 1:
        mask = mask[None]
    out = np.empty((mask.shape[0], words_for(mask.shape[1])), dtype=np.uint64)
    bool_to_bits(mask, out)
    return out


def to_bool(bits, k: int) -> np.ndarray:
    """Boolean (rows, k) from bitsets (rows, words).

    Examples
    --------
    >>> to_bool(np.array([[5]], dtype=np.uint64), 3).tolist()
    [[True, False, True]]
    """
    from ._direction_kernels import bits_to_bool

    bits = np.ascontiguousarray(np.asarray(bits, dtype=np.uint64))
    shape = bits.shape[:-1]
    flat = bits.reshape(-1, bits.shape[-1])
    if flat.shape[1] != words_for(k):
        raise ValueError(f"bitsets of {k} bits need {words_for(k)} words, got {flat.shape[1]}")
    out = np.empty((flat.shape[0], k), dtype=np.uint8)
    bits_to_bool(flat, k, out)
    return out.astype(bool).reshape(shape + (k,))


def count(bits) -> np.ndarray:
    """Number of set bits of each bitset (rows, words) -> (rows,) int64."""
    from ._direction_kernels import popcount_rows

    bits = np.ascontiguousarray(np.asarray(bits, dtype=np.uint64))
    shape = bits.shape[:-1]
    flat = bits.reshape(-1, bits.shape[-1])
    out = np.empty(flat.shape[0], dtype=np.int64)
    popcount_rows(flat, out)
    return out.reshape(shape)
