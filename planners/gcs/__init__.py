"""`gcs`: motion planning with graphs of convex sets (Drake's GcsTrajectoryOptimization) through
collision-free IRIS regions built offline, once per collision world.

From the bottom up:
- `sets`: the regions' options (every field in the cache key), a region set and its cache on disk;
- `solve`: one GCS solve through a set, and the repairs where its path collides;
- `cover`: world-only seeding (the task chain, its segments, a clique cover, the scene's own seeds);
- `iris`: one region grown by Drake's sampled IRIS (its options, its log, the Drake checker);
- `regions`: a world's region set seeded, grown, checked with the python-fcl world and cached;
- `planner`: the planner `gcs` (`GcsPlanner`, `GcsConfig`).
"""
