"""Rigid-body dynamics and contact: bodies, collision, LCP/PGS contact solvers, articulated chains."""
