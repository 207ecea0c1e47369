"""Histories of a simulation run: z-trace, time-trace and Interval Treap."""
