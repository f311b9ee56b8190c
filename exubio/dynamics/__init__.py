"""Inverse dynamics on exubio's reconstructions (numpy, no Exudyn): segment inertia from Dumas et
al. 2007 (inertia), Newton-Euler on the kinematic tree and the girdle's contact split
(newton_euler), and the joint-moment table (moments)."""
