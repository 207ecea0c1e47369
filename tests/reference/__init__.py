"""Slow, plain reference implementations the tests check the library's kernels against:
Bezier and bilinear heights, the voxel casting and tool tests of paper 002, the dexel cut,
the drop-cutter, the EZ-map's edge codes. They live with the tests, not in the library."""
