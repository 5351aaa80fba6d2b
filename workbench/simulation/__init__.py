"""Plans replayed in physics (MuJoCo): the scene, the replay and its verdict, the convex decomposition of parts,
and the stage that stores results (CONVENTIONS.md, Simulation)."""
