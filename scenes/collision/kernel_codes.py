"""The codes the compiled kernels share, below both of them: a state's decision, a joint table's
cell, an obstacle's kind, and the layout of the motion check's work array.

The state kernel (`scenes.collision.kernel_state`) and the motion kernel
(`scenes.collision.kernel_motion`, which calls the state kernel) read them, and so does the world
that drives them (`scenes.collision.compiled`). numba freezes them into the cached code, so this
module is one of `kernel_data.KERNEL_MODULES`: its source keys the cache. It imports nothing.
"""

#: Decisions of a state (and a motion check's request for a larger `todo` array).
FREE, COLLIDES, UNDECIDED, NEED_SPACE = 0, 1, 2, 4
#: Table cell values (as `scenes.collision.joint_tables`, which the kernels may not import).
UNKNOWN, APART, TOUCHING = 0, 1, 2
#: A scene pair the fine spheres prove apart.
APART_PAIR = 3
#: Obstacle kinds, each with its exact point distance: an axis-aligned box, a box, a cylinder
#: (axis z of its frame), a sphere.
AABB, OBB, CYLINDER, SPHERE = 0, 1, 2, 3

#: Layout of a motion check's work array (int64), where a resumable check stands: its phase, the
#: position to resume at, n (the motion's steps), the states evaluated, the head's length, the
#: head's sample indices, then the reach of q0 and of each head sample. WORK is its length.
WS_PHASE, WS_AT, WS_N, WS_STATES, WS_N_HEAD = 0, 1, 2, 3, 4
WS_HEAD, WS_REACH = 5, 5 + 8
WORK = WS_REACH + 9
#: The phases: a new motion (set ws[WS_PHASE] = PHASE_START to begin one), the head, the rest.
PHASE_START, PHASE_HEAD, PHASE_REST = 0, 1, 2
