"""`gcs`: motion planning with graphs of convex sets (Drake's GcsTrajectoryOptimization) through
collision-free IRIS regions built offline, once per collision world.

From the bottom up:
- `sets`: the regions' options (every field in the cache key), a region set and its cache on disk;
- `solve`: one GCS solve through a set, and the repairs where its path collides;
- `cover`: world-only seeding (the task chain, its segments, a clique cover, the scene's own seeds);
- `regions`: a world's region set grown with IRIS, checked with the python-fcl world and cached;
- `planner`: the planner `gcs` (`GcsPlanner`, `GcsConfig`).
"""
