"""The collision engine: the python-fcl world built from a scene, its exact certifier and its
compiled kernels. The judge (validator, certifier) runs the numpy reference; the planners run the
compiled kernels; each checks the other.

From the bottom up:
- `shapes`: primitives as FCL geometry, their covering spheres and boxes;
- `joint_tables`: self pairs proved apart (or touching) over the one joint they depend on;
- `build`: a world's arrays (link-frame rows, sphere pairs, tables), built once;
- `certify`: the exact segment check (certified, collision or unproved), and the reach bounds
  the motion checks borrow;
- `motion`: the motion checks (straight joint-space segments, sampled);
- `world`: `CollisionWorld`, the numpy reference (states, clearance, motions);
- `kernel_codes`, `kernel_data`: the kernels' shared codes, packed buffers and keyed numba cache;
- `kernel_state`, `kernel_motion`: the compiled state and motion checks (numba);
- `compiled`: `CompiledWorld`, the planners' world deciding with the kernels.
"""
