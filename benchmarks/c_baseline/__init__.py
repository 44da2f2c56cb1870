"""Plain C reference loops (velocity Verlet and RK4 on Kepler), compiled at benchmark time."""
